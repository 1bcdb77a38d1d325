"""Writing the graph's messages to a rosbag2 directory (metadata.yaml v9 + MCAP).

ROS-free: messages arrive already CDR-serialized (the recorder subscribes
raw), so nothing is re-encoded. Chunks are zstd-compressed (STORAGE mode;
MESSAGE mode is rejected by rosbag2's MCAP plugin and FILE mode makes a
``.mcap.zstd`` that MCAP tools cannot open). Every message definition is
embedded as ros2msg, so rosbags, the ``mcap`` library and Foxglove can decode
the bag without glocal_interfaces installed.
"""

from __future__ import annotations

import threading
from dataclasses import dataclass
from pathlib import Path

from rosbags.rosbag2 import CompressionFormat, CompressionMode, Reader, StoragePlugin, Writer
from rosbags.rosbag2.metadata import QosDurability, QosHistory, QosLiveliness, QosReliability, QosTime
from rosbags.rosbag2.writer import Qos
from rosbags.typesys import Stores, get_types_from_msg, get_typestore
from rosbags.typesys.store import Typestore

from glocal_ros.paths import interface_definitions_dir

INTERFACE_PACKAGE = "glocal_interfaces"


@dataclass(frozen=True)
class TopicSpec:
    name: str  # as recorded, absolute
    msgtype: str  # e.g. glocal_interfaces/msg/EpisodeRecord
    reliable: bool
    transient_local: bool
    depth: int


#: Every topic of the graph, with the QoS its publisher offers.
GRAPH_TOPICS: tuple[TopicSpec, ...] = (
    TopicSpec("/glocal/episodes", "glocal_interfaces/msg/EpisodeRecord", True, False, 1000),
    TopicSpec("/glocal/curriculum_state", "glocal_interfaces/msg/CurriculumState", True, True, 10),
    TopicSpec("/glocal/task_assignment", "glocal_interfaces/msg/TaskAssignment", True, True, 10),
    TopicSpec("/glocal/training_progress", "glocal_interfaces/msg/TrainingProgress", True, False, 100),
    TopicSpec("/glocal/evaluations", "glocal_interfaces/msg/EvaluationResult", True, False, 100),
    TopicSpec("/joint_states", "sensor_msgs/msg/JointState", False, False, 5),
    TopicSpec("/glocal/object_pose", "geometry_msgs/msg/PoseStamped", False, False, 5),
    TopicSpec("/glocal/grasp_state", "glocal_interfaces/msg/GraspState", False, False, 5),
)


def graph_typestore(definitions_dir: Path | None = None) -> Typestore:
    """Jazzy's standard types plus glocal_interfaces, read from its .msg files."""
    typestore = get_typestore(Stores.ROS2_JAZZY)
    folder = definitions_dir or interface_definitions_dir()
    types = {}
    for msg_file in sorted(folder.glob("*.msg")):
        types.update(get_types_from_msg(msg_file.read_text(), f"{INTERFACE_PACKAGE}/msg/{msg_file.stem}"))
    typestore.register(types)
    return typestore


def _offered_qos(spec: TopicSpec) -> Qos:
    zero = QosTime(sec=0, nsec=0)
    return Qos(
        history=QosHistory.KEEP_LAST,
        depth=spec.depth,
        reliability=QosReliability.RELIABLE if spec.reliable else QosReliability.BEST_EFFORT,
        durability=QosDurability.TRANSIENT_LOCAL if spec.transient_local else QosDurability.VOLATILE,
        deadline=zero,
        lifespan=zero,
        liveliness=QosLiveliness.AUTOMATIC,
        liveliness_lease_duration=zero,
        avoid_ros_namespace_conventions=False,
    )


class BagWriter:
    """A rosbag2 directory being written; thread-safe ``write``."""

    def __init__(self, path: Path, topics: tuple[TopicSpec, ...] = GRAPH_TOPICS, typestore: Typestore | None = None):
        self.path = Path(path)
        self.typestore = typestore or graph_typestore()
        self._writer = Writer(self.path, version=9, storage_plugin=StoragePlugin.MCAP)
        self._writer.set_compression(CompressionMode.STORAGE, CompressionFormat.ZSTD)
        self._writer.open()
        self._connections = {
            spec.name: self._writer.add_connection(
                spec.name, spec.msgtype, typestore=self.typestore, offered_qos_profiles=[_offered_qos(spec)]
            )
            for spec in topics
        }
        self._lock = threading.Lock()
        self.counts = {spec.name: 0 for spec in topics}

    def write(self, topic: str, timestamp_ns: int, data: bytes) -> None:
        with self._lock:
            self._writer.write(self._connections[topic], timestamp_ns, data)
            self.counts[topic] += 1

    def close(self) -> None:
        with self._lock:
            self._writer.close()


def message_counts(bag: Path) -> dict[str, int]:
    """Messages per topic of a closed bag, from its metadata."""
    with Reader(bag) as reader:
        return {connection.topic: connection.msgcount for connection in reader.connections}

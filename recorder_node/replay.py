"""Replaying a recorded bag onto the graph, as ``ros2 bag play`` does.

``replay(bag)`` republishes the recorded messages raw (the CDR bytes as
recorded: nothing is decoded or re-encoded) on the topic names as recorded,
which are absolute (under the recorder's namespace, if it had one), with the
recorded spacing divided by ``rate``. Each publisher offers the QoS the
recorded publishers offered (from the bag's ``offered_qos_profiles``, else
from the table's entry for the topic, ``glocal_ros.recording.table_topic``),
so late-joining viewers still get the latched curriculum state.

``replay(bag, episode=SEQ)`` plays one EpisodeRecord back for a viewer
instead: its ``joint_positions`` rows as sensor_msgs/JointState on
``joint_states`` of the namespace the episode was recorded in (``/joint_states``
for the root one), one per env step at the env's control period (physics
substeps x physics timestep of ``GraspEnvConfig``: 10 x 1/240 s), so that
robot_state_publisher + RViz show the arm as it moved in the sim.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path
from typing import Iterator, Protocol, Sequence

import numpy as np
import rclpy
from rclpy.duration import Duration
from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from rclpy.signals import SignalHandlerOptions
from rosbags.interfaces import Qos, QosDurability, QosHistory, QosReliability

from glocal_ros.recording import (
    episode_seq_from_cdr, episode_topics, graph_typestore, in_namespace, open_bag, table_topic, topic_namespace,
)
from glocal_ros.spaces import CONTROL_PERIOD
from glocal_ros.topics import EPISODES, EPISODES_TOPIC, JOINT_STATES
from node_common.runner import SHUTDOWN_POLL_SEC, configure_discovery
from recorder_node.recorder_node import message_class

#: Longest wait for subscribers before the first message (see ReplayNode.wait_for_subscribers):
#: discovery between two processes on loopback takes up to about 3 s here.
DEFAULT_WAIT_SEC = 5.0
#: The publisher sees a subscriber before that subscriber has matched the
#: publisher (discovery runs on both sides); until then a best-effort reader
#: drops what arrives and a reliable one gets it late, retransmitted.
_MATCH_SETTLE_SEC = 0.5
#: How long reliable publishers may take to get their last messages acknowledged at the end:
#: Fast DDS readers acknowledge when the writer's heartbeat asks, every 3 s by default.
_ACK_TIMEOUT = Duration(seconds=3.5)


@dataclass(frozen=True)
class ReplayTopic:
    name: str  # absolute, as recorded
    msgtype: str  # pkg/msg/Name
    qos: QoSProfile


class ReplaySource(Protocol):
    """What a ReplayNode plays: its topics, and the messages of one pass in time order."""

    topics: list[ReplayTopic]

    def messages(self) -> Iterator[tuple[int, str, object]]:
        """(nanoseconds after the start of the pass, topic, CDR bytes or a message to stamp now)."""
        ...


def publisher_qos(topic: str, recorded: Sequence[Qos]) -> QoSProfile:
    """The QoS to offer when replaying ``topic``, adapted from what its recorded publishers offered.

    The weakest of the recorded offers, as rosbag2's player adapts them:
    reliable only if every recorded publisher was, transient local only if
    every one was, so that a subscriber that matched all of them matches the
    replay too. Without recorded offers, the table's for the topic, under
    whatever namespace it was recorded. Offers seen in the graph carry no
    depth (0): the table's depth then, else rclpy's default of 10.
    """
    spec = table_topic(topic)
    known = [qos for qos in recorded if qos.reliability != QosReliability.UNKNOWN]
    if known:
        reliable = all(qos.reliability == QosReliability.RELIABLE for qos in known)
        latched = all(qos.durability == QosDurability.TRANSIENT_LOCAL for qos in known)
        keep_all = all(qos.history == QosHistory.KEEP_ALL for qos in known)
        depth = max(qos.depth for qos in known)
    elif spec is not None:
        reliable, latched, keep_all, depth = spec.qos.reliable, spec.qos.transient_local, False, spec.qos.depth
    else:  # neither recorded nor known: rclpy's defaults
        reliable, latched, keep_all, depth = True, False, False, 10
    return QoSProfile(
        history=HistoryPolicy.KEEP_ALL if keep_all else HistoryPolicy.KEEP_LAST,
        depth=depth or (spec.qos.depth if spec is not None else 10),
        reliability=ReliabilityPolicy.RELIABLE if reliable else ReliabilityPolicy.BEST_EFFORT,
        durability=DurabilityPolicy.TRANSIENT_LOCAL if latched else DurabilityPolicy.VOLATILE,
    )


class BagSource:
    """The bag's recorded messages, raw, from ``start_offset`` seconds after its first one."""

    def __init__(self, bag: Path, topics: Sequence[str] | None = None, start_offset: float = 0.0):
        self.bag = Path(bag)
        self.start_offset_ns = round(start_offset * 1e9)
        with open_bag(self.bag) as reader:  # ValueError for a missing or damaged bag
            recorded: dict[str, list] = {}
            for connection in reader.connections:
                recorded.setdefault(connection.topic, []).append(connection)
        if topics:
            wanted = [name if name.startswith("/") else "/" + name for name in topics]
        else:  # a topic without messages would only make wait_for_subscribers wait for nothing
            wanted = [name for name, connections in recorded.items() if any(c.msgcount for c in connections)]
            if not wanted:
                raise ValueError(f"{self.bag} holds no messages")
        if unknown := [name for name in wanted if name not in recorded]:
            raise ValueError(f"{self.bag} has no topic {', '.join(unknown)}; it has {', '.join(recorded)}")
        self.topics = []
        for name in wanted:
            if len({connection.msgtype for connection in recorded[name]}) > 1:
                raise ValueError(f"{name} was recorded with several message types: one publisher cannot replay it")
            qos = [qos for connection in recorded[name] for qos in connection.ext.offered_qos_profiles]
            self.topics.append(ReplayTopic(name, recorded[name][0].msgtype, publisher_qos(name, qos)))

    def messages(self) -> Iterator[tuple[int, str, bytes]]:
        names = {topic.name for topic in self.topics}
        with open_bag(self.bag) as reader:
            connections = [connection for connection in reader.connections if connection.topic in names]
            start = reader.start_time + self.start_offset_ns
            for connection, timestamp, data in reader.messages(connections=connections, start=start):
                yield timestamp - start, connection.topic, bytes(data)


def default_step_period() -> float:
    """The env's default control period (s): physics substeps per env step x physics timestep."""
    return CONTROL_PERIOD


class EpisodeSource:
    """One EpisodeRecord's joint positions as JointState messages, one per env step."""

    def __init__(self, bag: Path, seq: int, step_period: float, start_offset: float = 0.0):
        self.period_ns = round(step_period * 1e9)
        self.first_row = int(np.ceil(start_offset / step_period - 1e-9))
        found = episode_topics(Path(bag))
        if len(found) > 1:
            raise ValueError(f"{bag} has episodes of several sim nodes ({', '.join(found)}): "
                             "seq numbers are per node, so --episode cannot tell which")
        self.episodes_topic = found[0] if found else EPISODES_TOPIC
        self.joint_states_topic = in_namespace(topic_namespace(self.episodes_topic, EPISODES) or "/", JOINT_STATES)
        self.names, self.rows = self._find(Path(bag), self.episodes_topic, seq)
        if self.first_row >= len(self.rows):
            raise ValueError(f"--start-offset {start_offset} s is past the end of episode {seq} "
                             f"({len(self.rows)} states, {len(self.rows) * step_period:.2f} s)")
        with open_bag(Path(bag)) as reader:
            recorded = [qos for c in reader.connections if c.topic == self.joint_states_topic
                        for qos in c.ext.offered_qos_profiles]
        self.topics = [ReplayTopic(self.joint_states_topic, "sensor_msgs/msg/JointState",
                                   publisher_qos(self.joint_states_topic, recorded))]

    @staticmethod
    def _find(bag: Path, topic: str, seq: int) -> tuple[list[str], np.ndarray]:
        typestore = graph_typestore()
        record = None
        with open_bag(bag) as reader:
            connections = [connection for connection in reader.connections if connection.topic == topic]
            # An empty selection would mean every topic to rosbags.
            messages = reader.messages(connections=connections) if connections else iter(())
            for connection, _, data in messages:
                # Only the seq is read from every record; the one replayed is decoded in full.
                found = episode_seq_from_cdr(data)
                if found is None or found == seq:
                    record = typestore.deserialize_cdr(data, connection.msgtype)
                    if record.seq == seq:
                        break
                    record = None
        if record is None:
            raise ValueError(f"{bag} has no episode with seq {seq} on {topic}")
        names = list(record.joint_names)
        positions = np.asarray(record.joint_positions, dtype=np.float64)
        if not names or positions.size % len(names) or not positions.size:
            raise ValueError(f"episode {seq} has no joint positions to replay "
                             f"({positions.size} values for {len(names)} joints)")
        return names, positions.reshape(-1, len(names))

    def messages(self) -> Iterator[tuple[int, str, object]]:
        from sensor_msgs.msg import JointState

        for index in range(self.first_row, len(self.rows)):
            message = JointState(name=self.names, position=self.rows[index].tolist())
            yield (index - self.first_row) * self.period_ns, self.joint_states_topic, message


class ReplayNode(Node):
    """Publishes a ReplaySource's messages with their recorded spacing divided by ``rate``."""

    def __init__(self, source: ReplaySource, rate: float = 1.0, loop: bool = False) -> None:
        super().__init__("replay")
        self.source, self.rate, self.loop = source, rate, loop
        self.publishers_by_topic = {
            topic.name: self.create_publisher(message_class(topic.msgtype), topic.name, topic.qos)
            for topic in source.topics
        }
        self.published = 0

    def wait_for_subscribers(self, executor: SingleThreadedExecutor, timeout: float) -> None:
        """Wait until every publisher has a subscriber, ``timeout`` seconds at most.

        A subscriber that is already up (a viewer, a test) needs a moment to
        discover the new publishers; what a volatile publisher sends before
        that is lost to it. Topics nobody subscribes to only cost the timeout.
        """
        deadline = time.monotonic() + timeout
        while self.context.ok() and time.monotonic() < deadline:
            if all(publisher.get_subscription_count() for publisher in self.publishers_by_topic.values()):
                self._sleep_until(executor, time.monotonic() + _MATCH_SETTLE_SEC)
                return
            executor.spin_once(timeout_sec=0.05)
        unmatched = [topic for topic, publisher in self.publishers_by_topic.items()
                     if not publisher.get_subscription_count()]
        if unmatched and self.context.ok():
            self.get_logger().info(f"no subscriber after {timeout:g} s on {', '.join(unmatched)}: playing anyway")

    def play(self, executor: SingleThreadedExecutor) -> None:
        """One pass through the source (passes until shutdown with ``loop``)."""
        while self.context.ok():
            start = time.monotonic()
            messages = self.source.messages()
            try:
                for offset_ns, topic, message in messages:
                    if not self._sleep_until(executor, start + offset_ns / 1e9 / self.rate):
                        return
                    if not isinstance(message, bytes) and hasattr(message, "header"):
                        # Made for the replay, not recorded: stamped now, as a live sim would.
                        message.header.stamp = self.get_clock().now().to_msg()
                    self.publishers_by_topic[topic].publish(message)
                    self.published += 1
            finally:
                messages.close()  # closes the bag when a pass is cut short
            if not self.loop:
                return

    def wait_for_acknowledgements(self) -> None:
        """Let reliable subscribers get the last messages before the publishers go away.

        Fast DDS sends asynchronously: a publisher destroyed right after its
        last publish can take unsent data with it. Best-effort publishers
        return at once.
        """
        for publisher in self.publishers_by_topic.values():
            publisher.wait_for_all_acked(_ACK_TIMEOUT)

    def _sleep_until(self, executor: SingleThreadedExecutor, due: float) -> bool:
        """Spin until ``due`` (time.monotonic); False when the node was shut down meanwhile.

        Spinning instead of sleeping keeps the node's services answering and
        wakes up at once on SIGINT/SIGTERM.
        """
        while self.context.ok():
            remaining = due - time.monotonic()
            if remaining <= 0:
                return True
            executor.spin_once(timeout_sec=min(remaining, SHUTDOWN_POLL_SEC))
        return False


def replay(
    bag: Path,
    *,
    rate: float = 1.0,
    topics: Sequence[str] | None = None,
    loop: bool = False,
    start_offset: float = 0.0,
    episode: int | None = None,
    step_period: float | None = None,
    wait: float = DEFAULT_WAIT_SEC,
    args: Sequence[str] | None = None,
) -> int:
    """Replay ``bag`` (or one of its episodes) until done, or until SIGINT/SIGTERM with ``loop``; exit code.

    Bad input raises ValueError before anything is published.
    """
    if not rate > 0:
        raise ValueError(f"--rate must be positive, got {rate}")
    if start_offset < 0:
        raise ValueError(f"--start-offset must not be negative, got {start_offset}")
    if wait < 0:
        raise ValueError(f"--wait must not be negative, got {wait}")
    source: ReplaySource
    if episode is not None:
        if topics:
            raise ValueError("--episode replays joint_states only: --topics does not go with it")
        period = default_step_period() if step_period is None else step_period
        if not period > 0:
            raise ValueError(f"--step-period must be positive, got {period}")
        source = EpisodeSource(bag, episode, period, start_offset)
    else:
        source = BagSource(bag, topics, start_offset)
    for topic in source.topics:  # an uninstalled message type is bad input too, found before rclpy starts
        try:
            message_class(topic.msgtype)
        except (ImportError, AttributeError, ValueError):
            raise ValueError(f"cannot replay {topic.name}: its type {topic.msgtype} is not installed") from None

    configure_discovery()
    rclpy.init(args=args, signal_handler_options=SignalHandlerOptions.ALL)
    node: ReplayNode | None = None
    try:
        node = ReplayNode(source, rate, loop)
        executor = SingleThreadedExecutor()
        executor.add_node(node)
        what = f"episode {episode} of {bag}" if episode is not None else str(bag)
        node.get_logger().info(f"replaying {what} at rate {rate} on {', '.join(t.name for t in source.topics)}")
        node.wait_for_subscribers(executor, wait)
        node.play(executor)
        if node.context.ok():
            node.wait_for_acknowledgements()
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        if node is not None:
            node.destroy_node()
            # Not the node's logger: after SIGINT its rosout publisher is gone with the context.
            rclpy.logging.get_logger("replay").info(f"published {node.published} messages")
        rclpy.try_shutdown()
    return 0

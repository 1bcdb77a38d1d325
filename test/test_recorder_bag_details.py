"""What a recorded bag holds, field by field, against what rosbag2 Jazzy writes (issue 16).

Channel metadata ``topic_type_hash`` (RIHS01), ``ros_distro: jazzy``, each
message's ``log_time`` (the recorder's clock, the sim clock under
``use_sim_time``) apart from its ``publish_time`` (the publisher's source
timestamp), and ``offered_qos_profiles`` as the publishers offer them. Bags
are read back from the MCAP file with the ``mcap`` library, which sees the
fields rosbags' reader does not expose.
"""

from __future__ import annotations

import io
import shutil
import signal
import time
from collections import Counter
from dataclasses import replace
from pathlib import Path

import pytest
from builtin_interfaces.msg import Time
from glocal_interfaces.msg import CurriculumState, EpisodeRecord
from rclpy.qos import QoSProfile, ReliabilityPolicy
from rclpy.serialization import serialize_message
from rosbags.interfaces import QosDurability, QosHistory, QosReliability
from rosbags.rosbag2.metadata import parse_qos
from rosgraph_msgs.msg import Clock
from ruamel.yaml import YAML
from sensor_msgs.msg import JointState

from conftest import wait_until
from glocal_ros.bag_repair import copy_topics, repair_bag
from glocal_ros.recording import BagWriter, graph_typestore
from glocal_ros.topics import EPISODES, JOINT_STATES
from node_common import names, qos
from test_bags import episode

ROSOUT_AFTER_SHUTDOWN = "Failed to publish log message to rosout"


def read_mcap(bag: Path) -> tuple[dict[str, tuple[str, dict[str, str]]], list[tuple[str, int, int]], dict]:
    """(channels: topic -> (schema name, metadata), messages: (topic, log_time, publish_time) in file order,
    the rosbag2 metadata record embedded in the file, parsed)."""
    from mcap.reader import make_reader

    with open(bag / f"{bag.name}.mcap", "rb") as stream:
        reader = make_reader(stream)
        summary = reader.get_summary()
        channels = {channel.topic: (summary.schemas[channel.schema_id].name, dict(channel.metadata))
                    for channel in summary.channels.values()}
        messages = [(channel.topic, message.log_time, message.publish_time)
                    for _, channel, message in reader.iter_messages(log_time_order=False)]
        embedded = {record.name: dict(record.metadata) for record in reader.iter_metadata()}
    return channels, messages, YAML(typ="safe").load(embedded["rosbag2"]["serialized_metadata"])


def metadata_yaml(bag: Path) -> dict:
    return YAML(typ="safe").load((bag / "metadata.yaml").read_text())["rosbag2_bagfile_information"]


def assert_as_rosbag2_jazzy_writes(bag: Path) -> dict[str, str]:
    """Every channel's topic_type_hash is the typestore's RIHS01 and metadata.yaml's; ros_distro is jazzy.

    Returns each topic's hash.
    """
    channels, _, embedded = read_mcap(bag)
    information = metadata_yaml(bag)
    typestore = graph_typestore()
    yaml_hashes = {t["topic_metadata"]["name"]: t["topic_metadata"]["type_description_hash"]
                   for t in information["topics_with_message_count"]}
    assert set(yaml_hashes) == set(channels)
    for topic, (schema_name, metadata) in channels.items():
        assert metadata["topic_type_hash"].startswith("RIHS01_"), (topic, metadata)
        assert metadata["topic_type_hash"] == typestore.hash_rihs01(schema_name) == yaml_hashes[topic], topic
        assert parse_qos(metadata["offered_qos_profiles"]), topic
    assert information["ros_distro"] == "jazzy" and embedded["ros_distro"] == "jazzy"
    return {topic: metadata["topic_type_hash"] for topic, (_, metadata) in channels.items()}


def test_bag_writer_writes_type_hashes_distro_and_both_times_and_repair_keeps_them(tmp_path):
    bag = tmp_path / "bag"
    writer = BagWriter(bag)
    writer.write("/glocal/episodes", 2_000_000_000, serialize_message(episode(0)), publish_time_ns=1_500_000_000)
    writer.write("/joint_states", 3_000_000_000, serialize_message(JointState(name=["a"], position=[0.5])))
    writer.flush()
    killed = tmp_path / "killed"  # the bag as a recorder killed here would leave it: no summary, no metadata.yaml
    shutil.copytree(bag, killed)
    writer.close()

    assert_as_rosbag2_jazzy_writes(bag)
    _, messages, _ = read_mcap(bag)
    # The publish time as given; without one (a source that has none), the log time.
    assert sorted(messages) == [("/glocal/episodes", 2_000_000_000, 1_500_000_000),
                                ("/joint_states", 3_000_000_000, 3_000_000_000)]

    assert not (killed / "metadata.yaml").exists()
    assert repair_bag(killed).repaired
    hashes = assert_as_rosbag2_jazzy_writes(killed)
    assert {t: hashes[t] for t in ("/glocal/episodes", "/joint_states")} == \
           {t: read_mcap(bag)[0][t][1]["topic_type_hash"] for t in ("/glocal/episodes", "/joint_states")}
    assert sorted(read_mcap(killed)[1]) == sorted(messages)


def test_a_copy_of_some_topics_keeps_their_messages_as_recorded_and_refuses_what_it_cannot_copy(tmp_path):
    bag = tmp_path / "bag"
    # Named as a recorder under a namespace names them.
    writer = BagWriter(bag, [replace(spec, name=f"/robot1{spec.name}") for spec in (EPISODES, JOINT_STATES)])
    writer.write("/robot1/glocal/episodes", 2_000_000_000, serialize_message(episode(0)),
                 publish_time_ns=1_500_000_000)
    writer.write("/robot1/joint_states", 3_000_000_000, serialize_message(JointState(name=["a"], position=[0.5])))
    writer.write("/robot1/glocal/episodes", 4_000_000_000, serialize_message(episode(1)))
    writer.flush()
    killed = tmp_path / "killed"
    shutil.copytree(bag, killed)
    writer.close()

    copy = tmp_path / "copy" / "bag"
    assert copy_topics(bag, copy, lambda topic: topic.endswith("/glocal/episodes")) == {"/robot1/glocal/episodes": 2}
    channels, messages, _ = read_mcap(copy)
    assert sorted(messages) == [("/robot1/glocal/episodes", 2_000_000_000, 1_500_000_000),
                                ("/robot1/glocal/episodes", 4_000_000_000, 4_000_000_000)]
    assert channels == {topic: value for topic, value in read_mcap(bag)[0].items() if topic in channels}
    assert_as_rosbag2_jazzy_writes(copy)

    with pytest.raises(ValueError, match="exists: a copy never overwrites"):
        copy_topics(bag, copy, lambda topic: True)
    with pytest.raises(ValueError, match="is not an intact MCAP rosbag2 bag"):
        copy_topics(killed, tmp_path / "from-killed", lambda topic: True)
    assert not (tmp_path / "from-killed").exists()


def records_on_disk(mcap: Path) -> list[tuple[str, int]]:
    """(topic, log_time) of the messages in the complete chunks of an MCAP file that is still being written."""
    from mcap.records import Channel, Message
    from mcap.stream_reader import StreamReader

    topics: dict[int, str] = {}
    records = []
    try:
        for record in StreamReader(io.BytesIO(mcap.read_bytes()), emit_chunks=False).records:
            if isinstance(record, Channel):
                topics[record.id] = record.topic
            elif isinstance(record, Message):
                records.append((topics[record.channel_id], record.log_time))
    except Exception:  # noqa: BLE001 - the end of what is written so far
        pass
    return records


def live_type_hash(ros_node, topic: str) -> str:
    """The RIHS01 hash a publisher in the graph advertises for ``topic`` (rosidl's, from the installed type)."""
    return str(ros_node.get_publishers_info_by_topic(topic)[0].topic_type_hash)


def test_log_time_follows_the_recorders_sim_clock_and_publish_time_is_the_source_stamp(start_node, ros_node,
                                                                                          tmp_path):
    bag = tmp_path / "bag"
    recorder = start_node("recorder_node", output=str(bag), use_sim_time=True, flush_interval_sec=0.2)
    clock = ros_node.create_publisher(Clock, names.CLOCK, qos.CLOCK)
    episodes = ros_node.create_publisher(EpisodeRecord, names.EPISODES, qos.EPISODES)
    # /clock: the recorder's time source and its recording subscription.
    wait_until(lambda: clock.get_subscription_count() >= 2 and episodes.get_subscription_count(), 60,
               "the recorder's subscriptions", processes=[recorder])
    mcap = bag / "bag.mcap"
    sent: list[int] = []

    def publish_at(sim_sec: int, seq: int) -> tuple[int, int]:
        """Set the recorder's sim clock, then send an episode; the wall-clock window of the send."""
        def clock_set() -> bool:
            # The time source's reader is best effort: what it gets before its side of the match is
            # lost. A /clock message recorded at this time shows the recorder's clock got there.
            clock.publish(Clock(clock=Time(sec=sim_sec)))
            return ("/clock", sim_sec * 10**9) in records_on_disk(mcap)

        wait_until(clock_set, 60, f"the recorder's clock at {sim_sec} s", poll=0.1, processes=[recorder])
        before = time.time_ns()
        episodes.publish(episode(seq))
        after = time.time_ns()
        sent.append(seq)
        # Recorded before the clock moves on.
        wait_until(lambda: sum(topic == "/glocal/episodes" for topic, _ in records_on_disk(mcap)) == len(sent), 60,
                   f"episode {seq} on disk", processes=[recorder])
        return before, after

    first = publish_at(1000, 5)
    second = publish_at(2000, 7)
    assert recorder.stop(signal.SIGINT) == 0, recorder.log()
    assert ROSOUT_AFTER_SHUTDOWN not in recorder.log(), recorder.log()

    _, messages, _ = read_mcap(bag)
    recorded = [(log_time, publish_time) for topic, log_time, publish_time in messages if topic == "/glocal/episodes"]
    assert len(recorded) == 2, messages
    for (log_time, publish_time), sim_sec, (before, after) in zip(recorded, (1000, 2000), (first, second)):
        assert log_time == sim_sec * 10**9, recorded  # the recorder's clock: the last /clock it got
        assert before <= publish_time <= after, (publish_time, before, after)  # the source stamp, wall clock
    assert {log for topic, log, _ in messages if topic == "/clock"} >= {1000 * 10**9, 2000 * 10**9}, messages

    hashes = assert_as_rosbag2_jazzy_writes(bag)
    assert hashes["/glocal/episodes"] == live_type_hash(ros_node, "/glocal/episodes")
    assert hashes["/clock"] == live_type_hash(ros_node, "/clock")


def test_the_bag_records_the_qos_its_publishers_offer(start_node, ros_node, tmp_path):
    bag = tmp_path / "bag"
    recorder = start_node("recorder_node", output=str(bag), flush_interval_sec=0.2)
    best_effort = ros_node.create_publisher(JointState, names.JOINT_STATES,
                                            QoSProfile(depth=5, reliability=ReliabilityPolicy.BEST_EFFORT))
    latched = ros_node.create_publisher(CurriculumState, names.CURRICULUM_STATE, qos.LATCHED)
    latched.publish(CurriculumState(iteration=3))
    # The recorder subscribes to /joint_states reliable (the table's QoS), which matches no best-effort
    # publisher: a match means the recorder adapted its subscription to the offer.
    wait_until(lambda: best_effort.get_subscription_count() and latched.get_subscription_count(), 60,
               "the recorder's subscriptions", processes=[recorder])
    mcap = bag / "bag.mcap"

    def joint_states_recorded() -> bool:
        # Best effort: what is sent before the recorder's side of the match is lost, so send until one lands.
        best_effort.publish(JointState(name=["a"], position=[0.25]))
        counts = Counter(topic for topic, _ in records_on_disk(mcap))
        return counts["/joint_states"] > 0 and counts["/glocal/curriculum_state"] == 1

    wait_until(joint_states_recorded, 60, "a joint state and the latched state on disk", poll=0.1,
               processes=[recorder])
    assert "/joint_states: subscribing best effort, volatile" in recorder.log()
    assert recorder.stop(signal.SIGINT) == 0, recorder.log()

    channels, _, _ = read_mcap(bag)
    offered = {topic: parse_qos(metadata["offered_qos_profiles"]) for topic, (_, metadata) in channels.items()}
    # As the graph reports a publisher: reliability and durability; history and depth are not discovered.
    [joint_states] = offered["/joint_states"]
    assert (joint_states.reliability, joint_states.durability, joint_states.history) == \
           (QosReliability.BEST_EFFORT, QosDurability.VOLATILE, QosHistory.UNKNOWN), joint_states
    [state] = offered["/glocal/curriculum_state"]
    assert (state.reliability, state.durability) == (QosReliability.RELIABLE, QosDurability.TRANSIENT_LOCAL), state
    # No publisher seen: the table's QoS.
    [evaluations] = offered["/glocal/evaluations"]
    assert (evaluations.reliability, evaluations.durability, evaluations.history, evaluations.depth) == \
           (QosReliability.RELIABLE, QosDurability.VOLATILE, QosHistory.KEEP_LAST, 100), evaluations

    hashes = assert_as_rosbag2_jazzy_writes(bag)
    assert hashes["/joint_states"] == live_type_hash(ros_node, "/joint_states")
    assert hashes["/glocal/curriculum_state"] == live_type_hash(ros_node, "/glocal/curriculum_state")

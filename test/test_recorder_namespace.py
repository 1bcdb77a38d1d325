"""A namespaced graph's bag (issue 16): the recorder resolves the table's topics under its namespace, and
everything that reads bags by topic (bag check, analysis and report, replay) finds them there."""

from __future__ import annotations

import signal
from dataclasses import replace
from pathlib import Path

import pytest
from glocal_interfaces.msg import EpisodeRecord
from rclpy.qos import DurabilityPolicy, ReliabilityPolicy
from rclpy.serialization import serialize_message

from conftest import wait_until
from glocal_ros.analysis.report import bags_section
from glocal_ros.analysis.runs import read_run
from glocal_ros.curriculum.codes import STATUS_STARTING
from glocal_ros.recording import (
    BagWriter, episode_sequence, episode_topics, in_namespace, message_counts, table_topic, topic_namespace,
)
from glocal_ros.topics import CURRICULUM_STATE, EPISODES, JOINT_STATES, RECORDED_TOPICS, TF, TF_STATIC
from node_common import names, qos
from recorder_node.replay import EpisodeSource, publisher_qos
from test_bags import episode, messages_on_disk, run_cli
from test_recorder_bag_details import ROSOUT_AFTER_SHUTDOWN
from test_report import state_cdr

T0_NS = 1_700_000_000 * 10**9


def test_table_topics_are_found_under_any_namespace():
    assert table_topic("/glocal/episodes") is EPISODES
    assert table_topic("/robot1/glocal/episodes") is EPISODES
    assert table_topic("/lab/robot1/tf") is TF and table_topic("/robot1/tf_static") is TF_STATIC
    assert table_topic("/robot1/xtf") is None and table_topic("/robot1/episodes") is None
    assert topic_namespace("/lab/robot1/joint_states", JOINT_STATES) == "/lab/robot1"
    assert topic_namespace("/joint_states", JOINT_STATES) == "/"
    assert topic_namespace("/joint_states", EPISODES) is None
    assert in_namespace("/", EPISODES) == "/glocal/episodes" == EPISODES.name
    assert in_namespace("/robot1", EPISODES) == "/robot1/glocal/episodes"


def namespaced_bag(path: Path, namespaces: tuple[str, ...], states: int, episodes: int) -> Path:
    """A bag as recorders under ``namespaces`` write it: curriculum states and episodes in each."""
    topics = [replace(spec, name=in_namespace(ns, spec)) for ns in namespaces for spec in RECORDED_TOPICS]
    writer = BagWriter(path, topics)
    for ns in namespaces:
        for i in range(states):
            # Serialized by the typestore: rclpy's serialize_message (not what a publisher sends) pads
            # an empty uint64[] that rosbags then cannot read.
            state = state_cdr(T0_NS + i * 10**9, strategy="glocal", seed=1, status=STATUS_STARTING, iteration=i,
                              total_steps=i, tasks=["A0"], learned=[])
            writer.write(in_namespace(ns, CURRICULUM_STATE), T0_NS + i * 10**9, state)
        for seq in range(episodes):
            writer.write(in_namespace(ns, EPISODES), T0_NS + seq * 10**8, serialize_message(episode(seq, states=2)))
    writer.close()
    return path


def test_bag_check_analysis_and_replay_read_a_namespaced_bag(tmp_path):
    bag = namespaced_bag(tmp_path / "run" / "bag", ("/robot1",), states=2, episodes=3)
    assert episode_topics(bag) == ["/robot1/glocal/episodes"]
    check = episode_sequence(bag)
    assert (check.count, check.first, check.last, check.ok) == (3, 0, 2, True)
    result = run_cli("bag", "check", bag)
    assert result.returncode == 0, result.stdout + result.stderr
    assert "/robot1/glocal/episodes: 3 episodes, seq 0..2; no gaps" in result.stdout

    run = read_run(tmp_path / "run")
    assert run is not None and len(run.states) == 2 and run.episodes.train == 3
    assert "2 curriculum states and 3 episode records in the bags read." in bags_section([run], [])

    # Replay: a topic without recorded offers gets the table's QoS, found under the namespace.
    profile = publisher_qos("/robot1/glocal/curriculum_state", [])
    assert (profile.reliability, profile.durability, profile.depth) == \
           (ReliabilityPolicy.RELIABLE, DurabilityPolicy.TRANSIENT_LOCAL, CURRICULUM_STATE.qos.depth)
    # An episode replays on joint_states of its own namespace.
    source = EpisodeSource(bag, 1, step_period=0.05)
    assert [topic.name for topic in source.topics] == ["/robot1/joint_states"]
    assert [topic for _, topic, _ in source.messages()] == ["/robot1/joint_states"] * 2


def test_a_bag_of_several_namespaces_is_checked_per_sim_node(tmp_path):
    bag = namespaced_bag(tmp_path / "bag", ("/robot1", "/robot2"), states=1, episodes=2)
    assert episode_topics(bag) == ["/robot1/glocal/episodes", "/robot2/glocal/episodes"]
    with pytest.raises(ValueError, match="several sim nodes"):
        episode_sequence(bag)  # seq counts per sim node: merged, every one would be a duplicate
    assert episode_sequence(bag, "/robot2/glocal/episodes").ok
    result = run_cli("bag", "check", bag)
    assert result.returncode == 0, result.stdout + result.stderr
    for robot in ("robot1", "robot2"):
        assert f"/{robot}/glocal/episodes: 2 episodes, seq 0..1; no gaps" in result.stdout


def test_a_namespaced_recorder_records_its_namespace_and_closes_quietly(start_node, ros_node, tmp_path):
    bag = tmp_path / "bag"
    recorder = start_node("recorder_node", extra_args=("-r", "__ns:=/robot1"), output=str(bag),
                          flush_interval_sec=0.2)
    publisher = ros_node.create_publisher(EpisodeRecord, f"/robot1/{names.EPISODES}", qos.EPISODES)
    wait_until(lambda: publisher.get_subscription_count(), 60, "the recorder's subscription", processes=[recorder])
    for seq in range(5):
        publisher.publish(episode(seq))
    wait_until(lambda: messages_on_disk(bag / "bag.mcap") == 5, 60, "the 5 episodes on disk", processes=[recorder])
    assert recorder.stop(signal.SIGINT) == 0, recorder.log()
    log = recorder.log()
    # The closing report is there, and nothing was logged to the /rosout the SIGINT took away.
    assert "closed " in log and "/robot1/glocal/episodes: 5 episodes, seq 0..4; no gaps" in log, log
    assert ROSOUT_AFTER_SHUTDOWN not in log, log

    counts = message_counts(bag)
    assert sorted(counts) == sorted(in_namespace("/robot1", spec) for spec in RECORDED_TOPICS), counts
    assert counts["/robot1/glocal/episodes"] == 5
    check = episode_sequence(bag)
    assert (check.count, check.first, check.last, check.ok) == (5, 0, 4, True), check.summary()


def test_a_recorder_of_several_pairs_records_each_pairs_topics_under_its_namespace():
    from recorder_node.recorder_node import pair_namespace_list, recorded_names

    assert pair_namespace_list("") == [""]
    assert pair_namespace_list(" pair0, pair1/ ") == ["pair0", "pair1"]
    for bad in ("pair0,pair0", "pair0,", ",pair1"):
        with pytest.raises(ValueError, match="distinct namespaces"):
            pair_namespace_list(bad)
    assert recorded_names([""]) == [(spec, spec.relative_name) for spec in RECORDED_TOPICS]
    names_ = recorded_names(["pair0", "/lab/pair1"])
    assert ("glocal/curriculum_state" in [name for spec, name in names_ if spec is CURRICULUM_STATE]
            and len([name for spec, name in names_ if spec is CURRICULUM_STATE]) == 1), "the curriculum's, once"
    assert [name for spec, name in names_ if spec is EPISODES] == ["pair0/glocal/episodes",
                                                                  "/lab/pair1/glocal/episodes"]
    assert {name for spec, name in names_ if spec is TF} == {"pair0/tf", "/lab/pair1/tf"}


def test_a_recorder_of_two_pairs_checks_each_pairs_episodes_and_ends_cleanly_when_one_has_a_gap(
        start_node, ros_node, tmp_path):
    bag = tmp_path / "bag"
    recorder = start_node("recorder_node", output=str(bag), pair_namespaces="pair0,pair1", flush_interval_sec=0.2)
    publishers = {pair: ros_node.create_publisher(EpisodeRecord, f"/{pair}/{names.EPISODES}", qos.EPISODES)
                  for pair in ("pair0", "pair1")}
    wait_until(lambda: all(p.get_subscription_count() for p in publishers.values()), 60,
               "the recorder's subscriptions", processes=[recorder])
    for pair, seqs in (("pair0", (0, 1, 2)), ("pair1", (0, 2))):
        for seq in seqs:
            publishers[pair].publish(episode(seq))
    wait_until(lambda: messages_on_disk(bag / "bag.mcap") == 5, 60, "the 5 episodes on disk", processes=[recorder])
    assert recorder.stop(signal.SIGINT) == 0, recorder.log()
    log = recorder.log()
    assert "/pair0/glocal/episodes: 3 episodes, seq 0..2; no gaps" in log, log
    assert "/pair1/glocal/episodes: episode seq gap: 1 missing (got 2 after 0)" in log, log
    assert "/pair1/glocal/episodes: 2 episodes" in log, log
    assert message_counts(bag)["/pair1/glocal/episodes"] == 2

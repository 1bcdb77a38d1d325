"""Recorded bags: episode seq checks, repair of a killed recorder's bag, replay."""

import io
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from glocal_interfaces.msg import CurriculumState, EpisodeRecord, EvaluationResult
from rclpy.duration import Duration
from rclpy.serialization import serialize_message
from rosbags.highlevel import AnyReader
from rosbags.interfaces import QosReliability
from rosbags.rosbag2.metadata import parse_qos
from sensor_msgs.msg import JointState

from conftest import REPO, wait_until
from glocal_ros.recording import BagWriter, episode_seq_from_cdr, episode_sequence, graph_typestore
from node_common import names, qos
from node_common.arrays import to_float32_field

GLOCAL_ROS = [sys.executable, "-m", "glocal_app.cli"]
JOINTS = ["panda_joint1", "panda_joint2", "panda_finger_joint1"]
START_NS = 1_700_000_000 * 10**9


def run_cli(*args, timeout=60):
    """``glocal-ros ARGS`` in this test's environment (its ROS domain)."""
    return subprocess.run([*GLOCAL_ROS, *map(str, args)], capture_output=True, text=True, timeout=timeout, cwd=REPO)


def episode(seq: int, values: int = 4, states: int = 0) -> EpisodeRecord:
    record = EpisodeRecord(seq=seq, task="A0", length=max(states - 1, 0))
    record.header.frame_id = "world"
    record.observations = to_float32_field(np.random.default_rng(seq).random(values))
    record.joint_names = JOINTS
    record.joint_positions = to_float32_field(seq + np.arange(states * len(JOINTS)) / 100)
    return record


def write_bag(path: Path, messages) -> Path:
    """A bag as the recorder writes it, from (topic, seconds after the start, rclpy message)."""
    writer = BagWriter(path)
    try:
        for topic, seconds, message in messages:
            writer.write(topic, START_NS + round(seconds * 1e9), serialize_message(message))
    finally:
        writer.close()
    return path


def test_seq_is_read_from_the_cdr_bytes_as_rclpy_writes_them():
    for frame_id in ("", "w", "world", "seven77", "eight888"):
        record = episode(2**40 + 3)
        record.header.frame_id = frame_id
        assert episode_seq_from_cdr(serialize_message(record)) == 2**40 + 3
    assert episode_seq_from_cdr(b"\x00\x07\x00\x00" + bytes(40)) is None  # XCDR2: decoded in full instead


def test_episode_gaps_are_reported_and_fail_bag_check(tmp_path):
    with_gaps = write_bag(tmp_path / "gaps", [("/glocal/episodes", 0.1 * s, episode(s)) for s in range(10)
                                              if s not in (4, 7)])
    check = episode_sequence(with_gaps)
    assert (check.count, check.first, check.last, check.gaps, check.duplicates) == (8, 0, 9, [(4, 4), (7, 7)], [])
    result = run_cli("bag", "check", with_gaps)
    assert result.returncode == 1, result.stderr
    assert "/glocal/episodes" in result.stdout and "2 missing in 2 gaps: 4, 7" in result.stdout

    contiguous = write_bag(tmp_path / "contiguous", [("/glocal/episodes", 0.1 * s, episode(s)) for s in range(10)])
    assert episode_sequence(contiguous).ok
    result = run_cli("bag", "check", contiguous)
    assert result.returncode == 0, result.stderr
    assert "10 episodes, seq 0..9; no gaps" in result.stdout


def test_recorder_warns_about_a_gap_as_it_arrives(start_node, ros_node, tmp_path):
    recorder = start_node("recorder_node", output=str(tmp_path / "bag"))
    publisher = ros_node.create_publisher(EpisodeRecord, names.EPISODES, qos.EPISODES)
    wait_until(lambda: publisher.get_subscription_count(), 60, "the recorder's subscription", processes=[recorder])
    for seq in (0, 1, 2, 5, 6, 6):
        publisher.publish(episode(seq))
    assert publisher.wait_for_all_acked(Duration(seconds=60))
    wait_until(lambda: "episode seq gap: 3..4 missing" in recorder.log(), 60, "the gap warning",
               processes=[recorder])
    assert recorder.stop(signal.SIGINT) == 0, recorder.log()
    assert "6 episodes, seq 0..6; 2 missing in 1 gaps: 3..4; 1 duplicates: 6" in recorder.log()


def messages_on_disk(mcap: Path) -> int:
    """Message records in the complete chunks of an MCAP file that is still being written."""
    from mcap.records import Message
    from mcap.stream_reader import StreamReader

    count = 0
    try:
        for record in StreamReader(io.BytesIO(mcap.read_bytes()), emit_chunks=False).records:
            count += isinstance(record, Message)
    except Exception:  # noqa: BLE001 - the end of what is written so far
        pass
    return count


def test_a_killed_recorder_loses_nothing_before_its_last_flush(start_node, ros_node, tmp_path):
    """Before, a recorder killed in its first MiB left a 0-byte bag: nothing, not even the schemas."""
    bag = tmp_path / "bag"
    recorder = start_node("recorder_node", output=str(bag), flush_interval_sec=0.5)
    publisher = ros_node.create_publisher(EpisodeRecord, names.EPISODES, qos.EPISODES)
    wait_until(lambda: publisher.get_subscription_count(), 60, "the recorder's subscription", processes=[recorder])
    mcap = bag / "bag.mcap"
    wait_until(lambda: mcap.is_file() and mcap.stat().st_size > 0, 60, "the schemas on disk", processes=[recorder])
    for seq in range(5):
        publisher.publish(episode(seq))
    assert publisher.wait_for_all_acked(Duration(seconds=60))
    wait_until(lambda: messages_on_disk(mcap) == 5, 60, "the 5 episodes flushed", processes=[recorder])
    recorder.process.kill()
    recorder.process.wait(10)

    result = run_cli("bag", "repair", bag)
    assert result.returncode == 0, result.stdout + result.stderr
    check = episode_sequence(bag)
    assert (check.count, check.first, check.last) == (5, 0, 4) and check.ok, check.summary()


def channel_metadata(mcap: Path) -> dict[str, dict[str, str]]:
    """Each channel's metadata by topic, from the channel records of an MCAP file, closed or not."""
    from mcap.records import Channel
    from mcap.stream_reader import StreamReader

    found = {}
    try:
        for record in StreamReader(io.BytesIO(mcap.read_bytes()), emit_chunks=False).records:
            if isinstance(record, Channel):
                found[record.topic] = dict(record.metadata)
    except Exception:  # noqa: BLE001 - the end of what was written
        pass
    return found


def test_repair_recovers_what_a_killed_recorder_wrote(start_node, ros_node, tmp_path):
    bag = tmp_path / "bag"
    recorder = start_node("recorder_node", output=str(bag), flush_interval_sec=3600.0)
    publisher = ros_node.create_publisher(EpisodeRecord, names.EPISODES, qos.EPISODES)
    wait_until(lambda: publisher.get_subscription_count(), 60, "the recorder's subscription", processes=[recorder])
    # Besides the timed flushes (none within this test), the writer closes a chunk per MiB
    # of messages: 200 kB episodes fill two chunks, and the last one stays in memory.
    published = [episode(seq, values=50_000) for seq in range(13)]
    for record in published:
        publisher.publish(record)
    assert publisher.wait_for_all_acked(Duration(seconds=60))
    mcap = bag / "bag.mcap"
    sizes = []

    def settled() -> bool:  # written and no longer growing
        sizes.append(mcap.stat().st_size if mcap.exists() else 0)
        return sizes[-1] > 500_000 and len(sizes) > 10 and sizes[-10] == sizes[-1]

    wait_until(settled, 60, "the recorder's chunks on disk", processes=[recorder])
    recorder.process.kill()
    recorder.process.wait(10)
    assert not (bag / "metadata.yaml").exists()

    result = run_cli("bag", "repair", bag)
    assert result.returncode == 0, result.stderr
    assert "recovered" in result.stdout and "bag.damaged" in result.stdout
    with AnyReader([bag], default_typestore=graph_typestore()) as reader:
        connection = next(c for c in reader.connections if c.topic == "/glocal/episodes")
        # The recorded QoS went along: what the test's publisher offered (reliable; discovery reports no depth).
        offered = connection.ext.offered_qos_profiles
        assert offered == parse_qos(channel_metadata(tmp_path / "bag.damaged" / "bag.mcap")["/glocal/episodes"]
                                    ["offered_qos_profiles"])
        assert [qos.reliability for qos in offered] == [QosReliability.RELIABLE], offered
        records = [reader.deserialize(raw, c.msgtype) for c, _, raw in reader.messages(connections=[connection])]
    seqs = [record.seq for record in records]
    assert 6 <= len(seqs) < len(published) and seqs == list(range(len(seqs)))
    assert np.array_equal(records[-1].observations, np.asarray(published[len(seqs) - 1].observations))
    assert (tmp_path / "bag.damaged" / "bag.mcap").stat().st_size == sizes[-1]  # the original, untouched

    metadata = (bag / "metadata.yaml").read_text()
    result = run_cli("bag", "repair", bag)
    assert result.returncode == 0 and "intact" in result.stdout, result.stdout + result.stderr
    assert (bag / "metadata.yaml").read_text() == metadata and not (tmp_path / "bag.damaged.2").exists()
    assert run_cli("bag", "check", bag).returncode == 0


# Writes episodes through a BagWriter in a process whose files may not grow past a limit, as a
# full disk stops them (EFBIG there, ENOSPC on a disk); prints what the writer reported.
_WRITE_UNTIL_FULL = """
import json, resource, signal, sys
import numpy as np
from rclpy.serialization import serialize_message
from test_bags import episode
from glocal_ros.recording import BagWriter, RecordingStopped
limit = int(sys.argv[2])
signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
resource.setrlimit(resource.RLIMIT_FSIZE, (limit, limit))
writer = BagWriter(sys.argv[1])
written = 0
try:
    for seq in range(10_000):
        writer.write("/glocal/episodes", 10**18 + seq, serialize_message(episode(seq, values=20_000)))
        written += 1
        if seq % 10 == 9:
            writer.flush()
except RecordingStopped as stopped:
    print(json.dumps({"written": written, "kept": stopped.kept, "lost": stopped.lost, "error": str(stopped)}))
writer.close()
"""


def test_a_bag_that_cannot_grow_is_closed_whole_at_its_last_flush(tmp_path):
    bag = tmp_path / "bag"
    limit = BagWriter.RESERVE_BYTES + 2_000_000  # per file: the reserve fits, the MCAP file fills up
    result = subprocess.run([sys.executable, "-c", _WRITE_UNTIL_FULL, str(bag), str(limit)], capture_output=True,
                            text=True, timeout=300, cwd=REPO, env={**os.environ, "PYTHONPATH": str(REPO / "test")})
    assert result.returncode == 0, result.stderr
    report = json.loads(result.stdout)
    assert "bag.mcap" in report["error"] and "File too large" in report["error"], report
    assert report["kept"] % 10 == 0 and 0 < report["lost"] <= 10, report  # flushed every 10 episodes
    # Every episode is kept or counted lost; the failing write, if a write failed rather than a flush.
    assert report["written"] <= report["kept"] + report["lost"] <= report["written"] + 1, report
    assert not (bag / ".space-reserve").exists()
    check = episode_sequence(bag)  # a closed bag: metadata.yaml and a summary, no repair needed
    assert (check.count, check.first, check.last) == (report["kept"], 0, report["kept"] - 1) and check.ok
    assert run_cli("bag", "check", bag).returncode == 0


def _small_disk_available() -> bool:
    """Whether this user may mount a tmpfs in a user namespace of its own (the disk that fills up)."""
    try:
        return subprocess.run(["unshare", "-rm", "true"], capture_output=True, timeout=30).returncode == 0
    except (OSError, subprocess.TimeoutExpired):
        return False


@pytest.mark.skipif(not _small_disk_available(), reason="needs `unshare -rm` to mount a small tmpfs")
def test_a_recorder_on_a_full_disk_closes_its_bag_and_says_why(ros_node, tmp_path):
    """Before, the recorder died with FATAL on ENOSPC and left a bag nothing could read."""
    disk = tmp_path / "disk"
    disk.mkdir()
    # The recorder runs in a namespace where ``disk`` is a 10 MB tmpfs (8 MiB of it the bag's reserve);
    # the bag is copied out before the namespace, and the tmpfs with it, goes away. UDP only: Fast
    # DDS's shared memory does not cross the user namespace.
    script = 'mount -t tmpfs -o size=10m tmpfs "$0" && "$@"; code=$?; cp -r "$0/bag" "$0.out"; exit $code'
    log = tmp_path / "recorder.log"
    with open(log, "w") as out:
        recorder = subprocess.Popen(
            ["unshare", "-rm", "sh", "-c", script, str(disk), *GLOCAL_ROS, "run", "recorder_node", "--ros-args",
             "-p", f"output:={disk / 'bag'}", "-p", "flush_interval_sec:=0.5"],
            stdout=out, stderr=subprocess.STDOUT, cwd=REPO, env={**os.environ, "FASTDDS_BUILTIN_TRANSPORTS": "UDPv4"})
    try:
        publisher = ros_node.create_publisher(EpisodeRecord, names.EPISODES, qos.EPISODES)
        wait_until(lambda: publisher.get_subscription_count() or recorder.poll() is not None, 60,
                   "the recorder's subscription")
        assert recorder.poll() is None, log.read_text()
        for seq in range(200):  # 80 kB episodes, paced so that flushes come between them: 2 MB fill the disk
            publisher.publish(episode(seq, values=20_000))
            assert publisher.wait_for_all_acked(Duration(seconds=30))
            if recorder.poll() is not None:
                break
            time.sleep(0.1)
        assert recorder.wait(60) == 1, log.read_text()
    finally:
        if recorder.poll() is None:
            recorder.kill()
            recorder.wait()
    text = log.read_text()
    assert "recording stopped: cannot write" in text and "No space left on device" in text, text
    assert "FATAL" not in text, text
    check = episode_sequence(tmp_path / "disk.out")  # closed: no repair needed
    assert check.count > 0 and check.first == 0 and check.ok, check.summary()
    assert f"with {check.count} messages" in text, text


def received(ros_node, message_type, topic, profile):
    """(arrival time, message) of everything arriving on ``topic``."""
    arrivals = []
    ros_node.create_subscription(message_type, topic, lambda m: arrivals.append((time.monotonic(), m)), profile)
    return arrivals


def test_replay_keeps_order_and_timing_and_filters_topics(ros_node, tmp_path):
    bag = write_bag(tmp_path / "bag", [
        *[("/glocal/curriculum_state", 0.5 * i, CurriculumState(iteration=i)) for i in range(5)],
        *[("/glocal/evaluations", 0.6 + 0.5 * i, EvaluationResult(policy=f"p{i}")) for i in range(2)],
    ])
    states = received(ros_node, CurriculumState, names.CURRICULUM_STATE, qos.LATCHED)
    evaluations = received(ros_node, EvaluationResult, names.EVALUATIONS, qos.EVENTS)

    result = run_cli("replay", bag, "--rate", "2", "--wait", "20")
    assert result.returncode == 0, result.stderr
    wait_until(lambda: len(states) == 5 and len(evaluations) == 2, 60, "the replayed messages")
    assert [m.iteration for _, m in states] == [0, 1, 2, 3, 4]
    assert [m.policy for _, m in evaluations] == ["p0", "p1"]
    # 0.5 s recorded, at rate 2: 0.25 s apart, 1 s from first to last, timed where they arrive.
    # On a loaded machine delivery bunches them (a late match or a retransmission holds the first
    # ones back; this process's executor takes several at once: a median gap of 0.12 s was seen),
    # so the checks are the ones bunching cannot fake: paced over half the span at least, and
    # faster than rate 1 would be (0.5 s apart).
    gaps = np.diff([t for t, _ in states])
    assert states[-1][0] - states[0][0] > 0.5, gaps  # paced, not sent at once
    assert float(np.median(gaps)) < 0.5, gaps

    states.clear()
    result = run_cli("replay", bag, "--topics", "glocal/curriculum_state", "--start-offset", "0.75", "--wait", "20")
    assert result.returncode == 0, result.stderr
    wait_until(lambda: len(states) == 3, 60, "the replayed states")
    assert [m.iteration for _, m in states] == [2, 3, 4] and len(evaluations) == 2


def test_replay_of_an_episode_publishes_its_joint_states(ros_node, tmp_path):
    """joint_states is volatile: what the replay sends before this reader has matched it is lost
    (on a loaded machine that can outlast the replay's settle time). Looping the episode until one
    whole pass has arrived checks the content without betting on discovery's timing."""
    bag = write_bag(tmp_path / "bag", [("/glocal/episodes", 1.0 * s, episode(s, states=4 + s)) for s in range(3)])
    joint_states = received(ros_node, JointState, names.JOINT_STATES, qos.VIEWER)
    rows = np.asarray(episode(1, states=5).joint_positions).reshape(5, len(JOINTS))

    def one_whole_pass() -> bool:
        positions = [m.position for _, m in joint_states]
        return any(np.allclose(positions[i:i + len(rows)], rows) for i in range(len(positions) - len(rows) + 1))

    replay = subprocess.Popen([*GLOCAL_ROS, "replay", bag, "--episode", "1", "--step-period", "0.05", "--loop",
                               "--wait", "20"], cwd=REPO, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    try:
        wait_until(lambda: one_whole_pass() or replay.poll() is not None, 120, "one whole pass of the 5 joint states")
    finally:
        replay.send_signal(signal.SIGINT)
        output = replay.communicate(timeout=30)[0]
    assert one_whole_pass(), output
    assert all(list(m.name) == JOINTS for _, m in joint_states)
    assert all(m.header.stamp.sec > 0 for _, m in joint_states)  # stamped when published

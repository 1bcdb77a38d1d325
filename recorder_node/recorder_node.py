"""recorder_node: every topic of the graph into one rosbag2 directory (MCAP, zstd chunks).

Subscribes raw (serialized) to the topics of ``glocal_ros.topics.RECORDED_TOPICS``
with the QoS their publishers offer, so that messages are written as they
travelled, and closes the bag cleanly on SIGINT/SIGTERM.

EpisodeRecord.seq is checked as episodes arrive: every gap (an episode the
recorder never got) is logged as a warning when it is seen, and the total
with every gap when the bag closes (``glocal-ros bag check`` does the same
on a bag afterwards). A recorder that was killed leaves a bag without
metadata.yaml: ``glocal-ros bag repair`` recovers it, up to the last flush:
every ``flush_interval_sec`` the pending chunk is closed and synced to disk.

A bag that cannot be written (a full disk) is closed at its last flush,
whole and readable (``BagWriter``); the node logs why and what was lost,
and exits with code 1: a recording with a hole is not a recording.
"""

from __future__ import annotations

import importlib
from dataclasses import replace
from pathlib import Path

from glocal_interfaces.msg import EpisodeRecord
from rclpy.node import Node
from rclpy.qos import QoSProfile
from rclpy.serialization import deserialize_message

from glocal_ros.recording import BagWriter, RecordingStopped, SequenceTracker, episode_seq_from_cdr
from glocal_ros.topics import EPISODES_TOPIC, RECORDED_TOPICS, TopicSpec
from node_common import qos
from node_common.params import declare
from node_common.runner import spin_node


def message_class(msgtype: str):
    """``"pkg/msg/Name"`` -> the generated Python class ``pkg.msg.Name``."""
    package, kind, name = msgtype.split("/")
    return getattr(importlib.import_module(f"{package}.{kind}"), name)


def subscription_qos(spec: TopicSpec) -> QoSProfile:
    """The publisher's QoS, with a queue of 1000 at least on reliable topics: a burst must not overflow it."""
    offered = spec.qos
    return qos.profile(replace(offered, depth=max(offered.depth, 1000)) if offered.reliable else offered)


class RecorderNode(Node):
    def __init__(self) -> None:
        super().__init__("recorder_node")
        output = declare(self, "output", "bag", "rosbag2 directory to create (must not exist)")
        flush_interval = declare(self, "flush_interval_sec", 2.0, "seconds between chunk flushes to disk: "
                                 "the most a killed recorder loses", min_value=0.1, max_value=86_400.0)
        self.writer = BagWriter(Path(output))
        self.exit_code = 0
        self.create_timer(flush_interval, self._flush)
        self.episode_seqs = SequenceTracker()
        for spec in RECORDED_TOPICS:
            self.create_subscription(
                message_class(spec.msgtype), spec.name, self._writer_for(spec.name), subscription_qos(spec), raw=True
            )
        self.get_logger().info(f"recording {len(RECORDED_TOPICS)} topics into {output}")

    def _flush(self) -> None:
        try:
            self.writer.flush()
        except RecordingStopped as stopped:
            self._stop(stopped)

    def _stop(self, stopped: RecordingStopped) -> None:
        """The bag is closed (see ``BagWriter``): say so once, and end the node."""
        if self.exit_code:
            return
        self.exit_code = 1
        self.get_logger().error(f"recording stopped: {stopped}")
        self.context.try_shutdown()

    def _writer_for(self, topic: str):
        def write(data: bytes) -> None:
            try:
                self.writer.write(topic, self.get_clock().now().nanoseconds, data)
            except RecordingStopped as stopped:
                self._stop(stopped)

        if topic != EPISODES_TOPIC:
            return write

        def write_and_check(data: bytes) -> None:
            write(data)  # first: a message that fails the check is still recorded
            self._check_episode_seq(data)

        return write_and_check

    def _check_episode_seq(self, data: bytes) -> None:
        """Warn about a gap in EpisodeRecord.seq as soon as it shows.

        The seq is read from the CDR bytes without decoding the record (its
        arrays can be large); an encoding that parser does not handle is
        decoded in full instead.
        """
        seq = episode_seq_from_cdr(data)
        if seq is None:
            seq = deserialize_message(data, EpisodeRecord).seq
        highest = self.episode_seqs.highest
        self.episode_seqs.add(seq)
        if highest is None:
            if seq:
                self.get_logger().info(f"first episode has seq {seq}: seq 0..{seq - 1} came before the recording")
        elif seq > highest + 1:
            missing = f"{highest + 1}" if seq == highest + 2 else f"{highest + 1}..{seq - 1}"
            self.get_logger().warning(f"episode seq gap: {missing} missing (got {seq} after {highest})")
        elif seq <= highest:
            self.get_logger().warning(f"episode seq {seq} after {highest}: a duplicate or out of order")

    def close(self) -> None:
        self.writer.close()
        counts = ", ".join(f"{topic} {count}" for topic, count in self.writer.counts.items() if count)
        self.get_logger().info(f"closed {self.writer.path}: {counts or 'no messages'}")
        check = self.episode_seqs.result()
        log = self.get_logger().info if check.ok else self.get_logger().warning
        log(f"{EPISODES_TOPIC}: {check.summary()}")


def main(args=None) -> int:
    return spin_node(RecorderNode, args)


if __name__ == "__main__":
    raise SystemExit(main())

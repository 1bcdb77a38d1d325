"""recorder_node: every topic of the graph into one rosbag2 directory (MCAP, zstd chunks).

Subscribes raw (serialized) to the topics of ``glocal_ros.recording.GRAPH_TOPICS``
with the QoS their publishers offer, so that messages are written as they
travelled, and closes the bag cleanly on SIGINT/SIGTERM. Issue "Record,
replay, report" adds sequence-gap checks, repair of a killed recorder's bag
and topic discovery.
"""

from __future__ import annotations

import importlib
from pathlib import Path

from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

from glocal_ros.recording import GRAPH_TOPICS, BagWriter, TopicSpec
from node_common.params import declare
from node_common.runner import spin_node


def message_class(msgtype: str):
    """``"pkg/msg/Name"`` -> the generated Python class ``pkg.msg.Name``."""
    package, kind, name = msgtype.split("/")
    return getattr(importlib.import_module(f"{package}.{kind}"), name)


def subscription_qos(spec: TopicSpec) -> QoSProfile:
    return QoSProfile(
        history=HistoryPolicy.KEEP_LAST,
        depth=max(spec.depth, 1000) if spec.reliable else spec.depth,
        reliability=ReliabilityPolicy.RELIABLE if spec.reliable else ReliabilityPolicy.BEST_EFFORT,
        durability=DurabilityPolicy.TRANSIENT_LOCAL if spec.transient_local else DurabilityPolicy.VOLATILE,
    )


class RecorderNode(Node):
    def __init__(self) -> None:
        super().__init__("recorder_node")
        output = declare(self, "output", "bag", "rosbag2 directory to create (must not exist)")
        self.writer = BagWriter(Path(output))
        for spec in GRAPH_TOPICS:
            self.create_subscription(
                message_class(spec.msgtype), spec.name, self._writer_for(spec.name), subscription_qos(spec), raw=True
            )
        self.get_logger().info(f"recording {len(GRAPH_TOPICS)} topics into {output}")

    def _writer_for(self, topic: str):
        def write(data: bytes) -> None:
            self.writer.write(topic, self.get_clock().now().nanoseconds, data)

        return write

    def close(self) -> None:
        self.writer.close()
        counts = ", ".join(f"{topic} {count}" for topic, count in self.writer.counts.items() if count)
        self.get_logger().info(f"closed {self.writer.path}: {counts or 'no messages'}")


def main(args=None) -> int:
    return spin_node(RecorderNode, args)


if __name__ == "__main__":
    raise SystemExit(main())

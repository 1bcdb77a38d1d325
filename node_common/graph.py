"""Subscribing to a topic of the graph generically: its message class from the type name, and a QoS that
matches what its publishers offer.

Shared by the nodes that take every topic as it comes (recorder_node, foxglove_bridge_node): both subscribe
raw, by type name, with the QoS that ``adapted_qos`` derives from the publishers the graph lists.
"""

from __future__ import annotations

import importlib
from typing import Sequence

from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy

from glocal_ros.topics import QosSpec


def message_class(msgtype: str):
    """``"pkg/msg/Name"`` -> the generated Python class ``pkg.msg.Name``."""
    package, kind, name = msgtype.split("/")
    return getattr(importlib.import_module(f"{package}.{kind}"), name)


def adapted_qos(table: QosSpec, offers: Sequence[QoSProfile]) -> QosSpec:
    """The QoS to subscribe with, given what the topic's publishers offer (``table`` while there are none).

    As rosbag2's recorder adapts it: reliable only if every publisher is
    (a reliable reader matches no best-effort writer), transient local only
    if every one is (a transient-local reader matches no volatile writer).
    """
    if not offers:
        return table
    reliable = all(offer.reliability == ReliabilityPolicy.RELIABLE for offer in offers)
    latched = all(offer.durability == DurabilityPolicy.TRANSIENT_LOCAL for offer in offers)
    return QosSpec(reliable=reliable, transient_local=latched, depth=table.depth)

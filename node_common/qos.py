"""rclpy QoS profiles of the graph, built from the plain data of ``glocal_ros.topics``.

The table there is the one place a topic's QoS is decided; this module only
turns it into ``QoSProfile`` objects.
"""

from __future__ import annotations

from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

from glocal_ros import topics
from glocal_ros.topics import QosSpec


def profile(spec: QosSpec) -> QoSProfile:
    """``spec`` as an rclpy profile (keep-last ``spec.depth``)."""
    return QoSProfile(
        history=HistoryPolicy.KEEP_LAST,
        depth=spec.depth,
        reliability=ReliabilityPolicy.RELIABLE if spec.reliable else ReliabilityPolicy.BEST_EFFORT,
        durability=DurabilityPolicy.TRANSIENT_LOCAL if spec.transient_local else DurabilityPolicy.VOLATILE,
    )


EPISODES = profile(topics.EPISODES_QOS)
LATCHED = profile(topics.LATCHED_QOS)
EVENTS = profile(topics.EVENTS_QOS)
VIEWER = profile(topics.VIEWER_QOS)
DESCRIPTION = profile(topics.DESCRIPTION_QOS)
CLOCK = profile(topics.CLOCK_QOS)

"""QoS profiles of the graph, chosen per topic kind (see README, "Topics")."""

from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

#: Every episode must reach the recorder: reliable, and a deep queue so that a
#: burst of finished episodes (N envs ending together) is never dropped.
EPISODES = QoSProfile(
    history=HistoryPolicy.KEEP_LAST,
    depth=1000,
    reliability=ReliabilityPolicy.RELIABLE,
    durability=DurabilityPolicy.VOLATILE,
)

#: Curriculum state and assignments: a late joiner (viewer, recorder) gets the
#: latest one at once.
LATCHED = QoSProfile(
    history=HistoryPolicy.KEEP_LAST,
    depth=10,
    reliability=ReliabilityPolicy.RELIABLE,
    durability=DurabilityPolicy.TRANSIENT_LOCAL,
)

#: Reliable event streams that are not latched (evaluations, training progress).
EVENTS = QoSProfile(
    history=HistoryPolicy.KEEP_LAST,
    depth=100,
    reliability=ReliabilityPolicy.RELIABLE,
    durability=DurabilityPolicy.VOLATILE,
)

#: Throttled viewer streams (joint states, object pose, grasp state): a lost
#: sample is replaced by the next one.
VIEWER = QoSProfile(
    history=HistoryPolicy.KEEP_LAST,
    depth=5,
    reliability=ReliabilityPolicy.BEST_EFFORT,
    durability=DurabilityPolicy.VOLATILE,
)

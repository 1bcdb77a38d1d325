"""The graph's topics, one table: name, message type, QoS, recorded or not.

Every node, the recorder, replay and the analysis read their topic names and
QoS from here; ``node_common.qos`` turns each ``QosSpec`` into an rclpy
``QoSProfile`` and ``node_common.names`` gives nodes the names relative to
their namespace. ROS-free on purpose: QoS is plain data (reliability,
durability, keep-last depth), so the recorder's bag metadata and the
analysis need no ROS client.
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class QosSpec:
    """A publisher's offered QoS; history is always keep-last ``depth``."""

    reliable: bool  # else best effort
    transient_local: bool  # else volatile
    depth: int


#: Every episode must reach the recorder: reliable, and a deep queue so that a
#: burst of finished episodes (N envs ending together) is never dropped.
EPISODES_QOS = QosSpec(reliable=True, transient_local=False, depth=1000)
#: Curriculum state and assignments: a late joiner (viewer, recorder) gets the
#: latest one at once.
LATCHED_QOS = QosSpec(reliable=True, transient_local=True, depth=10)
#: Reliable event streams that are not latched (evaluations, training progress).
EVENTS_QOS = QosSpec(reliable=True, transient_local=False, depth=100)
#: Throttled viewer streams (joint states, object pose, grasp state, /tf): reliable with a small
#: queue, which reliable and best-effort subscribers alike accept (a tutorial-style
#: ``create_subscription(T, name, cb, 10)`` is reliable and would get nothing from a best-effort
#: publisher); joint_state_broadcaster and robot_state_publisher offer the same.
VIEWER_QOS = QosSpec(reliable=True, transient_local=False, depth=10)
#: What a viewer that starts late must still get at once: robot_description, /tf_static, the
#: object marker (as robot_state_publisher offers them: reliable, transient local, depth 1).
DESCRIPTION_QOS = QosSpec(reliable=True, transient_local=True, depth=1)
#: /clock: one message per lockstep step. Reliable is accepted by rclpy's own best-effort
#: time-source subscription and by reliable ones; the deeper queue lets a recorder that falls
#: a second behind still get every tick.
CLOCK_QOS = QosSpec(reliable=True, transient_local=False, depth=100)


@dataclass(frozen=True)
class TopicSpec:
    name: str  # absolute, as a root-namespace recorder subscribes and a bag stores it
    msgtype: str  # e.g. glocal_interfaces/msg/EpisodeRecord
    qos: QosSpec
    recorded: bool  # written to the run's bag by recorder_node
    #: Published by a sim/learner pair (sim_node or learner_node), so under the pair's namespace in a run of
    #: several pairs; else the curriculum's, under the run's namespace.
    of_pair: bool = True

    @property
    def relative_name(self) -> str:
        """The name a node uses: it follows the node's namespace (several sim/learner pairs per domain)."""
        return self.name.lstrip("/")


EPISODES = TopicSpec("/glocal/episodes", "glocal_interfaces/msg/EpisodeRecord", EPISODES_QOS, recorded=True)
CURRICULUM_STATE = TopicSpec("/glocal/curriculum_state", "glocal_interfaces/msg/CurriculumState", LATCHED_QOS,
                             recorded=True, of_pair=False)
TASK_ASSIGNMENT = TopicSpec("/glocal/task_assignment", "glocal_interfaces/msg/TaskAssignment", LATCHED_QOS,
                            recorded=True, of_pair=False)
TRAINING_PROGRESS = TopicSpec("/glocal/training_progress", "glocal_interfaces/msg/TrainingProgress", EVENTS_QOS,
                              recorded=True)
EVALUATIONS = TopicSpec("/glocal/evaluations", "glocal_interfaces/msg/EvaluationResult", EVENTS_QOS, recorded=True)
JOINT_STATES = TopicSpec("/joint_states", "sensor_msgs/msg/JointState", VIEWER_QOS, recorded=True)
OBJECT_POSE = TopicSpec("/glocal/object_pose", "geometry_msgs/msg/PoseStamped", VIEWER_QOS, recorded=True)
GRASP_STATE = TopicSpec("/glocal/grasp_state", "glocal_interfaces/msg/GraspState", VIEWER_QOS, recorded=True)
ROBOT_DESCRIPTION = TopicSpec("/robot_description", "std_msgs/msg/String", DESCRIPTION_QOS, recorded=True)
TF = TopicSpec("/tf", "tf2_msgs/msg/TFMessage", VIEWER_QOS, recorded=True)
TF_STATIC = TopicSpec("/tf_static", "tf2_msgs/msg/TFMessage", DESCRIPTION_QOS, recorded=True)
OBJECT_MARKER = TopicSpec("/glocal/object_marker", "visualization_msgs/msg/Marker", DESCRIPTION_QOS, recorded=True)
CLOCK = TopicSpec("/clock", "rosgraph_msgs/msg/Clock", CLOCK_QOS, recorded=True)

#: Every topic of the graph, with the QoS its publisher offers.
GRAPH_TOPICS: tuple[TopicSpec, ...] = (
    EPISODES, CURRICULUM_STATE, TASK_ASSIGNMENT, TRAINING_PROGRESS, EVALUATIONS, JOINT_STATES, OBJECT_POSE,
    GRASP_STATE, ROBOT_DESCRIPTION, TF, TF_STATIC, OBJECT_MARKER, CLOCK,
)
#: The curriculum's replay of its journal when it resumes, as ROS diagnostics (``rqt_robot_monitor`` reads
#: them at the root namespace): what the launcher's watchdog hears before the first state of a resumed run.
#: Outside ``GRAPH_TOPICS``: neither recorded nor served to viewers.
DIAGNOSTICS = TopicSpec("/diagnostics", "diagnostic_msgs/msg/DiagnosticArray", EVENTS_QOS, recorded=False,
                        of_pair=False)
#: The name of the replay's DiagnosticStatus, after its node's: ``/curriculum_node: journal replay``.
REPLAY_STATUS = "journal replay"
#: What recorder_node writes to a run's bag.
RECORDED_TOPICS: tuple[TopicSpec, ...] = tuple(topic for topic in GRAPH_TOPICS if topic.recorded)

#: The topic whose EpisodeRecord.seq counts a sim node's episodes from 0 without gaps.
EPISODES_TOPIC = EPISODES.name

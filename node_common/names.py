"""Topic, service and action names of the graph (relative: they follow the
node's namespace, so several sim/learner pairs can share one domain).

Topic names come from the one table, ``glocal_ros.topics``.
"""

from glocal_ros import topics

SIM_RESET = "sim/reset"
SIM_STEP = "sim/step"
LEARNER_TRAIN = "learner/train"
LEARNER_EVALUATE = "learner/evaluate"
LEARNER_LIST_POLICIES = "learner/list_policies"
LEARNER_COPY_POLICY = "learner/copy_policy"

JOINT_STATES = topics.JOINT_STATES.relative_name
OBJECT_POSE = topics.OBJECT_POSE.relative_name
GRASP_STATE = topics.GRASP_STATE.relative_name
EPISODES = topics.EPISODES.relative_name
CURRICULUM_STATE = topics.CURRICULUM_STATE.relative_name
TASK_ASSIGNMENT = topics.TASK_ASSIGNMENT.relative_name
TRAINING_PROGRESS = topics.TRAINING_PROGRESS.relative_name
EVALUATIONS = topics.EVALUATIONS.relative_name
ROBOT_DESCRIPTION = topics.ROBOT_DESCRIPTION.relative_name
TF = topics.TF.relative_name
TF_STATIC = topics.TF_STATIC.relative_name
OBJECT_MARKER = topics.OBJECT_MARKER.relative_name
CLOCK = topics.CLOCK.relative_name
DIAGNOSTICS = topics.DIAGNOSTICS.relative_name

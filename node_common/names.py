"""Topic, service and action names of the graph (relative: they follow the
node's namespace, so several sim/learner pairs can share one domain)."""

SIM_RESET = "sim/reset"
SIM_STEP = "sim/step"
LEARNER_TRAIN = "learner/train"
LEARNER_EVALUATE = "learner/evaluate"
LEARNER_LIST_POLICIES = "learner/list_policies"
LEARNER_COPY_POLICY = "learner/copy_policy"

JOINT_STATES = "joint_states"
OBJECT_POSE = "glocal/object_pose"
GRASP_STATE = "glocal/grasp_state"
EPISODES = "glocal/episodes"
CURRICULUM_STATE = "glocal/curriculum_state"
TASK_ASSIGNMENT = "glocal/task_assignment"
TRAINING_PROGRESS = "glocal/training_progress"
EVALUATIONS = "glocal/evaluations"

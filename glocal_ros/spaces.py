"""The grasp env as everyone outside the sim sees it: sizes and the control period.

Sizes are the paper's observation and action (Section IV-A); ``sim_node.grasp_env``
builds its spaces from them and the learner its policies. The control period
is the default one of ``sim_node.grasp_env.GraspEnvConfig``, which takes its
defaults from here, so that a replay paces an episode's joint states without
loading the simulator.
"""

from glocal_ros.tasks import NUM_TASKS

#: one-hot task (49) + gripper pose (6) + object pose (6) + two finger-contact bits.
OBS_DIM = NUM_TASKS + 6 + 6 + 2
#: gripper open/close, rotation about the table normal, 3D translation.
ACTION_DIM = 5
#: Version of the meaning of the OBS_DIM numbers (``sim_node.grasp_env``). Layout 1 gave the object's
#: yaw relative to the gripper's as the sine and cosine of twice that angle, which hid a half turn;
#: layout 2 gives those of the angle itself. A policy of one layout acts blindly on another of the
#: same size, so stored policies record theirs and the learner refuses a mismatch.
OBSERVATION_LAYOUT = 2

#: Physics steps per env step, by default.
SUBSTEPS = 10
#: One physics step (s), by default: PyBullet's 240 Hz.
PHYSICS_TIMESTEP = 1.0 / 240.0
#: The env's default control period (s): physics substeps per env step x physics timestep.
CONTROL_PERIOD = SUBSTEPS * PHYSICS_TIMESTEP

"""glocal_ros: GloCAL curriculum learning of Panda grasps, the ROS-free library.

Importing the package registers the Gymnasium environment
``glocal_ros/Grasp-v0`` (``gymnasium.make("glocal_ros/Grasp-v0", task="A0")``);
the environment itself lives in ``sim_node.grasp_env`` and is only imported
when made.
"""

import gymnasium

__version__ = "0.1.0"

GRASP_ENV_ID = "glocal_ros/Grasp-v0"

if GRASP_ENV_ID not in gymnasium.registry:
    gymnasium.register(id=GRASP_ENV_ID, entry_point="sim_node.grasp_env:GraspEnv")

"""glocal_ros: GloCAL curriculum learning of Panda grasps, the ROS-free library.

The Gymnasium environment is the sim's: importing ``sim_node.grasp_env``
registers it as ``glocal_ros/Grasp-v0`` (``sim_contract.GRASP_ENV_ID``), so
``gymnasium.make("sim_node.grasp_env:glocal_ros/Grasp-v0", task="A0")`` makes
it from anywhere; the library itself never names a node package.
"""

__version__ = "0.1.0"

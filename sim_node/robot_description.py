"""The robot as viewers see it: the very URDF the sim loads, with mesh paths a viewer resolves.

PyBullet loads the Panda from pybullet_data, whose URDF names its meshes
``package://meshes/...`` (PyBullet reads them relative to the file; no
viewer can). ``robot_description`` rewrites them to
``package://glocal_ros/robots/franka_panda/meshes/...``: setup.py installs
those same mesh files under ``share/glocal_ros/robots/franka_panda/``, so RViz
and Foxglove find them through the installed package (ament index, or
Foxglove's ROS package path). Nothing else changes: links, joints and
origins are the simulated ones.
"""

from __future__ import annotations

from pathlib import Path

import pybullet_data

#: The robot's URDF inside pybullet_data (what ``PandaRobot`` loads).
PANDA_URDF = "franka_panda/panda.urdf"
#: Where setup.py installs the Panda's meshes, under share/glocal_ros.
MESH_SHARE_DIR = "robots/franka_panda"
_SIM_MESH_PREFIX = "package://meshes/"
_VIEWER_MESH_PREFIX = f"package://glocal_ros/{MESH_SHARE_DIR}/meshes/"


def panda_urdf_path() -> Path:
    return Path(pybullet_data.getDataPath()) / PANDA_URDF


def robot_description() -> str:
    """The Panda's URDF for ``robot_description``, meshes as ``package://glocal_ros/...``."""
    return panda_urdf_path().read_text().replace(_SIM_MESH_PREFIX, _VIEWER_MESH_PREFIX)

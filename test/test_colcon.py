"""The repo builds with colcon from its root, as on a full ROS 2 Jazzy install.

The venv stands in for /opt/ros/jazzy: its prefix holds the ROS wheels'
share/ and CMake files. The build runs in a copy of the checkout, and the
installed node starts from install/ with colcon's setup.sh sourced.
"""

import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from conftest import REPO

pytestmark = pytest.mark.slow


def checkout_copy(destination: Path) -> None:
    files = subprocess.run(["git", "ls-files", "-co", "--exclude-standard", "-z"], cwd=REPO, check=True,
                           capture_output=True).stdout.decode().split("\0")
    for name in filter(None, files):
        if (REPO / name).is_file():
            (destination / name).parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(REPO / name, destination / name)


def test_colcon_build_installs_runnable_nodes(tmp_path):
    workspace = tmp_path / "ws"
    checkout_copy(workspace)
    env = {**os.environ, "AMENT_PREFIX_PATH": sys.prefix, "CMAKE_PREFIX_PATH": sys.prefix}
    build = subprocess.run(
        [str(Path(sys.prefix) / "bin" / "colcon"), "build", "--cmake-args",
         f"-DPython3_EXECUTABLE={sys.executable}", "-DBUILD_TESTING=OFF"],
        cwd=workspace, env=env, capture_output=True, text=True, timeout=900,
    )
    assert build.returncode == 0, build.stdout + build.stderr
    assert "2 packages finished" in build.stdout

    # Every mesh robot_description names resolves in the installed package, as RViz resolves package://.
    from glocal_ros.urdf import parse_urdf
    from sim_node.robot_description import robot_description

    share = workspace / "install" / "glocal_ros" / "share"
    meshes = {visual.mesh for visuals in parse_urdf(robot_description()).visuals.values() for visual in visuals}
    assert meshes
    for mesh in meshes:
        assert (share / mesh.removeprefix("package://")).is_file(), mesh

    executable = workspace / "install" / "glocal_ros" / "lib" / "glocal_ros" / "curriculum_node"
    assert executable.is_file() and os.access(executable, os.X_OK)
    # Started away from the checkout, so that only install/ can provide the packages; with
    # no learner on the domain the node must start, wait, then exit 1 with a clear reason.
    run = subprocess.run(
        ["sh", "-c", f'. "{workspace}/install/setup.sh" && exec "{executable}" --ros-args '
                     "-p learner_timeout_sec:=2.0 -p tasks:=A0,A1"],
        cwd=tmp_path, env={k: v for k, v in os.environ.items() if k not in ("AMENT_PREFIX_PATH", "PYTHONPATH")},
        capture_output=True, text=True, timeout=120,
    )
    assert run.returncode == 1, run.stdout + run.stderr
    assert "learner/evaluate is not available" in run.stdout + run.stderr

"""The repo builds in a colcon workspace as a ROS user builds it: cloned into ``ws/src``, then
``colcon build`` and ``source install/setup.bash`` in ``ws``.

The checkout is copied as ``git clone`` gives it (tracked files and new ones git does not ignore,
links kept) into a temporary ``ws/src/glocal_ros``; a plain ``colcon build`` there must find and
build both packages, glocal_interfaces (``msg_schemas/``) and glocal_ros (``colcon/glocal_ros``,
see ``colcon.pkg``). The venv stands in for /opt/ros/jazzy: its prefix holds the ROS wheels'
share/ and CMake files. The installed node then starts from ``install/`` with its setup.bash
sourced, away from the checkout, as ``ros2 run glocal_ros curriculum_node`` starts it. The README's
``rosdep install --from-paths ...`` names folders in which rosdep finds both packages too.
"""

import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from conftest import REPO

pytestmark = pytest.mark.slow


def clone_checkout(destination: Path) -> None:
    """The checkout's files as a clone has them: tracked and untracked-but-not-ignored, links as links."""
    files = subprocess.run(["git", "ls-files", "-co", "--exclude-standard", "-z"], cwd=REPO, check=True,
                           capture_output=True).stdout.decode().split("\0")
    for name in filter(None, files):
        source, target = REPO / name, destination / name
        if source.is_symlink():
            target.parent.mkdir(parents=True, exist_ok=True)
            target.symlink_to(os.readlink(source))
        elif source.is_file():
            target.parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(source, target)


def in_sourced_workspace(workspace: Path, command: str, cwd: Path) -> subprocess.CompletedProcess:
    """``command`` in bash after ``source install/setup.bash``, with nothing of the checkout or the venv's
    package index on the paths beforehand."""
    env = {k: v for k, v in os.environ.items() if k not in ("AMENT_PREFIX_PATH", "PYTHONPATH")}
    return subprocess.run(["bash", "-c", f'source "{workspace}/install/setup.bash" && {command}'], cwd=cwd,
                          env=env, capture_output=True, text=True, timeout=120)


def test_a_workspace_clone_builds_both_packages_and_runs_a_node(tmp_path):
    workspace = tmp_path / "ws"
    clone_checkout(workspace / "src" / "glocal_ros")

    # The README's rosdep step sees both packages: rosdep (catkin_pkg) stops at a package.xml as colcon does,
    # and has no colcon.pkg, so the README names msg_schemas/ for it.
    from catkin_pkg.packages import find_packages

    (paths,) = re.findall(r"rosdep install --from-paths (.+?) --ignore-src", (REPO / "README.md").read_text())
    found = {package.name for path in paths.split() for package in find_packages(str(workspace / path)).values()}
    assert found == {"glocal_ros", "glocal_interfaces"}, paths
    env = {**os.environ, "AMENT_PREFIX_PATH": sys.prefix, "CMAKE_PREFIX_PATH": sys.prefix}
    build = subprocess.run(
        [str(Path(sys.prefix) / "bin" / "colcon"), "build", "--cmake-args",
         f"-DPython3_EXECUTABLE={sys.executable}", "-DBUILD_TESTING=OFF"],
        cwd=workspace, env=env, capture_output=True, text=True, timeout=900,
    )
    assert build.returncode == 0, build.stdout + build.stderr
    assert "2 packages finished" in build.stdout, build.stdout
    assert "tf2_msgs" not in build.stdout, "the venv-only tf2_msgs (tools/) must not shadow the system's"
    install = workspace / "install"
    assert sorted(path.name for path in install.iterdir() if path.is_dir()) == ["glocal_interfaces", "glocal_ros"]

    # Every mesh robot_description names resolves in the installed package, as RViz resolves package://.
    from glocal_ros.urdf import parse_urdf
    from sim_node.robot_description import robot_description

    share = install / "glocal_ros" / "share"
    meshes = {visual.mesh for visuals in parse_urdf(robot_description()).visuals.values() for visual in visuals}
    assert meshes
    for mesh in meshes:
        assert (share / mesh.removeprefix("package://")).is_file(), mesh

    # The sourced workspace, not the venv's own installs, provides both packages.
    where = in_sourced_workspace(
        workspace, f'"{sys.executable}" -c "import glocal_interfaces.msg, node_common; '
                   f'print(glocal_interfaces.msg.__file__); print(node_common.__file__)"', tmp_path)
    assert where.returncode == 0, where.stdout + where.stderr
    interfaces, library = where.stdout.split()
    assert Path(interfaces).is_relative_to(install / "glocal_interfaces"), interfaces
    assert Path(library).is_relative_to(install / "glocal_ros"), library

    # What `ros2 run glocal_ros curriculum_node` runs; with no learner on the domain the node must
    # start, wait, then exit 1 with a clear reason.
    executable = install / "glocal_ros" / "lib" / "glocal_ros" / "curriculum_node"
    assert executable.is_file() and os.access(executable, os.X_OK)
    run = in_sourced_workspace(workspace, f'exec "{executable}" --ros-args -p learner_timeout_sec:=2.0 '
                                          "-p tasks:=A0,A1", tmp_path)
    assert run.returncode == 1, run.stdout + run.stderr
    assert "learner/evaluate is not available" in run.stdout + run.stderr

"""ament_python package ``glocal_ros``: pip-installable and colcon-buildable.

It holds every Python room: the library ``glocal_ros``, ``node_common``, the
node packages and the application ``glocal_app`` (the ``glocal-ros`` script).

Dependencies are pinned in requirements.txt (and constraints.txt); ``make
setup`` installs them. Nodes are installed twice on purpose: as console
scripts (on PATH in a venv) and as plain executables in ``lib/glocal_ros``,
where ``ros2 run`` looks on a full ROS 2 install (pip ignores setup.cfg's
``install_scripts``, colcon honours it).

Paths are relative to the folder setuptools runs in: this one (pip, ``make setup``) or
``colcon/glocal_ros``, whose links to this folder's files are where a colcon workspace finds the
package (``colcon.pkg`` says why); a package folder missing there stops the build.
"""

import importlib.util
import os
import runpy
from pathlib import Path

from setuptools import find_packages, setup

PACKAGE = "glocal_ros"
HERE = Path(__file__).resolve().parent
# Read, not imported: the package's dependencies need not be installed yet.
NODES = runpy.run_path(str(HERE / "glocal_app" / "nodes.py"))["NODES"]
#: The Python packages, each with its subpackages.
TOP_LEVEL = (PACKAGE, "node_common", *NODES, "glocal_app")
_missing = [name for name in TOP_LEVEL if not (Path(name) / "__init__.py").is_file()]
if _missing:
    raise SystemExit(f"setup.py runs in {Path.cwd()}, which lacks the packages {', '.join(_missing)} "
                     f"(colcon/glocal_ros needs a link to each)")


def asset_files() -> list[tuple[str, list[str]]]:
    """Everything under assets/, mirrored into share/glocal_ros/assets."""
    entries = []
    for folder, _, files in sorted(os.walk(HERE / "assets")):
        if files:
            relative = Path(folder).relative_to(HERE)
            entries.append((f"share/{PACKAGE}/{relative}", sorted(str(relative / f) for f in files)))
    return entries


def panda_mesh_files() -> list[tuple[str, list[str]]]:
    """The Panda meshes of pybullet_data, into share/glocal_ros/robots/franka_panda (sim_node.robot_description).

    Found without importing pybullet, which must be installed before this package (make setup does).
    Paths relative to the folder setuptools runs in: colcon refuses absolute ones.
    """
    spec = importlib.util.find_spec("pybullet_data")
    if spec is None or not spec.submodule_search_locations:
        raise SystemExit("pybullet (pybullet_data) must be installed before glocal_ros: its Panda meshes are "
                         "installed for viewers")
    panda = Path(list(spec.submodule_search_locations)[0]) / "franka_panda"
    return [(f"share/{PACKAGE}/robots/franka_panda/{folder.relative_to(panda)}",
             sorted(os.path.relpath(f) for f in folder.iterdir() if f.is_file()))
            for folder in sorted(panda.rglob("*")) if folder.is_dir()] + \
        [(f"share/{PACKAGE}/robots/franka_panda", [os.path.relpath(panda / "LICENSE.txt")])]


setup(
    name=PACKAGE,
    version="0.1.0",
    packages=find_packages(include=[name for top in TOP_LEVEL for name in (top, f"{top}.*")]),
    data_files=[
        ("share/ament_index/resource_index/packages", [f"resource/{PACKAGE}"]),
        (f"share/{PACKAGE}", ["package.xml"]),
        (f"lib/{PACKAGE}", [f"bin/{node}" for node in NODES]),
        # `ros2 launch glocal_ros glocal.launch.py` finds launch files in share/<package>/launch.
        (f"share/{PACKAGE}/launch",
         sorted(str(path.relative_to(HERE)) for path in (HERE / "launch").glob("*.launch.py"))),
        *asset_files(),
        *panda_mesh_files(),
    ],
    install_requires=["setuptools"],
    zip_safe=False,
    maintainer="glocal_ros maintainers",
    maintainer_email="maintainers@glocal-ros.org",
    description="GloCAL curriculum learning of Panda grasps as a ROS 2 node graph",
    license="Apache-2.0",
    entry_points={
        "console_scripts": [
            "glocal-ros = glocal_app.cli:main",
            *(f"{node} = {node}.{node}:main" for node in NODES),
        ],
    },
)

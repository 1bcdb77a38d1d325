"""package.xml declares what the code imports, so that rosdep installs it on a full ROS 2 install.

Imports are read from every Python file's syntax tree (lazy ones included,
as ``test_rooms`` reads them) in the rooms, ``bin/`` and ``launch/``. A ROS
package is a name in the ament index (the venv's prefix holds the wheels'
and the built interfaces' markers), or ``launch``/``launch_ros``, which are
not installable here. Every other third-party import must be in
``PYTHON_KEYS``: its rosdep key, declared, or ``None`` when rosdistro has
none, which package.xml's comment must then name.
"""

import sys
from pathlib import Path

import pytest
from catkin_pkg.package import parse_package

from conftest import REPO
from test_rooms import ROOMS, imported_roots

#: ROS packages the code imports that the venv cannot hold (not on PyPI): launch/glocal.launch.py's.
ROS_PACKAGES_NOT_HERE = {"launch", "launch_ros"}
#: Third-party Python import -> rosdep key (None: rosdistro has no key; package.xml's comment says so).
PYTHON_KEYS: dict[str, str | None] = {
    "numpy": "python3-numpy",
    "scipy": "python3-scipy",
    "sklearn": "python3-sklearn",
    "skimage": "python3-skimage",
    "matplotlib": "python3-matplotlib",
    "PIL": "python3-pil",
    "yaml": "python3-yaml",
    "ruamel": "python3-ruamel.yaml",
    "tqdm": "python3-tqdm",
    "torch": "python3-torch",
    "pybullet": "python3-pybullet-pip",
    "pybullet_data": "python3-pybullet-pip",
    "pybullet_utils": "python3-pybullet-pip",
    "gymnasium": "python3-gymnasium-pip",
    "stable_baselines3": "python3-stable-baselines3-pip",
    "sbx": None,
    "jax": None,
    "flax": None,
    "optax": None,
    "rosbags": "python3-rosbags-pip",
    "trimesh": "python3-trimesh-pip",
    "mcap": None,
    "fast_simplification": None,
    "threadpoolctl": None,  # scikit-learn's own dependency
    "foxglove": None,  # foxglove-sdk
    "ray": None,  # glocal-ros experiment --ray
}
#: How package.xml's comment names a dependency without a key (the pip name).
PIP_NAMES = {"mcap": "mcap", "fast_simplification": "fast-simplification", "threadpoolctl": "threadpoolctl",
             "sbx": "sbx-rl", "jax": "jax", "flax": "flax", "optax": "optax",
             "foxglove": "foxglove-sdk", "ray": "ray"}
OWN = {*ROOMS, "glocal_interfaces"}


def code_files() -> list[Path]:
    files = [path for room in ROOMS for path in sorted((REPO / room).rglob("*.py"))]
    return files + sorted((REPO / "bin").iterdir()) + sorted((REPO / "launch").glob("*.py"))


def imported() -> dict[str, str]:
    """Every top-level module the code imports, with one file that imports it."""
    modules: dict[str, str] = {}
    for path in code_files():
        for root in imported_roots(path):
            modules.setdefault(root, str(path.relative_to(REPO)))
    return modules


def ament_packages() -> set[str]:
    index = Path(sys.prefix) / "share" / "ament_index" / "resource_index" / "packages"
    return {marker.name for marker in index.iterdir()}


@pytest.fixture(scope="module")
def package():
    manifest = parse_package(str(REPO / "package.xml"))
    manifest.validate()  # catkin_pkg's own checks of format 3
    return manifest


def declared(package) -> set[str]:
    return {dependency.name for dependency in package.exec_depends}


def test_every_imported_ros_package_is_declared(package):
    ros = ament_packages() | ROS_PACKAGES_NOT_HERE
    imports = imported()
    used = {name: where for name, where in imports.items() if name in ros and name != "glocal_ros"}
    assert {"rclpy", "rcl_interfaces", "builtin_interfaces", "visualization_msgs", "rosgraph_msgs", "tf2_msgs",
            "launch", "launch_ros"} <= set(used), "the walk missed imports it must see"
    missing = {name: where for name, where in used.items() if name not in declared(package)}
    assert missing == {}, f"imported but not in package.xml (name: a file that imports it): {missing}"
    assert "glocal_interfaces" in {d.name for d in package.build_depends}


def test_every_python_dependency_has_its_rosdep_key_or_is_named_without_one(package):
    standard = set(sys.stdlib_module_names) | {"__future__"}
    ros = ament_packages() | ROS_PACKAGES_NOT_HERE
    third_party = {name: where for name, where in imported().items()
                   if name not in standard and name not in ros and name not in OWN}
    unknown = {name: where for name, where in third_party.items() if name not in PYTHON_KEYS}
    assert unknown == {}, f"new imports: add their rosdep key to package.xml and PYTHON_KEYS: {unknown}"
    keys = {PYTHON_KEYS[name] for name in third_party} - {None}
    assert keys - declared(package) == set()
    comment = (REPO / "package.xml").read_text()
    without_key = [PIP_NAMES[name] for name in third_party if PYTHON_KEYS[name] is None]
    assert without_key and all(name in comment for name in without_key)
    assert "Not packaged by rosdep" not in comment, "the old, wrong comment"


def test_no_declared_dependency_is_left_over(package):
    """A key that nothing imports any more goes (the launch CLI and the tests' keys aside)."""
    used = set(imported()) | {"ros2launch"}
    expected_keys = {key for name, key in PYTHON_KEYS.items() if name in used}
    leftover = {name for name in declared(package) if name not in used and name not in expected_keys}
    assert leftover == set()
    test_imports = {root for path in sorted((REPO / "test").glob("*.py")) for root in imported_roots(path)}
    assert {"pytest", "hypothesis"} <= test_imports
    assert {d.name for d in package.test_depends} == {"python3-pytest", "python3-hypothesis"}


def test_the_ast_walk_reads_the_launch_file():
    roots = imported_roots(REPO / "launch" / "glocal.launch.py")
    assert {"launch", "launch_ros", "ament_index_python", "glocal_app"} <= set(roots)

"""package.xml declares what the code imports, so that rosdep installs it on a full ROS 2 install.

Imports are read from every Python file's syntax tree (lazy ones included,
as ``test_rooms`` reads them) in the rooms, ``bin/`` and ``launch/``. A ROS
package is a name in the ament index (the venv's prefix holds the wheels'
and the built interfaces' markers), or ``launch``/``launch_ros``, which are
not installable here. Every other third-party import must be in
``PYTHON_KEYS``: its rosdep key, declared, or ``None`` when rosdistro has
none, which package.xml's comment must then name.
"""

import re
import sys
from pathlib import Path

import pytest
from catkin_pkg.package import parse_package

from conftest import REPO
from test_rooms import ROOMS, imported_roots

#: ROS packages the code imports that the venv cannot hold (not on PyPI): launch/glocal.launch.py's.
ROS_PACKAGES_NOT_HERE = {"launch", "launch_ros"}
#: Every pinned dependency of requirements-system-ros.txt -> its rosdep key (None: rosdistro's
#: rosdep/python.yaml has none, and package.xml's comment names it).
PIP_KEYS: dict[str, str | None] = {
    "torch": "python3-torch",
    "pybullet": "python3-pybullet-pip",
    "gymnasium": "python3-gymnasium-pip",
    "stable-baselines3": "python3-stable-baselines3-pip",
    "sbx-rl": None,
    "jax": None,
    "jaxlib": None,  # jax's CPU backend
    "flax": None,
    "optax": None,
    "scikit-learn": "python3-sklearn",
    "threadpoolctl": None,  # scikit-learn's own dependency, imported by the learner
    "scipy": "python3-scipy",
    "scikit-image": "python3-skimage",
    "trimesh": "python3-trimesh-pip",
    "fast-simplification": None,
    "rosbags": "python3-rosbags-pip",
    "ruamel.yaml": "python3-ruamel.yaml",
    "pillow": "python3-pil",
    "mcap": None,
    "mcap-ros2-support": None,
    "foxglove-sdk": None,
    "matplotlib": "python3-matplotlib",
    "tensorboard": "python3-tensorboard-pip",
    "tqdm": "python3-tqdm",
    "pyyaml": "python3-yaml",
    "ray": None,
    "pytest": "python3-pytest",
    "pytest-timeout": "python3-pytest-timeout",  # pytest.ini's timeout
    "hypothesis": "python3-hypothesis",
    "websockets": "python3-websockets",
    "numpy": "python3-numpy",  # not pinned directly: everything above pulls it in
    "catkin-pkg": "python3-catkin-pkg-modules",  # a ROS install's own; test_package_xml reads package.xml
}
#: Third-party Python import -> its pip name.
PIP_NAMES: dict[str, str] = {
    "numpy": "numpy", "scipy": "scipy", "sklearn": "scikit-learn", "skimage": "scikit-image",
    "matplotlib": "matplotlib", "PIL": "pillow", "yaml": "pyyaml", "ruamel": "ruamel.yaml", "tqdm": "tqdm",
    "torch": "torch", "pybullet": "pybullet", "pybullet_data": "pybullet", "pybullet_utils": "pybullet",
    "gymnasium": "gymnasium", "stable_baselines3": "stable-baselines3", "sbx": "sbx-rl", "jax": "jax",
    "flax": "flax", "optax": "optax", "rosbags": "rosbags", "trimesh": "trimesh", "mcap": "mcap",
    "fast_simplification": "fast-simplification", "threadpoolctl": "threadpoolctl", "foxglove": "foxglove-sdk",
    "ray": "ray", "pytest": "pytest", "hypothesis": "hypothesis", "websockets": "websockets",
    "catkin_pkg": "catkin-pkg", "tensorboard": "tensorboard",
}
#: Modules the code needs without naming them: ``torch.utils.tensorboard`` writes through tensorboard.
IMPORTED_THROUGH_ANOTHER = {"tensorboard"}
#: Third-party Python import -> rosdep key (None: rosdistro has no key; package.xml's comment says so).
PYTHON_KEYS: dict[str, str | None] = {module: PIP_KEYS[pip] for module, pip in PIP_NAMES.items()}
#: What the tests need beside pytest's plugins, by pip name: what the tests import, and pytest-timeout.
TEST_PLUGINS = {"pytest-timeout"}
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
    used = set(imported()) | IMPORTED_THROUGH_ANOTHER | {"ros2launch"}
    expected_keys = {key for name, key in PYTHON_KEYS.items() if name in used}
    leftover = {name for name in declared(package) if name not in used and name not in expected_keys}
    assert leftover == set()
    test_imports = {root for path in sorted((REPO / "test").glob("*.py")) for root in imported_roots(path)}
    assert {"pytest", "hypothesis", "websockets", "yaml", "catkin_pkg"} <= test_imports
    tests_need = {PIP_NAMES[name] for name in test_imports if name in PIP_NAMES} | TEST_PLUGINS
    test_keys = {PIP_KEYS[pip] for pip in tests_need} - declared(package) - {None}
    assert {d.name for d in package.test_depends} == test_keys


def pinned(requirements: Path) -> dict[str, str]:
    """The pip names a requirements file pins (``name==version``), lower case, extras dropped, with their line."""
    names = {}
    for line in requirements.read_text().splitlines():
        line = line.split("#")[0].strip()
        if line and not line.startswith("-"):
            name, _, version = line.partition("==")
            assert version, f"{requirements.name}: {line} is not pinned"
            names[name.split("[")[0].strip().lower()] = line
    return names


def test_the_venv_installs_both_requirement_files_and_nothing_else():
    lines = [line for line in (REPO / "requirements.txt").read_text().splitlines()
             if line.strip() and not line.startswith("#")]
    assert lines == ["-r requirements-ros-wheels.txt", "-r requirements-system-ros.txt"]
    assert not set(pinned(REPO / "requirements-ros-wheels.txt")) & set(pinned(REPO / "requirements-system-ros.txt"))


def test_the_system_ros_requirements_leave_ros_to_the_system():
    """What a ROS 2 Jazzy install provides (its packages, rclpy, the build tools) is only in the wheels' file:
    installed beside /opt/ros/jazzy in a venv with --system-site-packages, it would shadow the system's."""
    ros_provides = ("ros-", "rclpy", "rosidl", "ament", "catkin-pkg", "colcon", "empy", "lark")
    wheels = pinned(REPO / "requirements-ros-wheels.txt")
    assert all(name.startswith(ros_provides) for name in wheels), wheels
    system = pinned(REPO / "requirements-system-ros.txt")
    assert not [name for name in system if name.startswith(ros_provides)]


def test_every_system_ros_pin_has_its_rosdep_key_or_is_named_without_one(package):
    system = pinned(REPO / "requirements-system-ros.txt")
    unknown = set(system) - set(PIP_KEYS)
    assert unknown == set(), f"new pins: add their rosdep key (or None) to PIP_KEYS and package.xml: {unknown}"
    keys = {PIP_KEYS[name] for name in system} - {None}
    declared_keys = declared(package) | {d.name for d in package.test_depends}
    assert keys - declared_keys == set(), "rosdep keys of pinned dependencies that package.xml does not declare"
    comment = (REPO / "package.xml").read_text().split("No rosdep key")[1].split("-->")[0]
    unnamed = [name for name in system if PIP_KEYS[name] is None and not re.search(rf"\b{re.escape(name)}\b", comment)]
    assert unnamed == [], f"no rosdep key, and package.xml's comment does not name them: {unnamed}"


def test_the_ast_walk_reads_the_launch_file():
    roots = imported_roots(REPO / "launch" / "glocal.launch.py")
    assert {"launch", "launch_ros", "ament_index_python", "glocal_app"} <= set(roots)


def test_the_license_file_is_the_one_package_xml_and_setup_py_name(package):
    assert [license_ for license_ in package.licenses] == ["Apache-2.0"]
    assert 'license="Apache-2.0"' in (REPO / "setup.py").read_text()
    text = (REPO / "LICENSE").read_text()
    assert text.split()[:4] == ["Apache", "License", "Version", "2.0,"]
    assert "END OF TERMS AND CONDITIONS" in text

"""The rooms of the architecture: what each part may import.

Two kinds of check: what importing a module loads (``imported_after``, for
third-party weight such as rclpy and pybullet), and which rooms each file's
source names in an import, read from its syntax tree so that lazy imports
inside functions count as much as the ones at the top.
"""

import ast
import re
import subprocess
import sys
from pathlib import Path

import pytest

from conftest import REPO

LIBRARY = "glocal_ros"
COMMON = "node_common"
NODE_PACKAGES = ("sim_node", "learner_node", "curriculum_node", "recorder_node", "foxglove_bridge_node")
APPLICATION = "glocal_app"
ROOMS = (LIBRARY, COMMON, *NODE_PACKAGES, APPLICATION)

#: Top-level packages each room must not import, directly or lazily.
FORBIDDEN: dict[str, set[str]] = {
    LIBRARY: {"rclpy", COMMON, *NODE_PACKAGES, APPLICATION},
    COMMON: {*NODE_PACKAGES, APPLICATION},
    # Node packages never import each other (nor the application above them).
    **{node: {*NODE_PACKAGES, APPLICATION} - {node} for node in NODE_PACKAGES},
}


def imported_after(statement: str) -> set[str]:
    code = f"import sys; {statement}; print(' '.join(sorted(sys.modules)))"
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=REPO, check=True)
    return set(result.stdout.split())


def imported_roots(path: Path) -> dict[str, int]:
    """Top-level packages that ``path`` imports anywhere, with the line of the first import of each."""
    roots: dict[str, int] = {}
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            names = [alias.name for alias in node.names]
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            names = [node.module]
        else:
            continue  # relative imports stay in their own package
        for name in names:
            roots.setdefault(name.split(".")[0], node.lineno)
    return roots


def room_files(room: str) -> list[Path]:
    return sorted((REPO / room).rglob("*.py"))


@pytest.mark.parametrize("room", list(FORBIDDEN))
def test_rooms_import_only_what_they_may(room):
    files = room_files(room)
    assert files, f"no Python file in {room}/"
    breaches = [f"{path.relative_to(REPO)}:{line}: imports {root}"
                for path in files for root, line in imported_roots(path).items() if root in FORBIDDEN[room]]
    assert breaches == []


#: ``module.path:attribute``, as entry points (Gymnasium's, setuptools', pickle's) name code in a string.
_ENTRY_POINT = re.compile(r"^([A-Za-z_]\w*)(?:\.\w+)*:[A-Za-z_]\w*$")


def entry_point_roots(path: Path) -> dict[str, int]:
    """Top-level packages that ``path`` names in an entry-point string, with the line of the first."""
    roots: dict[str, int] = {}
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Constant) and isinstance(node.value, str):
            match = _ENTRY_POINT.match(node.value)
            if match:
                roots.setdefault(match.group(1), node.lineno)
    return roots


@pytest.mark.parametrize("room", list(FORBIDDEN))
def test_rooms_name_no_code_they_may_not_import_in_a_string(room):
    breaches = [f"{path.relative_to(REPO)}:{line}: names {root} in an entry point"
                for path in room_files(room) for root, line in entry_point_roots(path).items()
                if root in FORBIDDEN[room]]
    assert breaches == []


def test_the_entry_point_check_sees_a_registration_by_string(tmp_path):
    module = tmp_path / "registers.py"
    module.write_text('import gymnasium\ngymnasium.register(id="x/Y-v0", entry_point="sim_node.grasp_env:GraspEnv")\n'
                      'URL = "ws://127.0.0.1:8765"\n')
    assert entry_point_roots(module) == {"sim_node": 2}


def test_the_ast_check_sees_lazy_imports(tmp_path):
    module = tmp_path / "lazy.py"
    module.write_text("def f():\n    from sim_node.batch import BatchedEnvs\n    import rclpy.node\n")
    assert imported_roots(module) == {"sim_node": 2, "rclpy": 3}


@pytest.mark.parametrize("module", ["glocal_ros.clustering", "glocal_ros.recording", "glocal_ros.tasks",
                                    "glocal_ros.objects", "glocal_ros.sim_contract", "glocal_ros.topics",
                                    "glocal_app.cli"])
def test_the_library_has_no_ros_client(module):
    assert "rclpy" not in imported_after(f"import {module}")


def test_the_learner_never_loads_the_simulator():
    modules = imported_after("import learner_node.learner_node, learner_node.prior, learner_node.policies")
    assert "pybullet" not in modules


def test_every_node_has_its_package_main_and_ros2_run_wrapper():
    from glocal_app.nodes import NODES

    assert set(NODES) == set(NODE_PACKAGES)
    assert sorted(path.name for path in (REPO / "bin").iterdir()) == sorted(NODES)
    for node in NODES:
        assert "main" in {n.name for n in ast.parse((REPO / node / f"{node}.py").read_text()).body
                          if isinstance(n, ast.FunctionDef)}
        assert f"from {node}.{node} import main" in (REPO / "bin" / node).read_text()

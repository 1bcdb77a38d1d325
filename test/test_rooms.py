"""The rooms of the architecture: what each part may import."""

import subprocess
import sys

import pytest

from conftest import REPO


def imported_after(statement: str) -> set[str]:
    code = f"import sys; {statement}; print(' '.join(sorted(sys.modules)))"
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=REPO, check=True)
    return set(result.stdout.split())


@pytest.mark.parametrize("module", ["glocal_ros.clustering", "glocal_ros.recording", "glocal_ros.tasks",
                                    "glocal_ros.objects", "glocal_ros.cli"])
def test_the_library_has_no_ros_client(module):
    assert "rclpy" not in imported_after(f"import {module}")


def test_the_learner_never_loads_the_simulator():
    modules = imported_after("import learner_node.learner_node, learner_node.prior, learner_node.policies")
    assert "pybullet" not in modules

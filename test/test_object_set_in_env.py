"""The committed object set in the env: every object loads and the scripted grasp lifts it."""

import subprocess
import sys

import gymnasium
import pytest

import glocal_ros
from conftest import REPO
from glocal_ros.objects import ObjectSetMetadata
from glocal_ros.paths import objects_dir
from glocal_ros.spaces import ACTION_DIM, OBS_DIM
from glocal_ros.tasks import ALL_TASKS
from sim_node.scripted_grasp import scripted_success_rate


def test_gymnasium_make_after_importing_the_package():
    env = gymnasium.make(glocal_ros.GRASP_ENV_ID, task="C3")
    try:
        observation, info = env.reset(seed=0)
        assert observation.shape == (OBS_DIM,) and env.action_space.shape == (ACTION_DIM,)
        assert info["task"] == "C3"
    finally:
        env.close()


@pytest.fixture(scope="module")
def env():
    env = gymnasium.make(glocal_ros.GRASP_ENV_ID, task="A0")
    yield env
    env.close()


@pytest.mark.parametrize("task", ALL_TASKS)
def test_scripted_grasp_lifts_every_object(env, task):
    # Seeded, so this is a fixed check; 3 tries allow for the objects the
    # controller grasps about 70% of the time (see objects.json).
    assert scripted_success_rate(env, task, episodes=3, seed=0) > 0


def test_metadata_records_both_grasp_checks():
    metadata = ObjectSetMetadata.load(objects_dir())
    scripted = {task: obj.scripted_grasp_success for task, obj in metadata.objects.items()}
    perturbed = {task: obj.perturbed_grasp_success for task, obj in metadata.objects.items()}
    assert set(scripted) == set(perturbed) == set(ALL_TASKS)
    assert all(rate is not None and rate > 0 for rate in scripted.values()), scripted
    assert all(rate is not None and 0 <= rate <= 1 for rate in perturbed.values()), perturbed


def test_assets_show_lists_every_object():
    result = subprocess.run([sys.executable, "-m", "glocal_app.cli", "assets", "show"], capture_output=True,
                            text=True, timeout=60, cwd=REPO)
    assert result.returncode == 0, result.stderr
    rows = [line.split()[0] for line in result.stdout.splitlines()[1:]]
    assert rows == list(ALL_TASKS)

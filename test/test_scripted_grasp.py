"""The scripted grasp controller against real PyBullet, on small primitive objects."""

from __future__ import annotations

import gymnasium as gym
import pytest

from primitive_objects import BOX_TASK, CYLINDER_TASK, write_test_objects
from sim_node.grasp_env import GraspEnv
from sim_node.scripted_grasp import Phase, ScriptedGraspPolicy, scripted_success_rate


@pytest.fixture(scope="module")
def env(tmp_path_factory: pytest.TempPathFactory):
    """One env holding the probe's 4 x 6 x 5 cm box (A0) and a 2.8 cm-radius cylinder (B3)."""
    grasp_env = GraspEnv(objects_dir=write_test_objects(tmp_path_factory.mktemp("objects")))
    yield grasp_env
    grasp_env.close()


@pytest.mark.parametrize("task", [BOX_TASK, CYLINDER_TASK])
def test_scripted_policy_lifts_the_object(env: GraspEnv, task: str) -> None:
    assert scripted_success_rate(env, task, episodes=10, seed=0) >= 0.8


def test_successful_episode_terminates_with_is_success(env: GraspEnv) -> None:
    wrapped = gym.wrappers.RecordEpisodeStatistics(env)
    policy = ScriptedGraspPolicy()
    wrapped.reset(seed=3, options={"task": BOX_TASK})
    flags = []
    while not flags or not (flags[-1][0] or flags[-1][1]):
        _, reward, terminated, truncated, info = wrapped.step(policy.act(wrapped))
        assert reward == -1.0
        flags.append((terminated, truncated, info["is_success"]))
    assert flags[-1] == (True, False, True)
    assert not any(success for _, _, success in flags[:-1])
    assert env.grasp_state().object_lift > env.config.success_height
    assert env.grasp_state().left_contact and env.grasp_state().right_contact
    assert len(flags) < env.config.max_steps


def test_policy_starts_over_in_each_episode(env: GraspEnv) -> None:
    policy = ScriptedGraspPolicy()
    env.reset(seed=0, options={"task": BOX_TASK})
    while True:
        _, _, terminated, truncated, _ = env.step(policy.act(env))
        if terminated or truncated:
            break
    assert policy.phase is Phase.LIFT
    env.reset()
    action = policy.act(env)
    assert policy.phase is Phase.APPROACH
    assert action[0] == -1.0 and env.action_space.contains(action)


def test_success_rate_needs_episodes(env: GraspEnv) -> None:
    with pytest.raises(ValueError, match="episodes"):
        scripted_success_rate(env, BOX_TASK, episodes=0)

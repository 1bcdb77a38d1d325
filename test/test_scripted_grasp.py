"""The scripted grasp controller against real PyBullet, on small primitive objects."""

from __future__ import annotations

import math

import gymnasium as gym
import numpy as np
import pytest

from primitive_objects import BOX_TASK, CYLINDER_TASK, write_test_objects
from sim_node.grasp_env import GraspEnv
from sim_node.scripted_grasp import (
    GraspError,
    GraspErrors,
    Phase,
    ScriptedGraspPolicy,
    grasp_trial,
    perturbed_success_rate,
    scripted_success_rate,
)


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


def one_episode(env: GraspEnv, policy: ScriptedGraspPolicy, seed: int) -> bool:
    env.reset(seed=seed, options={"task": BOX_TASK})
    while True:
        _, _, terminated, truncated, info = env.step(policy.act(env))
        if terminated or truncated:
            return bool(info["is_success"])


def test_a_grasp_without_error_or_retry_lifts_the_box_and_one_beside_it_does_not(env: GraspEnv) -> None:
    assert one_episode(env, ScriptedGraspPolicy(retry=False), seed=1)
    # 4 cm along the closing direction: one finger lands on the box's top, the other beside it.
    missed = ScriptedGraspPolicy(error=GraspError(across=0.04), retry=False)
    assert not one_episode(env, missed, seed=1)
    assert missed.phase is Phase.LIFT, "without retries a missed grasp lifts nothing and does not approach again"


def test_grasp_errors_stay_in_their_ranges_and_follow_the_seed() -> None:
    errors = GraspErrors()
    samples = [errors.sample(np.random.default_rng([4, i])) for i in range(200)]
    assert all(math.hypot(e.across, e.along) <= errors.max_offset for e in samples)
    assert all(abs(e.yaw) <= errors.max_yaw and errors.lowest <= e.height <= errors.highest for e in samples)
    assert max(math.hypot(e.across, e.along) for e in samples) > 0.8 * errors.max_offset
    assert errors.sample(np.random.default_rng(3)) == errors.sample(np.random.default_rng(3))


def test_perturbed_success_is_a_function_of_its_seed_and_falls_with_the_error(env: GraspEnv) -> None:
    small, large = GraspErrors(max_offset=0.002, max_yaw=0.02), GraspErrors(max_offset=0.05)
    first = perturbed_success_rate(env, BOX_TASK, 6, seed=2, errors=small)
    assert first == perturbed_success_rate(env, BOX_TASK, 6, seed=2, errors=small)
    assert first >= 5 / 6 and perturbed_success_rate(env, BOX_TASK, 6, seed=2, errors=large) < first
    with pytest.raises(ValueError, match="episodes"):
        perturbed_success_rate(env, BOX_TASK, 0, seed=2)


def test_grasp_trial_measures_both_rates_in_an_env_of_its_own(env: GraspEnv) -> None:
    perturbed, scripted = grasp_trial(env.objects_dir, CYLINDER_TASK, seed=0, perturbed_episodes=4,
                                      scripted_episodes=3)
    assert scripted >= 2 / 3 and perturbed in (0.0, 0.25, 0.5, 0.75, 1.0)

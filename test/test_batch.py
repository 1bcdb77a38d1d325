"""BatchedEnvs over real GraspEnvs and the committed object set."""

import numpy as np
import pytest

from glocal_ros.sim_contract import PHASE_EVAL, PHASE_TRAIN, BatchStepper
from glocal_ros.tasks import UnknownTaskError, task_index
from sim_node.batch import BatchedEnvs
from sim_node.grasp_env import GraspEnv, GraspEnvConfig

T = 4


@pytest.fixture(scope="module")
def batch():
    envs = BatchedEnvs(lambda i: GraspEnv("A0", config=GraspEnvConfig(max_steps=T)), num_envs=3)
    yield envs
    envs.close()


def zero_actions(batch):
    return np.zeros((batch.num_envs, batch.action_dim), dtype=np.float32)


def test_the_batch_is_a_batch_stepper(batch):
    assert isinstance(batch, BatchStepper)
    finish = batch.start_step(zero_actions(batch))
    assert finish().observations.shape == (3, 63)


def test_reset_and_step_shapes(batch):
    observations, _ = batch.reset(tasks=["B2"], seeds=[7])
    assert observations.shape == (3, 63) and observations.dtype == np.float32
    assert batch.tasks == ["B2"] * 3
    result = batch.step(zero_actions(batch))
    assert result.observations.shape == (3, 63)
    assert result.rewards.tolist() == [-1.0] * 3
    assert not result.terminated.any() and not result.truncated.any()
    assert result.finished == []


def test_episodes_end_reset_and_are_logged(batch):
    batch.reset(tasks=["A0"], phase=PHASE_EVAL, policy_name="zero")
    for _ in range(T - 1):
        assert batch.step(zero_actions(batch), phase=PHASE_EVAL, policy_name="zero").finished == []
    result = batch.step(zero_actions(batch), next_tasks=["C1", "", "A0"], phase=PHASE_EVAL,
                        policy_name="zero", global_step=42)
    assert result.truncated.all() and not result.terminated.any()
    assert result.tasks == ["C1", "A0", "A0"]
    assert [log.env_index for log in result.finished] == [0, 1, 2]
    log = result.finished[0]
    assert (log.task, log.phase, log.policy_name, log.global_step) == ("A0", PHASE_EVAL, "zero", 42)
    assert log.length == T and len(log.observations) == T + 1 and len(log.joint_positions) == T + 1
    assert log.truncated and not log.success and not log.interrupted
    # The last observation comes back separately; the returned one begins the next episode.
    np.testing.assert_array_equal(result.terminal_observations[0], log.observations[-1])
    np.testing.assert_array_equal(result.observations[0], batch._logs[0].observations[0])
    assert result.observations[0][task_index("C1")] == 1.0


def test_reset_mid_episode_returns_interrupted_episode(batch):
    batch.reset(tasks=["A0"])
    batch.step(zero_actions(batch))
    _, interrupted = batch.reset(env_indices=[1], tasks=["A1"])
    assert [(log.env_index, log.length, log.interrupted) for log in interrupted] == [(1, 1, True)]
    assert batch.tasks == ["A0", "A1", "A0"]


def test_seeded_resets_repeat(batch):
    first, _ = batch.reset(tasks=["D4"], seeds=[3])
    second, _ = batch.reset(tasks=["D4"], seeds=[3])
    np.testing.assert_array_equal(first, second)
    assert not np.array_equal(first[0], first[1])  # env k gets seed + k


@pytest.mark.parametrize("actions, message", [
    (np.zeros(14, dtype=np.float32), "expected 15 action values"),
    (np.full(15, np.nan, dtype=np.float32), "NaN or inf"),
    (np.full(15, np.inf, dtype=np.float32), "NaN or inf"),
    (np.full(15, 1.5, dtype=np.float32), r"\[-1, 1\]"),
])
def test_bad_actions_are_refused(batch, actions, message):
    with pytest.raises(ValueError, match=message):
        batch.step(actions)


def test_bad_reset_requests_are_refused(batch):
    with pytest.raises(UnknownTaskError):
        batch.reset(tasks=["Z9"])
    with pytest.raises(ValueError, match="out of range"):
        batch.reset(env_indices=[3])
    with pytest.raises(ValueError, match="repeat"):
        batch.reset(env_indices=[0, 0])
    with pytest.raises(ValueError, match="one per reset env"):
        batch.reset(tasks=["A0", "A1"])
    with pytest.raises(ValueError, match="phase"):
        batch.reset(phase=7)
    with pytest.raises(ValueError, match="next_tasks"):
        batch.step(zero_actions(batch), next_tasks=["A0"])
    with pytest.raises(UnknownTaskError):
        batch.step(zero_actions(batch), next_tasks=["A0", "Q", ""])
    # Refused requests change nothing: the batch still steps.
    assert batch.step(zero_actions(batch), phase=PHASE_TRAIN).observations.shape == (3, 63)

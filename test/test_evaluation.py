"""The paper's score over a batch of real envs, in-process."""

import numpy as np
import pytest

from learner_node.evaluation import evaluate
from sim_node.batch import BatchedEnvs
from sim_node.grasp_env import GraspEnv
from sim_node.scripted_grasp import ScriptedGraspPolicy


class RecordingBatch(BatchedEnvs):
    """BatchedEnvs that keeps every finished episode and the envs of every step, to check the bookkeeping, and
    each env's latest observation, so that a privileged policy knows which env a row is from."""

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        self.finished, self.stepped = [], []
        self.latest = np.zeros((self.num_envs, self.obs_dim), dtype=np.float32)

    def reset(self, env_indices=(), *args, **kwargs):
        observations, interrupted = super().reset(env_indices, *args, **kwargs)
        self.latest[list(env_indices) or slice(None)] = observations
        return observations, interrupted

    def step(self, actions, next_tasks=(), phase=0, policy_name="", global_step=0, env_indices=()):
        result = super().step(actions, next_tasks, phase, policy_name, global_step, env_indices)
        indices = list(env_indices) or list(range(self.num_envs))
        self.finished += result.finished
        self.stepped.append(indices)
        self.latest[indices] = result.observations
        return result


@pytest.fixture(scope="module")
def batch():
    envs = RecordingBatch(lambda i: GraspEnv("A0"), num_envs=3)
    yield envs
    envs.close()


def scripted(batch):
    """The privileged scripted controller, one per env, as a batch policy of the envs whose rows it gets."""
    controllers = [ScriptedGraspPolicy() for _ in batch.envs]

    def act(observations):
        envs = [int(np.flatnonzero((batch.latest == row).all(axis=1))[0]) for row in observations]
        return np.stack([controllers[env].act(batch.envs[env]) for env in envs])

    return act


def test_scores_count_successes_of_exactly_the_requested_episodes(batch):
    batch.finished.clear()
    scores = evaluate(batch, scripted(batch), ["A0", "A1"], episodes=4, policy_name="scripted", seed=1)
    assert [(s.task, s.episodes) for s in scores] == [("A0", 4), ("A1", 4)]
    for score in scores:
        ran = [log for log in batch.finished if log.task == score.task]
        # Each task ran exactly its 4 episodes (an env without a job waits) and the score counts them.
        assert len(ran) == 4
        assert score.successes == sum(log.success for log in ran)
    assert scores[0].successes >= 3  # the scripted grasp lifts the easiest object


def test_seeded_evaluation_repeats(batch):
    first = evaluate(batch, scripted(batch), ["B1"], episodes=3, seed=5)
    second = evaluate(batch, scripted(batch), ["B1"], episodes=3, seed=5)
    assert first == second


def test_more_envs_than_episodes_steps_only_the_envs_with_a_job(batch):
    batch.finished.clear()
    batch.stepped.clear()
    scores = evaluate(batch, scripted(batch), ["A0", "C2"], episodes=1, seed=0)
    assert [s.episodes for s in scores] == [1, 1]
    assert sorted(log.task for log in batch.finished) == ["A0", "C2"]
    assert [log.env_index for log in batch.finished if log.task == "C2"] == [2]  # spread: envs 0 and 2
    assert {env for step in batch.stepped for env in step} == {0, 2}, "env 1 has no job and never steps"
    assert [s.successes for s in scores] == [log.success for log in sorted(batch.finished, key=lambda l: l.task)]


def test_bad_arguments(batch):
    with pytest.raises(ValueError, match="at least 1"):
        evaluate(batch, scripted(batch), ["A0"], episodes=0)
    with pytest.raises(ValueError, match="no task"):
        evaluate(batch, scripted(batch), [], episodes=3)

"""The paper's score over a batch of real envs, in-process."""

import numpy as np
import pytest

from learner_node.evaluation import evaluate
from sim_node.batch import BatchedEnvs
from sim_node.grasp_env import GraspEnv
from sim_node.scripted_grasp import ScriptedGraspPolicy


class RecordingBatch(BatchedEnvs):
    """BatchedEnvs that keeps every finished episode, to check the bookkeeping."""

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        self.finished = []

    def step(self, *args, **kwargs):
        result = super().step(*args, **kwargs)
        self.finished += result.finished
        return result


@pytest.fixture(scope="module")
def batch():
    envs = RecordingBatch(lambda i: GraspEnv("A0"), num_envs=3)
    yield envs
    envs.close()


def scripted(batch):
    """The privileged scripted controller, one per env, as a batch policy."""
    controllers = [ScriptedGraspPolicy() for _ in batch.envs]
    return lambda observations: np.stack([c.act(env) for c, env in zip(controllers, batch.envs)])


def test_scores_count_successes_of_exactly_the_requested_episodes(batch):
    batch.finished.clear()
    scores = evaluate(batch, scripted(batch), ["A0", "A1"], episodes=4, policy_name="scripted", seed=1)
    assert [(s.task, s.episodes) for s in scores] == [("A0", 4), ("A1", 4)]
    for score in scores:
        ran = [log for log in batch.finished if log.task == score.task]
        # Each task ran at least its 4 episodes (an env can start one uncounted extra) ...
        assert len(ran) >= 4
        # ... and the score counts successes among them only.
        assert score.successes <= sum(log.success for log in ran)
    assert scores[0].successes >= 3  # the scripted grasp lifts the easiest object


def test_seeded_evaluation_repeats(batch):
    first = evaluate(batch, scripted(batch), ["B1"], episodes=3, seed=5)
    second = evaluate(batch, scripted(batch), ["B1"], episodes=3, seed=5)
    assert first == second


def test_more_envs_than_episodes(batch):
    scores = evaluate(batch, scripted(batch), ["A0", "C2"], episodes=1, seed=0)
    assert [s.episodes for s in scores] == [1, 1]
    assert all(0 <= s.successes <= 1 for s in scores)


def test_bad_arguments(batch):
    with pytest.raises(ValueError, match="at least 1"):
        evaluate(batch, scripted(batch), ["A0"], episodes=0)
    with pytest.raises(ValueError, match="no task"):
        evaluate(batch, scripted(batch), [], episodes=3)

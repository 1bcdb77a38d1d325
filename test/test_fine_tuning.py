"""What a goal does to the stored model before its first step (``learner_node.fine_tuning``), on the shipped
prior's real weights and Adam state, and that acting with a stored policy computes on the learner's one thread."""

import os

import numpy as np
import pytest
import torch

from glocal_ros.paths import assets_dir
from glocal_ros.tasks import task_index
from learner_node.fine_tuning import input_layers, start_fine_tuning
from learner_node.policies import PolicyRegistry
from learner_node.policy_store import PolicyStore
from learner_node.sac_settings import COMPUTE_THREADS, XLA_ONE_THREAD_FLAGS, FineTuning, fine_tuning_recipe
from glocal_ros.curriculum.learner import TrainGoal
from learner_node.training import Trainer
from sim_node.batch import BatchedEnvs
from sim_node.grasp_env import GraspEnv

A0, C4, G6 = task_index("A0"), task_index("C4"), task_index("G6")


@pytest.fixture
def prior():
    return PolicyStore(assets_dir() / "priors").load("prior")


def test_a_new_task_bit_starts_as_the_mean_of_the_trained_ones_and_nothing_else_moves(prior):
    before = input_layers(prior)
    assert len(before) == 3, "the actor and two critics"
    for layer in before:
        assert layer.second_moments[A0].any() and not layer.second_moments[C4].any(), "the prior trained on A0 only"

    start_fine_tuning(prior, FineTuning(new_task_inputs="trained-mean"), ["C4", "C4"])

    for layer, old in zip(input_layers(prior), before):
        np.testing.assert_array_equal(layer.weights[C4], old.weights[A0])  # the one trained bit's weights
        changed = (layer.weights != old.weights).any(axis=1).nonzero()[0].tolist()
        assert changed == [C4], "only the goal's new bit"
        np.testing.assert_array_equal(layer.second_moments[C4], layer.second_moments[A0])
        assert not layer.first_moments[C4].any()
        np.testing.assert_array_equal(np.delete(layer.first_moments, C4, axis=0),
                                      np.delete(old.first_moments, C4, axis=0))

    # A bit trained since keeps its own weights; a further new bit gets the mean of both trained ones.
    start_fine_tuning(prior, FineTuning(new_task_inputs="trained-mean"), ["C4", "G6"])
    actor = input_layers(prior)[0]
    np.testing.assert_allclose(actor.weights[G6], (before[0].weights[A0] + actor.weights[C4]) / 2, rtol=1e-6)


def test_initial_task_inputs_and_stored_moments_leave_the_model_as_it_was_loaded(prior):
    before = input_layers(prior)
    start_fine_tuning(prior, FineTuning(), ["C4"])
    for layer, old in zip(input_layers(prior), before):
        for array, old_array in zip((layer.weights, layer.first_moments, layer.second_moments),
                                    (old.weights, old.first_moments, old.second_moments)):
            np.testing.assert_array_equal(array, old_array)


def test_fresh_moments_and_unseen_moments_as_the_bias(prior):
    bias_second = np.array(prior.policy.actor_state.opt_state.inner_state[0].nu["params"]["Dense_0"]["bias"])
    start_fine_tuning(prior, FineTuning(optimizers="unseen-as-bias"), ["C4"])
    actor = input_layers(prior)[0]
    np.testing.assert_array_equal(actor.second_moments[C4], bias_second)
    assert actor.second_moments[A0].any() and not np.array_equal(actor.second_moments[A0], bias_second)
    start_fine_tuning(prior, FineTuning(optimizers="fresh"), ["C4"])
    for layer in input_layers(prior):
        assert not layer.first_moments.any() and not layer.second_moments.any()
    for state in (prior.policy.actor_state, prior.policy.qf_state):
        assert int(state.opt_state.inner_state[0].count) == 0


def test_unknown_starts_are_refused_with_the_choices():
    with pytest.raises(ValueError, match="new_task_inputs must be 'initial' or 'trained-mean'"):
        FineTuning(new_task_inputs="copy")
    with pytest.raises(ValueError, match="optimizers must be"):
        FineTuning(optimizers="sgd")


def test_a_goal_with_task_inputs_trains_the_new_bit_from_the_known_one(tmp_path):
    """Through the Trainer: the stored output's B1 weights are A0's, moved by the goal's few updates."""
    envs = BatchedEnvs(lambda i: GraspEnv("B1"), 2, "B1")
    policies = PolicyRegistry(PolicyStore(tmp_path / "store"), [PolicyStore(assets_dir() / "priors")])
    prior = policies.model("prior")
    b1 = task_index("B1")
    try:
        outcome = Trainer(envs, policies, tmp_path / "checkpoints",
                          fine_tuning=fine_tuning_recipe("parent-experience-task-inputs")).train(TrainGoal(
                              "B1", "prior", "b1", step_budget=10, threshold=0, eval_episodes=1))
    finally:
        envs.close()
    assert outcome.completed
    layer, prior_layer = input_layers(policies.model("b1"))[0], input_layers(prior)[0]
    distance_to_a0 = np.abs(layer.weights[b1] - prior_layer.weights[A0]).max()
    assert 0 < distance_to_a0 < 0.05  # ten updates of at most a few learning rates each
    assert np.abs(layer.weights[b1] - prior_layer.weights[b1]).max() > 0.05
    assert layer.second_moments[b1].any()


def test_acting_with_a_stored_policy_computes_on_the_learners_threads(monkeypatch):
    """XLA reads its flags once, when JAX makes its CPU backend: set before any model is loaded."""
    monkeypatch.setenv("XLA_FLAGS", "--xla_cpu_enable_fast_math=false")
    torch.set_num_threads(2)
    PolicyRegistry(PolicyStore(assets_dir() / "priors")).load("prior")
    # The user's flags are kept.
    assert os.environ["XLA_FLAGS"] == f"--xla_cpu_enable_fast_math=false {XLA_ONE_THREAD_FLAGS}"
    assert torch.get_num_threads() == COMPUTE_THREADS


def test_a_policy_loaded_again_runs_the_code_jax_compiled_for_the_first(tmp_path):
    """Each loaded model's train states get the apply functions and optimisers of the first model of its
    settings: a goal from a stored policy no longer compiles SBX's functions again (about 20 s a goal)."""
    from sbx.common.policies import BaseJaxPolicy

    store = PolicyStore(tmp_path / "store")
    store.add_copy(PolicyStore(assets_dir() / "priors"), "prior", "copy")
    first, second = PolicyStore(assets_dir() / "priors").load("prior"), store.load("copy")
    for name in ("actor_state", "qf_state"):
        a, b = getattr(first.policy, name), getattr(second.policy, name)
        assert a.apply_fn is b.apply_fn and a.tx is b.tx, name
    assert first.ent_coef_state.tx is second.ent_coef_state.tx
    observations = np.zeros((2, 63), dtype=np.float32)
    first.predict(observations, deterministic=True)
    compiled = BaseJaxPolicy.select_action._cache_size()
    second.predict(observations, deterministic=True)
    assert BaseJaxPolicy.select_action._cache_size() == compiled

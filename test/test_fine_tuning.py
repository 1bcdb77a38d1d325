"""What a goal does to the stored model before its first step (``learner_node.fine_tuning``), on the shipped
prior's real weights and Adam state, and that acting with a stored policy runs torch on one thread."""

import pytest
import torch

from glocal_ros.paths import assets_dir
from glocal_ros.tasks import task_index
from learner_node.fine_tuning import first_layers, start_fine_tuning
from learner_node.policies import PolicyRegistry
from learner_node.policy_store import PolicyStore
from learner_node.sac_settings import TORCH_THREADS, FineTuning, fine_tuning_recipe
from learner_node.training import Trainer, TrainSpec
from sim_node.batch import BatchedEnvs
from sim_node.grasp_env import GraspEnv

A0, C4, G6 = task_index("A0"), task_index("C4"), task_index("G6")


@pytest.fixture
def prior():
    return PolicyStore(assets_dir() / "priors").load("prior")


def weights(model) -> list[torch.Tensor]:
    return [layer.weight.detach().clone() for layer, _ in first_layers(model)]


def test_a_new_task_bit_starts_as_the_mean_of_the_trained_ones_and_nothing_else_moves(prior):
    before = weights(prior)
    (actor_layer, actor_optimizer), *_ = first_layers(prior)
    second_before = actor_optimizer.state[actor_layer.weight]["exp_avg_sq"].clone()
    assert second_before[:, A0].any() and not second_before[:, C4].any(), "the prior trained on A0 only"

    start_fine_tuning(prior, FineTuning(new_task_inputs="trained-mean"), ["C4", "C4"])

    for (layer, optimizer), old in zip(first_layers(prior), before):
        assert torch.equal(layer.weight[:, C4], old[:, A0])  # the one trained bit's weights
        changed = (layer.weight != old).any(dim=0).nonzero().flatten().tolist()
        assert changed == [C4], "only the goal's new bit"
        state = optimizer.state[layer.weight]
        assert torch.equal(state["exp_avg_sq"][:, C4], state["exp_avg_sq"][:, A0])
        assert not state["exp_avg"][:, C4].any()

    # A bit trained since keeps its own weights; a further new bit gets the mean of both trained ones.
    start_fine_tuning(prior, FineTuning(new_task_inputs="trained-mean"), ["C4", "G6"])
    layer = actor_layer
    assert torch.allclose(layer.weight[:, G6], (before[0][:, A0] + layer.weight[:, C4]) / 2)


def test_initial_task_inputs_and_stored_moments_leave_the_model_as_it_was_loaded(prior):
    before = weights(prior)
    start_fine_tuning(prior, FineTuning(), ["C4"])
    assert all(torch.equal(layer.weight, old) for (layer, _), old in zip(first_layers(prior), before))
    assert all(prior.actor.optimizer.state[layer.weight] for layer, _ in first_layers(prior)[:1])


def test_fresh_moments_and_unseen_moments_as_the_bias(prior):
    layer, optimizer = first_layers(prior)[0]
    bias_second = optimizer.state[layer.bias]["exp_avg_sq"].clone()
    start_fine_tuning(prior, FineTuning(optimizers="unseen-as-bias"), ["C4"])
    assert torch.equal(optimizer.state[layer.weight]["exp_avg_sq"][:, C4], bias_second)
    start_fine_tuning(prior, FineTuning(optimizers="fresh"), ["C4"])
    assert len(prior.actor.optimizer.state) == 0 and len(prior.critic.optimizer.state) == 0


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
                          fine_tuning=fine_tuning_recipe("parent-experience-task-inputs")).train(TrainSpec(
                              "B1", "prior", "b1", step_budget=10, threshold=0, eval_episodes=1))
    finally:
        envs.close()
    assert outcome.completed
    (layer, optimizer), (prior_layer, _) = first_layers(policies.model("b1"))[0], first_layers(prior)[0]
    distance_to_a0 = (layer.weight[:, b1] - prior_layer.weight[:, A0]).abs().max().item()
    assert 0 < distance_to_a0 < 0.05  # ten updates of at most a few learning rates each
    assert (layer.weight[:, b1] - prior_layer.weight[:, b1]).abs().max().item() > 0.05
    assert optimizer.state[layer.weight]["exp_avg_sq"][:, b1].any()


def test_acting_with_a_stored_policy_runs_torch_on_the_learners_threads():
    torch.set_num_threads(2)
    PolicyRegistry(PolicyStore(assets_dir() / "priors")).load("prior")
    assert torch.get_num_threads() == TORCH_THREADS

"""The learner's gradient steps run while the sim steps: SB3's updates, a step later, none lost; and the
fine-tuning recipe decides how a goal starts."""

import pytest

from glocal_ros.paths import assets_dir
from learner_node.policies import PolicyRegistry
from learner_node.policy_store import PolicyStore
from learner_node.sac_settings import SAC_KWARGS, FineTuning, fine_tuning_recipe
from learner_node.training import Trainer, TrainSpec
from sim_node.batch import BatchedEnvs
from sim_node.grasp_env import GraspEnv


class SplitSteps:
    """In-process envs with the sim client's ``start_step``; notes when a step is out."""

    def __init__(self, envs: BatchedEnvs):
        self.envs = envs
        self.step_out = False

    def reset(self, *request):
        return self.envs.reset(*request)

    def step(self, *request):
        return self.envs.step(*request)

    def start_step(self, *request):
        self.step_out = True
        batch = self.envs.step(*request)

        def finish():
            self.step_out = False
            return batch

        return finish


def test_each_steps_updates_run_during_the_next_step_and_the_last_at_the_end(tmp_path, monkeypatch):
    from stable_baselines3 import SAC

    num_envs, batch_size = 2, SAC_KWARGS["batch_size"]
    envs = SplitSteps(BatchedEnvs(lambda i: GraspEnv("A0"), num_envs, "A0"))
    policies = PolicyRegistry(PolicyStore(tmp_path / "store"), [PolicyStore(assets_dir() / "priors")])
    train_calls: list[tuple[bool, int]] = []  # (a step was out, gradient steps)
    real_train = SAC.train

    def noted_train(model, gradient_steps, batch_size=64):
        train_calls.append((envs.step_out, gradient_steps))
        return real_train(model, gradient_steps, batch_size)

    monkeypatch.setattr(SAC, "train", noted_train)
    vector_steps_with_updates = 20
    step_budget = batch_size + num_envs * vector_steps_with_updates
    try:
        outcome = Trainer(envs, policies, tmp_path / "checkpoints").train(TrainSpec(
            "A0", "prior", "a0", step_budget=step_budget, threshold=0, eval_episodes=1))
    finally:
        envs.envs.close()

    assert outcome.completed and outcome.steps_used == step_budget
    # SB3: updates once more than batch_size steps are in, one per env step (gradient_steps=-1).
    assert sum(steps for _, steps in train_calls) == num_envs * vector_steps_with_updates
    assert train_calls == [(True, num_envs)] * (vector_steps_with_updates - 1) + [(False, num_envs)]
    stored = policies.model("a0")
    assert stored.gradient_steps == SAC_KWARGS["gradient_steps"]  # the overlap is not saved with the model
    assert stored._n_updates - policies.model("prior")._n_updates == num_envs * vector_steps_with_updates


@pytest.mark.parametrize("recipe", ["random-first", "policy-first", "policy-first-lr1e-4"])
def test_a_recipe_chooses_the_first_actions_and_the_rate_and_updates_wait_for_a_batch(tmp_path, monkeypatch, recipe):
    """SB3's warm-up draws ``batch_size`` random actions; "policy" acts with the loaded policy at once. Either way
    the first gradient step comes once the buffer holds a batch, so both update equally often."""
    from gymnasium.spaces import Box
    from stable_baselines3 import SAC

    tuning = fine_tuning_recipe(recipe)
    num_envs = 2
    envs = BatchedEnvs(lambda i: GraspEnv("A0"), num_envs, "A0")
    policies = PolicyRegistry(PolicyStore(tmp_path / "store"), [PolicyStore(assets_dir() / "priors")])
    random_actions, updates = [0], [0]
    real_sample, real_train = Box.sample, SAC.train

    def counted_sample(space, *args, **kwargs):
        random_actions[0] += 1
        return real_sample(space, *args, **kwargs)

    def counted_train(model, gradient_steps, batch_size=64):
        assert model.replay_buffer.pos * num_envs >= batch_size, "an update before a batch was in"
        updates[0] += gradient_steps
        return real_train(model, gradient_steps, batch_size)

    monkeypatch.setattr(Box, "sample", counted_sample)
    monkeypatch.setattr(SAC, "train", counted_train)
    step_budget = tuning.batch_size + num_envs * 20
    try:
        outcome = Trainer(envs, policies, tmp_path / "checkpoints", fine_tuning=tuning).train(TrainSpec(
            "A0", "prior", "a0", step_budget=step_budget, threshold=0, eval_episodes=1))
    finally:
        envs.close()

    assert outcome.completed and outcome.steps_used == step_budget
    assert random_actions[0] == (tuning.batch_size if tuning.first_actions == "random" else 0)
    assert updates[0] == num_envs * 20
    stored, prior = policies.model("a0"), policies.model("prior")
    rate = tuning.learning_rate or prior.learning_rate
    assert stored.learning_rate == rate
    assert stored.actor.optimizer.param_groups[0]["lr"] == pytest.approx(rate)


def test_an_unknown_recipe_or_setting_is_refused_with_the_choices():
    with pytest.raises(ValueError, match="random-first"):
        fine_tuning_recipe("rlpd")
    with pytest.raises(ValueError, match="first_actions"):
        FineTuning(first_actions="demonstrations")
    with pytest.raises(ValueError, match="batch_size"):
        FineTuning(batch_size=0)

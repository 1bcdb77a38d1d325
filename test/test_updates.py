"""The learner's gradient steps run while the sim steps: SB3's updates, a step later, none lost; and the
fine-tuning recipe decides how a goal starts."""

import numpy as np
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
    from sbx import SAC

    num_envs = 2
    envs = SplitSteps(BatchedEnvs(lambda i: GraspEnv("A0"), num_envs, "A0"))
    policies = PolicyRegistry(PolicyStore(tmp_path / "store"), [PolicyStore(assets_dir() / "priors")])
    batch_size = policies.model("prior").batch_size
    train_calls: list[tuple[bool, int]] = []  # (a step was out, gradient steps)
    real_train = SAC.train

    def noted_train(model, gradient_steps, batch_size=64):
        train_calls.append((envs.step_out, gradient_steps))
        return real_train(model, gradient_steps, batch_size)

    monkeypatch.setattr(SAC, "train", noted_train)
    vector_steps_with_updates = 20
    step_budget = batch_size + num_envs * vector_steps_with_updates
    try:
        # SB3's own start (random-first): updates from batch_size steps on, as the plain loop does.
        outcome = Trainer(envs, policies, tmp_path / "checkpoints", fine_tuning=FineTuning()).train(TrainSpec(
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


@pytest.mark.parametrize("recipe", ["random-first", "policy-first", "policy-first-lr1e-4",
                                    FineTuning(first_actions="random", batch_size=32)])
def test_a_recipe_chooses_the_first_actions_and_the_rate_and_updates_wait_for_a_batch(tmp_path, monkeypatch, recipe):
    """SB3's warm-up draws a batch of random actions; "policy" acts with the loaded policy at once. Either way
    the first gradient step comes once the buffer holds a batch, so both update equally often. A recipe's batch
    (None: the stored model's own) is the batch of every update."""
    from gymnasium.spaces import Box
    from sbx import SAC

    tuning = recipe if isinstance(recipe, FineTuning) else fine_tuning_recipe(recipe)
    num_envs = 2
    envs = BatchedEnvs(lambda i: GraspEnv("A0"), num_envs, "A0")
    policies = PolicyRegistry(PolicyStore(tmp_path / "store"), [PolicyStore(assets_dir() / "priors")])
    batch = tuning.batch_size or policies.model("prior").batch_size
    random_actions, updates = [0], [0]
    real_sample, real_train = Box.sample, SAC.train

    def counted_sample(space, *args, **kwargs):
        random_actions[0] += 1
        return real_sample(space, *args, **kwargs)

    def counted_train(model, gradient_steps, batch_size=64):
        assert batch_size == batch
        assert model.replay_buffer.pos * num_envs >= batch_size, "an update before a batch was in"
        updates[0] += gradient_steps
        return real_train(model, gradient_steps, batch_size)

    monkeypatch.setattr(Box, "sample", counted_sample)
    monkeypatch.setattr(SAC, "train", counted_train)
    step_budget = batch + num_envs * 20
    try:
        outcome = Trainer(envs, policies, tmp_path / "checkpoints", fine_tuning=tuning).train(TrainSpec(
            "A0", "prior", "a0", step_budget=step_budget, threshold=0, eval_episodes=1))
    finally:
        envs.close()

    assert outcome.completed and outcome.steps_used == step_budget
    assert random_actions[0] == (batch if tuning.first_actions == "random" else 0)
    assert updates[0] == num_envs * 20
    stored, prior = policies.model("a0"), policies.model("prior")
    assert stored.batch_size == batch
    rate = tuning.learning_rate or prior.learning_rate
    assert stored.learning_rate == rate
    for state in (stored.policy.actor_state, stored.policy.qf_state):
        assert state.opt_state.hyperparams["learning_rate"] == pytest.approx(rate)


def test_an_unknown_recipe_or_setting_is_refused_with_the_choices():
    with pytest.raises(ValueError, match="random-first"):
        fine_tuning_recipe("rlpd")
    with pytest.raises(ValueError, match="first_actions"):
        FineTuning(first_actions="demonstrations")
    with pytest.raises(ValueError, match="batch_size"):
        FineTuning(batch_size=0)
    with pytest.raises(ValueError, match="critic_warmup"):
        FineTuning(critic_warmup=-1)


def test_critic_warmup_leaves_the_actor_alone_for_the_first_steps_then_updates_both(tmp_path, monkeypatch):
    """The gradient steps owed for a goal's first ``critic_warmup`` steps move the critics and not the actor;
    every later one moves both; the goal does as many gradient steps as without a warm-up."""
    import jax
    from sbx import SAC

    def flat(state):
        return np.concatenate([np.ravel(leaf) for leaf in jax.tree_util.tree_leaves(state.params)])

    num_envs, batch, warmup, step_budget = 2, 32, 60, 100
    calls: list[tuple[int, bool, bool]] = []  # (gradient steps, the actor moved, the critic moved)
    real_train = SAC.train

    def noted_train(model, gradient_steps, batch_size=64):
        actor, critic = flat(model.policy.actor_state), flat(model.policy.qf_state)
        real_train(model, gradient_steps, batch_size)
        calls.append((gradient_steps, not np.array_equal(actor, flat(model.policy.actor_state)),
                      not np.array_equal(critic, flat(model.policy.qf_state))))

    monkeypatch.setattr(SAC, "train", noted_train)
    envs = BatchedEnvs(lambda i: GraspEnv("A0"), num_envs, "A0")
    policies = PolicyRegistry(PolicyStore(tmp_path / "store"), [PolicyStore(assets_dir() / "priors")])
    try:
        outcome = Trainer(envs, policies, tmp_path / "checkpoints", fine_tuning=FineTuning(
            first_actions="policy", batch_size=batch, critic_warmup=warmup)).train(TrainSpec(
                "A0", "prior", "a0", step_budget=step_budget, threshold=0, eval_episodes=1))
    finally:
        envs.close()

    assert outcome.completed and outcome.steps_used == step_budget
    critic_only = [steps for steps, actor_moved, _ in calls if not actor_moved]
    both = [steps for steps, actor_moved, _ in calls if actor_moved]
    assert all(critic_moved for _, _, critic_moved in calls)
    assert [actor_moved for _, actor_moved, _ in calls] == [False] * len(critic_only) + [True] * len(both)
    assert sum(both) == step_budget - warmup  # UTD 1 after the warm-up
    assert sum(critic_only) == warmup - batch  # the warm-up's updates, from the step a batch is in


def test_parent_experience_starts_the_buffer_and_the_stored_policy_keeps_the_newest(tmp_path, monkeypatch):
    """The "parent-experience" way: the goal's buffer starts with its initial policy's kept transitions, so
    updates start at the first step; the policy it stores keeps the newest transitions, its own last."""
    from sbx import SAC

    from learner_node.prior import collect_experience

    parents = PolicyStore(tmp_path / "parents")
    parents.add_copy(PolicyStore(assets_dir() / "priors"), "prior", "prior")
    env = GraspEnv("A0")
    try:
        parent_experience = collect_experience(parents.load("prior"), env, 300, seed=3)
    finally:
        env.close()
    parents.keep_experience("prior", parent_experience)
    num_envs, step_budget = 2, 20
    envs = BatchedEnvs(lambda i: GraspEnv("B1"), num_envs, "B1")
    policies = PolicyRegistry(PolicyStore(tmp_path / "store"), [parents])
    rows_at_first_update, updates = [], [0]
    real_train = SAC.train

    def counted_train(model, gradient_steps, batch_size=64):
        if not rows_at_first_update:
            rows_at_first_update.append(model.replay_buffer.pos)
        updates[0] += gradient_steps
        return real_train(model, gradient_steps, batch_size)

    monkeypatch.setattr(SAC, "train", counted_train)
    tuning = FineTuning(first_actions="policy", experience=300)
    try:
        outcome = Trainer(envs, policies, tmp_path / "checkpoints", fine_tuning=tuning).train(TrainSpec(
            "B1", "prior", "b1", step_budget=step_budget, threshold=0, eval_episodes=1))
    finally:
        envs.close()

    assert outcome.completed and outcome.steps_used == step_budget
    assert updates[0] == step_budget, "the parent's 300 transitions are a batch: updates from the first step"
    assert rows_at_first_update == [300 // num_envs + 1]  # the parent's rows, then the goal's first step
    kept = policies.experience("b1")
    assert len(kept["observations"]) == 300
    np.testing.assert_array_equal(kept["observations"][:300 - step_budget],
                                  parent_experience["observations"][step_budget:])
    assert not np.array_equal(kept["observations"][-1], parent_experience["observations"][-1])

"""The learner's gradient steps run while the sim steps, in one compiled call per step: SB3's updates, a step
later, none lost; and the fine-tuning recipe decides how a goal starts."""

from dataclasses import asdict

import numpy as np
import pytest

from glocal_ros.paths import assets_dir
from learner_node.policies import PolicyRegistry
from learner_node.policy_store import PolicyStore
from learner_node.sac_settings import SAC_KWARGS, FineTuning, fine_tuning_recipe
from glocal_ros.curriculum.learner import TrainGoal
from learner_node.training import Trainer
from learner_node.updates import OverlappedUpdates
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


def noting_payments(monkeypatch, note):
    """``OverlappedUpdates.pay`` calls ``note(updates, critic_only, owed)`` before each payment that runs
    gradient steps, with what it owes (critic-only and all); then pays."""
    real_pay = OverlappedUpdates.pay

    def noted_pay(updates):
        if updates.owed or updates.owed_critic_only:
            note(updates, updates.owed_critic_only, updates.owed_critic_only + updates.owed)
        return real_pay(updates)

    monkeypatch.setattr(OverlappedUpdates, "pay", noted_pay)


def test_each_steps_updates_run_during_the_next_step_and_the_last_at_the_end(tmp_path, monkeypatch):
    num_envs = 2
    envs = SplitSteps(BatchedEnvs(lambda i: GraspEnv("A0"), num_envs, "A0"))
    policies = PolicyRegistry(PolicyStore(tmp_path / "store"), [PolicyStore(assets_dir() / "priors")])
    batch_size = policies.model("prior").batch_size
    payments: list[tuple[bool, int]] = []  # (a step was out, gradient steps)
    noting_payments(monkeypatch, lambda updates, critic_only, steps: payments.append((envs.step_out, steps)))
    vector_steps_with_updates = 20
    step_budget = batch_size + num_envs * vector_steps_with_updates
    try:
        # SB3's own start (random-first): updates from batch_size steps on, as the plain loop does.
        outcome = Trainer(envs, policies, tmp_path / "checkpoints", fine_tuning=FineTuning()).train(TrainGoal(
            "A0", "prior", "a0", step_budget=step_budget, threshold=0, eval_episodes=1))
    finally:
        envs.envs.close()

    assert outcome.completed and outcome.steps_used == step_budget
    # SB3: updates once more than batch_size steps are in, one per env step (gradient_steps=-1).
    assert sum(steps for _, steps in payments) == num_envs * vector_steps_with_updates
    assert payments == [(True, num_envs)] * (vector_steps_with_updates - 1) + [(False, num_envs)]
    stored = policies.model("a0")
    assert stored.gradient_steps == SAC_KWARGS["gradient_steps"]
    assert stored._n_updates - policies.model("prior")._n_updates == num_envs * vector_steps_with_updates


#: WSRL's warm start of the prior's batch (64) steps, and an actor slower than the critics.
WARM_START_SLOW_ACTOR = FineTuning(first_actions="policy", warm_start_steps=64, actor_learning_rate=1e-5)


@pytest.mark.parametrize("recipe", ["random-first", "policy-first", "policy-first-lr1e-4",
                                    FineTuning(first_actions="random", batch_size=32), WARM_START_SLOW_ACTOR])
def test_a_recipe_chooses_the_first_actions_and_the_rate_and_updates_wait_for_a_batch(tmp_path, monkeypatch, recipe):
    """SB3's warm-up draws a batch of random actions; "policy" acts with the loaded policy at once. Either way
    the first gradient step comes once the buffer holds a batch, so both update equally often; so does a warm
    start of a batch's steps, acting with the policy and updating nothing meanwhile. A recipe's batch (None:
    the stored model's own) is the batch of every update, and its rates those of the optimisers."""
    from gymnasium.spaces import Box

    tuning = recipe if isinstance(recipe, FineTuning) else fine_tuning_recipe(recipe)
    num_envs = 2
    envs = BatchedEnvs(lambda i: GraspEnv("A0"), num_envs, "A0")
    policies = PolicyRegistry(PolicyStore(tmp_path / "store"), [PolicyStore(assets_dir() / "priors")])
    batch = tuning.batch_size or policies.model("prior").batch_size
    random_actions, updates = [0], [0]
    real_sample = Box.sample

    def counted_sample(space, *args, **kwargs):
        random_actions[0] += 1
        return real_sample(space, *args, **kwargs)

    def counted_payment(payer, critic_only, steps):
        assert payer.model.batch_size == batch
        in_buffer = payer.ring.size + sum(len(rows["observations"]) for rows in payer.pending)
        assert in_buffer >= batch, "an update before a batch was in"
        updates[0] += steps

    monkeypatch.setattr(Box, "sample", counted_sample)
    noting_payments(monkeypatch, counted_payment)
    step_budget = batch + num_envs * 20
    try:
        outcome = Trainer(envs, policies, tmp_path / "checkpoints", fine_tuning=tuning).train(TrainGoal(
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
    actor_rate = stored.policy.actor_state.opt_state.hyperparams["learning_rate"]
    assert actor_rate == pytest.approx(tuning.actor_learning_rate or rate)
    assert stored.policy.qf_state.opt_state.hyperparams["learning_rate"] == pytest.approx(rate)


def test_an_unknown_recipe_or_setting_is_refused_with_the_choices():
    with pytest.raises(ValueError, match="random-first"):
        fine_tuning_recipe("rlpd")
    with pytest.raises(ValueError, match="first_actions"):
        FineTuning(first_actions="demonstrations")
    with pytest.raises(ValueError, match="batch_size"):
        FineTuning(batch_size=0)
    with pytest.raises(ValueError, match="critic_warmup"):
        FineTuning(critic_warmup=-1)
    with pytest.raises(ValueError, match="actor_learning_rate"):
        FineTuning(actor_learning_rate=0)
    with pytest.raises(ValueError, match="first_actions 'policy'"):
        FineTuning(warm_start_steps=100)
    with pytest.raises(ValueError, match="anchor_decay_steps"):
        FineTuning(parent_anchor=0.4)
    with pytest.raises(ValueError, match="anchor_decay_steps"):
        FineTuning(anchor_decay_steps=1000)


def test_a_recipe_records_the_remedies_only_when_set_so_checkpoints_written_before_them_resume():
    assert FineTuning().key() == {name: value for name, value in asdict(FineTuning()).items()
                                  if name not in ("actor_learning_rate", "warm_start_steps", "parent_anchor",
                                                  "anchor_decay_steps")}
    assert FineTuning(parent_anchor=0.4, anchor_decay_steps=1000).key()["parent_anchor"] == 0.4


def test_the_anchor_keeps_the_actor_near_where_the_goal_started_and_fades(tmp_path):
    """Two goals from the prior on an object it does not grasp, the same seed, one with a heavy anchor: its
    actor ends nearer its start (the deterministic actions on the goal's own observations). The weight
    falls linearly to 0 at the decay's end."""
    from learner_node.fine_tuning import goal_start_actor
    from learner_node.updates import Anchor

    anchor = Anchor(params=None, weight=0.4, decay_steps=1000, start_timesteps=500)
    assert [anchor.weight_at(t) for t in (500, 1000, 1500, 2500)] == pytest.approx([0.4, 0.2, 0.0, 0.0])

    envs = BatchedEnvs(lambda i: GraspEnv("G5"), 2, "G5")
    policies = PolicyRegistry(PolicyStore(tmp_path / "store"), [PolicyStore(assets_dir() / "priors")])
    recipes = {"free": FineTuning(first_actions="policy"),
               "anchored": FineTuning(first_actions="policy", parent_anchor=100.0, anchor_decay_steps=10_000)}
    try:
        for name, tuning in recipes.items():
            Trainer(envs, policies, tmp_path / "checkpoints", fine_tuning=tuning).train(TrainGoal(
                "G5", "prior", name, step_budget=400, threshold=0, eval_episodes=1, seed=3))
    finally:
        envs.close()
    probe = GraspEnv("G5")
    try:
        observations = np.stack([probe.reset(seed=seed)[0] for seed in range(16)]).astype(np.float32)
    finally:
        probe.close()
    start = goal_start_actor(policies.model("prior"), recipes["free"], ("G5",)).actor_state

    def moved(policy):
        actor = policies.model(policy).policy.actor_state
        ends = np.asarray(actor.apply_fn(actor.params, observations).mode())
        begins = np.asarray(start.apply_fn(start.params, observations).mode())
        return float(np.linalg.norm(ends - begins, axis=-1).mean())

    assert moved("anchored") < 0.5 * moved("free"), (moved("anchored"), moved("free"))


def test_critic_warmup_leaves_the_actor_alone_for_the_first_steps_then_updates_both(tmp_path, monkeypatch):
    """The gradient steps owed for a goal's first ``critic_warmup`` steps move the critics and not the actor;
    every later one moves both; the goal does as many gradient steps as without a warm-up."""
    import jax

    def flat(state):
        return np.concatenate([np.ravel(leaf) for leaf in jax.tree_util.tree_leaves(state.params)])

    num_envs, batch, warmup, step_budget = 2, 32, 60, 100
    calls: list[tuple[int, int, bool, bool]] = []  # (critic-only steps, steps, the actor moved, the critic moved)
    real_pay = OverlappedUpdates.pay

    def noted_pay(updates):
        owed = (updates.owed_critic_only, updates.owed_critic_only + updates.owed)
        model = updates.model
        actor, critic = flat(model.policy.actor_state), flat(model.policy.qf_state)
        real_pay(updates)
        if owed[1]:
            calls.append((*owed, not np.array_equal(actor, flat(model.policy.actor_state)),
                          not np.array_equal(critic, flat(model.policy.qf_state))))

    monkeypatch.setattr(OverlappedUpdates, "pay", noted_pay)
    envs = BatchedEnvs(lambda i: GraspEnv("A0"), num_envs, "A0")
    policies = PolicyRegistry(PolicyStore(tmp_path / "store"), [PolicyStore(assets_dir() / "priors")])
    try:
        outcome = Trainer(envs, policies, tmp_path / "checkpoints", fine_tuning=FineTuning(
            first_actions="policy", batch_size=batch, critic_warmup=warmup)).train(TrainGoal(
                "A0", "prior", "a0", step_budget=step_budget, threshold=0, eval_episodes=1))
    finally:
        envs.close()

    assert outcome.completed and outcome.steps_used == step_budget
    assert all(critic_moved for *_, critic_moved in calls)
    # The actor moves in exactly the payments with steps that are not critic-only, and those come last.
    assert [actor_moved for critic_only, steps, actor_moved, _ in calls] == \
        [steps > critic_only for critic_only, steps, _, _ in calls]
    assert all(critic_only == 0 for critic_only, *_ in calls[[c[2] for c in calls].index(True) + 1:])
    assert sum(steps - critic_only for critic_only, steps, *_ in calls) == step_budget - warmup  # UTD 1 after
    assert sum(critic_only for critic_only, *_ in calls) == warmup - batch  # from the step a batch is in


def test_parent_experience_starts_the_buffer_and_the_stored_policy_keeps_the_newest(tmp_path, monkeypatch):
    """The "parent-experience" way: the goal's buffer starts with its initial policy's kept transitions, so
    updates start at the first step; the policy it stores keeps the newest transitions, its own last."""
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

    def counted_payment(payer, critic_only, steps):
        if not rows_at_first_update:
            rows_at_first_update.append(payer.ring.size + sum(len(rows["observations"]) for rows in payer.pending))
        updates[0] += steps

    noting_payments(monkeypatch, counted_payment)
    tuning = FineTuning(first_actions="policy", experience=300)
    try:
        outcome = Trainer(envs, policies, tmp_path / "checkpoints", fine_tuning=tuning).train(TrainGoal(
            "B1", "prior", "b1", step_budget=step_budget, threshold=0, eval_episodes=1))
    finally:
        envs.close()

    assert outcome.completed and outcome.steps_used == step_budget
    assert updates[0] == step_budget, "the parent's 300 transitions are a batch: updates from the first step"
    assert rows_at_first_update == [300 + num_envs]  # the parent's transitions, then the goal's first step
    kept = policies.experience("b1")
    assert len(kept["observations"]) == 300
    np.testing.assert_array_equal(kept["observations"][:300 - step_budget],
                                  parent_experience["observations"][step_budget:])
    assert not np.array_equal(kept["observations"][-1], parent_experience["observations"][-1])


def test_the_loops_actions_are_the_numbers_sb3s_predict_gives(tmp_path):
    """The compiled calls that act (``sample_actions`` in a goal, ``deterministic_actions`` in evaluations)
    give exactly what SBX's ``predict`` gives from the same weights and keys."""
    import copy

    from learner_node.policies import deterministic_actions
    from learner_node.updates import sample_actions

    model = PolicyStore(assets_dir() / "priors").load("prior")
    observations = np.random.default_rng(0).uniform(-1, 1, (4, 63)).astype(np.float32)
    observations[:, :49] = 0
    observations[:, 3] = 1
    np.testing.assert_array_equal(deterministic_actions(model.policy)(observations),
                                  model.predict(observations, deterministic=True)[0])
    twin = copy.copy(model.policy)  # the same weights and key
    for _ in range(3):  # each call draws from a new key, in the same order
        expected = model.predict(observations, deterministic=False)[0]
        np.testing.assert_array_equal(twin.unscale_action(np.clip(sample_actions(twin, observations), -1, 1)),
                                      expected)

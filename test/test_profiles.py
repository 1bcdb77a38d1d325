"""Learner profiles (``learner_node.profiles``): ``paper`` item by item against Stable Baselines 2's SAC
defaults (hill-a/stable-baselines, the implementation the paper's "Robot Environment Setup" names),
``glocal_ros`` as the project's default, how a goal of each starts,
and that ``learner/evaluate``'s policy scores as a goal's check before its first step, on the same episodes."""

import json

import jax
import numpy as np
import pytest
from flax.traverse_util import flatten_dict

from glocal_ros.seeds import derived_seed
from glocal_ros.spaces import OBSERVATION_LAYOUT
from learner_node.evaluation import evaluate
from learner_node.policies import PolicyRegistry
from learner_node.policy_store import PolicyRecord, PolicyStore
from learner_node.profiles import PROFILES, learner_profile
from learner_node.sac_settings import DEFAULT_FINE_TUNING, FineTuning
from glocal_ros.curriculum.learner import TrainGoal
from learner_node.training import CHECKPOINT_FILE, EVALUATION_STREAM, Trainer
from learner_node.vec_env import BatchVecEnv, TaskCycle
from sim_node.batch import BatchedEnvs
from sim_node.grasp_env import GraspEnv, GraspEnvConfig

PAPER = PROFILES["paper"]
SHORT = GraspEnvConfig(max_steps=10)


@pytest.fixture(scope="module")
def paper_model():
    """A new model as the paper profile makes one (a prior's start)."""
    return PAPER.new_model(GraspEnv("A0", config=SHORT), seed=0)


def test_a_new_paper_model_has_sb2s_sac_defaults(paper_model):
    model = paper_model
    assert model.gamma == 0.99  # sac.py:61
    assert model.buffer_size == 50_000 and model.replay_buffer.buffer_size == 50_000
    assert model.batch_size == 64 and model.learning_rate == 3e-4 and model.tau == 0.005
    assert model.train_freq.frequency == 1 and model.gradient_steps == -1  # one gradient step per env step
    assert model.policy_kwargs["net_arch"] == [64, 64] and model.policy.activation_fn is jax.nn.relu
    assert model.target_entropy == -5.0  # -prod(action shape)
    assert float(model.ent_coef_state.apply_fn({"params": model.ent_coef_state.params})) == pytest.approx(1.0)


def test_a_new_paper_model_is_glorot_uniform_with_zero_biases_and_equal_targets(paper_model):
    for name in ("actor_state", "qf_state"):
        state = getattr(paper_model.policy, name)
        for path, leaf in flatten_dict(state.params).items():
            leaf = np.asarray(leaf)
            if path[-1] == "bias":
                assert not leaf.any(), path
                continue
            fan_in, fan_out = leaf.shape[-2:]
            limit = np.sqrt(6 / (fan_in + fan_out))
            assert np.abs(leaf).max() <= limit, path
            if leaf.size >= 4096:  # uniform on [-limit, limit]: std limit / sqrt(3)
                assert leaf.std() == pytest.approx(limit / np.sqrt(3), rel=0.05), path
        assert int(state.opt_state.inner_state[0].count) == 0
    qf = paper_model.policy.qf_state
    for params, targets in zip(jax.tree_util.tree_leaves(qf.params), jax.tree_util.tree_leaves(qf.target_params)):
        np.testing.assert_array_equal(params, targets)


def test_a_paper_goal_starts_as_sb2s_load_and_learn():
    tuning = PAPER.fine_tuning
    assert (tuning.first_actions, tuning.random_steps) == ("random", 100)  # learning_starts 100
    assert tuning.experience == 0  # SB2 does not save the replay buffer
    assert tuning.optimizers == "fresh-all"  # nor Adam's moments, for actor, critics and alpha
    assert tuning.new_task_inputs == "initial"  # raw one-hot inputs
    assert tuning.critic_warmup == 0 and tuning.batch_size is None and tuning.learning_rate is None
    assert tuning.rearm_warm  # SB2's learn(reset_num_timesteps=True), chunk after chunk
    assert PAPER.time_limit_terminal


def test_the_glocal_ros_profile_is_the_projects_fine_tuning():
    profile = PROFILES["glocal_ros"]
    assert profile.fine_tuning == DEFAULT_FINE_TUNING and not profile.time_limit_terminal
    assert profile.model_kwargs()["gamma"] == 0.95 and profile.prior_store == "priors"
    assert profile.with_recipe("random-first") == FineTuning()


@pytest.mark.parametrize("make, message", [
    (lambda: learner_profile("sb2"), "unknown learner profile 'sb2': choose from glocal_ros, paper"),
    (lambda: PAPER.with_recipe("random-first"), "recipe 'random-first' contradicts learner profile 'paper'"),
    (lambda: PAPER.network_of("256x256"), "network '256x256' contradicts learner profile 'paper'"),
    (lambda: PROFILES["glocal_ros"].with_recipe("rlpd"), "unknown fine-tuning recipe 'rlpd': choose from"),
    (lambda: FineTuning(first_actions="policy", random_steps=100), "only with first_actions 'random'"),
])
def test_contradictions_are_refused_naming_the_choices(make, message):
    with pytest.raises(ValueError, match=message):
        make()


def test_a_profile_with_departures_changes_only_the_items_it_names():
    from dataclasses import asdict

    bootstrap = learner_profile("paper+time-limit-bootstrap")
    assert not bootstrap.time_limit_terminal and bootstrap.fine_tuning == PAPER.fine_tuning
    both = learner_profile(" paper+trained-mean-inputs+policy-first".strip())
    assert both.name == "paper+policy-first+trained-mean-inputs"  # DEPARTURES' order, whatever the name's
    changed = {field for field, value in asdict(both.fine_tuning).items()
               if value != asdict(PAPER.fine_tuning)[field]}
    assert changed == {"first_actions", "random_steps", "rearm_warm", "new_task_inputs"}
    assert both.time_limit_terminal and both.prior_store == PAPER.prior_store and both.base == "paper"
    assert both.model_kwargs() == PAPER.model_kwargs() and both.glorot_init
    assert learner_profile("paper+initial-entropy").fine_tuning.entropy_coefficient == "initial"


@pytest.mark.parametrize("name, message", [
    ("paper+sac-v1", "learner profile 'paper\\+sac-v1': unknown departure 'sac-v1' from 'paper' "
                     "\\(departures it has: time-limit-bootstrap, policy-first, initial-entropy"),
    ("paper+policy-first+policy-first", "a departure named twice"),
    ("glocal_ros+policy-first", "departures it has: none"),
    ("sb2+policy-first", "unknown learner profile 'sb2'"),
])
def test_an_unknown_departure_is_refused_naming_the_known_ones(name, message):
    with pytest.raises(ValueError, match=message):
        learner_profile(name)


def test_a_time_limit_is_terminal_to_the_paper_learner_and_a_cut_still_bootstraps():
    envs = BatchedEnvs(lambda i: GraspEnv("A0", config=GraspEnvConfig(max_steps=3)), 2, "A0")
    try:
        env = GraspEnv("A0")
        infos = {}
        for terminal in (False, True):
            cut = iter([False, False, False, True])
            vec_env = BatchVecEnv(envs, env.observation_space, env.action_space, TaskCycle(["A0"]),
                                  between_steps=lambda: next(cut), time_limit_terminal=terminal)
            vec_env.reset()
            still = np.zeros((2, 5), dtype=np.float32)
            for _ in range(3):  # T = 3: both episodes end at their time limit
                vec_env.step_async(still)
                _, _, dones, time_limit_infos = vec_env.step_wait()
            assert dones.all()
            vec_env.step_async(still)
            _, _, dones, cut_infos = vec_env.step_wait()  # the cut
            assert dones.all()
            infos[terminal] = ([i["TimeLimit.truncated"] for i in time_limit_infos],
                               [i["TimeLimit.truncated"] for i in cut_infos])
    finally:
        envs.close()
    assert infos[False] == ([True, True], [True, True])
    assert infos[True] == ([False, False], [True, True])


@pytest.fixture
def paper_store(tmp_path, paper_model):
    """A store holding a policy of the paper profile, never trained (so it has not learned a thing)."""
    store = PolicyStore(tmp_path / "store")
    store.save(paper_model, PolicyRecord(name="new", profile="paper"))
    return store


def test_a_paper_goal_acts_at_random_for_100_steps_updates_from_the_100th_and_rearms_each_chunk(tmp_path,
                                                                                                    paper_store):
    envs = BatchedEnvs(lambda i: GraspEnv("A0", config=SHORT), 2, "A0")
    policies = PolicyRegistry(paper_store)
    trainer = Trainer(envs, policies, tmp_path / "checkpoints", profile=PAPER)
    try:
        trainer.train(TrainGoal("", "new", "chunk1", step_budget=110, episode_tasks=("A0",), seed=1))
        trainer.train(TrainGoal("", "chunk1", "chunk2", step_budget=110, episode_tasks=("A0",), seed=2,
                                keep_replay_buffer=True))
    finally:
        envs.close()
    first, second = policies.model("chunk1"), policies.model("chunk2")
    # 2 lockstep envs: random actions at counts 0..98, updates at counts 100, 102, ..., 110 (2 each).
    assert (first.learning_starts, first._n_updates) == (100, 12)
    # The warm model goes on (no reload): 100 random steps again from 110, updates at 210..220.
    assert (second.learning_starts, second._n_updates) == (210, 24)
    assert policies.record("chunk2").profile == "paper"


def test_a_goal_refuses_a_policy_of_another_profile_naming_both(tmp_path, paper_store):
    policies = PolicyRegistry(paper_store, [PolicyStore(PROFILES["glocal_ros"].shipped_priors())])
    trainer = Trainer(None, policies, tmp_path / "checkpoints", profile=PAPER)
    with pytest.raises(ValueError, match="policy 'prior' was trained under learner profile 'glocal_ros', and this "
                                         "learner runs profile 'paper'"):
        trainer.train(TrainGoal("A0", "prior", "out", step_budget=10))


def test_a_profile_with_departures_trains_its_bases_policies_and_its_base_refuses_its_own(tmp_path, paper_store):
    envs = BatchedEnvs(lambda i: GraspEnv("A0", config=SHORT), 2, "A0")
    policies = PolicyRegistry(paper_store)
    try:
        departing = Trainer(envs, policies, tmp_path / "checkpoints", profile=learner_profile("paper+initial-entropy"))
        departing.train(TrainGoal("A0", "new", "departed", step_budget=110, seed=1))
        assert policies.record("departed").profile == "paper+initial-entropy"
        departing.check_initial_policy("departed")
        with pytest.raises(ValueError, match="policy 'departed' was trained under learner profile "
                                             "'paper\\+initial-entropy', and this learner runs profile 'paper'"):
            Trainer(envs, policies, tmp_path / "checkpoints", profile=PAPER).check_initial_policy("departed")
    finally:
        envs.close()


def test_initial_entropy_starts_a_goal_at_a_new_models_coefficient_and_sb2s_way_keeps_the_stored_one(paper_model):
    from learner_node.fine_tuning import start_fine_tuning

    def coefficient(model):
        return float(model.ent_coef_state.apply_fn({"params": model.ent_coef_state.params}))

    stored = paper_model.ent_coef_state
    try:
        paper_model.ent_coef_state = stored.replace(params={"log_ent_coef": jax.numpy.log(0.02)})
        start_fine_tuning(paper_model, PAPER.fine_tuning, ["A0"])
        assert coefficient(paper_model) == pytest.approx(0.02)
        start_fine_tuning(paper_model, learner_profile("paper+initial-entropy").fine_tuning, ["A0"])
        assert coefficient(paper_model) == pytest.approx(1.0)
    finally:
        paper_model.ent_coef_state = stored


def test_a_policy_of_an_older_observation_layout_is_refused_by_goals_and_evaluations(tmp_path, paper_store):
    """A record written before layouts were recorded (no field) is of layout 1, whose yaw hid a half turn."""
    record_file = paper_store.root / "new" / "policy.json"
    record = json.loads(record_file.read_text())
    assert record.pop("observation_layout") == OBSERVATION_LAYOUT
    record_file.write_text(json.dumps(record))
    policies = PolicyRegistry(paper_store)
    trainer = Trainer(None, policies, tmp_path / "checkpoints", profile=PAPER)
    message = f"policy 'new' was trained on observation layout 1, and the sim's is {OBSERVATION_LAYOUT}"
    with pytest.raises(ValueError, match=message):
        trainer.train(TrainGoal("A0", "new", "out", step_budget=10))
    with pytest.raises(ValueError, match=message):
        trainer.evaluation_policy("new", ["A0"])


@pytest.mark.parametrize("profile, task", [("glocal_ros", "D3"), ("paper", "A0")])
def test_evaluate_scores_a_policy_as_a_goals_check_before_its_first_step(tmp_path, profile, task):
    """The shipped prior of each profile; D3 is a task the glocal_ros prior meets with A0's inputs (2 of 20
    with raw inputs, 20 of 20 in a goal, before the two were made one)."""
    profile = PROFILES[profile]
    envs = BatchedEnvs(lambda i: GraspEnv(task), 2, task)
    policies = PolicyRegistry(PolicyStore(tmp_path / "store"), [PolicyStore(profile.shipped_priors())])
    trainer = Trainer(envs, policies, tmp_path / "checkpoints", profile=profile)
    checks = []
    try:
        trainer.train(TrainGoal(task, "prior", "out", step_budget=2, eval_episodes=10, threshold=9.5,
                                stop_when_learned=True, seed=5),
                      on_evaluation=lambda score, steps: checks.append((steps, score.successes)))
        (score,) = evaluate(envs, trainer.evaluation_policy("prior", [task, "G6"]), [task], 10,
                            seed=derived_seed(5, EVALUATION_STREAM, 0))
    finally:
        envs.close()
    assert checks[0] == (0, score.successes)


def test_a_checkpoint_of_another_profile_or_recipe_is_refused_not_resumed(tmp_path):
    envs = BatchedEnvs(lambda i: GraspEnv("A0", config=SHORT), 2, "A0")
    policies = PolicyRegistry(PolicyStore(tmp_path / "store"), [PolicyStore(PROFILES["glocal_ros"].shipped_priors())])
    spec = TrainGoal("A0", "prior", "out", step_budget=40, eval_episodes=1)
    vector_steps = iter(range(1_000))
    try:
        stopped = Trainer(envs, policies, tmp_path / "checkpoints").train(
            spec, should_stop=lambda: "stopped" if next(vector_steps) >= 8 else "")
        assert not stopped.completed and "stopped after 18 steps" in stopped.message
        with pytest.raises(ValueError, match="the checkpoint of 'out' at step 18 was trained with .*'profile': "
                                             "'glocal_ros'.*delete"):
            Trainer(envs, policies, tmp_path / "checkpoints", fine_tuning=FineTuning()).train(spec)
        checkpoint = tmp_path / "checkpoints" / "out" / CHECKPOINT_FILE
        written = checkpoint.read_text()
        saved = json.loads(written)
        del saved["format"]  # what the SB3 loop before this one wrote
        checkpoint.write_text(json.dumps(saved))
        with pytest.raises(ValueError, match="the checkpoint of 'out' at step 18 is of format 'sb3-loop.*this "
                                             "learner resumes 'compiled-loop-1'.*delete"):
            Trainer(envs, policies, tmp_path / "checkpoints").train(spec)
        assert json.loads(checkpoint.read_text()) == saved, "the refused checkpoint is left as it was"
        checkpoint.write_text(written)
        resumed = Trainer(envs, policies, tmp_path / "checkpoints").train(spec)
    finally:
        envs.close()
    assert resumed.completed and "resumed from a checkpoint at step 18" in resumed.message

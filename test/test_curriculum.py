"""The strategies of glocal_ros.curriculum against the learner double: the paper's rules, budgets, resuming."""

import json
import math

import pytest

from glocal_ros.clustering import cluster_tasks, split_global_local
from glocal_ros.curriculum.journal import CallJournal, JournalMismatch
from glocal_ros.curriculum.codes import (
    ROLE_CLUSTER, ROLE_GLOBAL, ROLE_SAMPLED, STATUS_EVALUATING, STATUS_FINISHED,
)
from glocal_ros.curriculum.learner import EpisodeSummary, TrainGoal, TrainResult
from glocal_ros.curriculum.run import Run, RunConfig
from glocal_ros.curriculum.strategies import STRATEGIES, run_strategy
from glocal_ros.tasks import ALL_TASKS
from learner_double import SimulatedLearner

SMALL = ("A0", "A1", "A2", "B0", "B1", "C0", "C3", "D2", "E5", "G6")
#: A small budget for tests that run every strategy (ALP-GMM-10 refits its GMMs every 10 episodes).
SHORT = dict(step_budget=40_000, task_step_budget=8_000, eval_interval=2_000, milestone_interval=10_000,
             baseline_eval_interval=5_000, baseline_chunk_episodes=20)


def config(strategy="glocal", tasks=SMALL, **changes) -> RunConfig:
    settings = dict(step_budget=600_000, task_step_budget=60_000, eval_interval=5_000, eval_episodes=100,
                    threshold=75, milestone_interval=100_000, baseline_eval_interval=50_000, seed=3)
    return RunConfig(strategy, tuple(tasks), **{**settings, **changes})


class Recorder:
    """Observes a run: every state (copied) and assignment."""

    def __init__(self):
        self.states, self.assignments = [], []

    def state_changed(self, state):
        self.states.append(_copy(state))

    def assigned(self, assignment):
        self.assignments.append(assignment)


class Answers:
    """A learner that keeps every train answer beside its request."""

    def __init__(self, learner):
        self.learner, self.goals = learner, []

    def __getattr__(self, name):
        return getattr(self.learner, name)

    def train(self, request):
        result = self.learner.train(request)
        self.goals.append((request, result))
        return result


def _copy(state):
    from copy import deepcopy

    return deepcopy(state)


def run(strategy="glocal", learner=None, **changes):
    learner = learner or SimulatedLearner(seed=1)
    recorder = Recorder()
    the_run = Run(config(strategy, **changes), learner, recorder)
    run_strategy(the_run)
    return the_run, learner, recorder


def trains(learner):
    return [request for call, request in learner.calls if call == "train"]


def test_first_iteration_follows_algorithm_1():
    the_run, learner, recorder = run()
    kind, (policy, tasks) = learner.calls[0]
    assert (kind, policy, tasks) == ("evaluate", "prior", tuple(sorted(SMALL)))

    # Recompute the first decision from the states the run published.
    first = next(s for s in recorder.states if s.clusters)
    c1_tasks, c1_scores = first.clusters[0]
    assert list(c1_scores) == sorted(c1_scores, reverse=True), "C1 is in descending score order"
    means = [sum(scores) / len(scores) for _, scores in first.clusters]
    assert means == sorted(means, reverse=True), "clusters by descending mean score"
    assert first.global_task == c1_tasks[len(c1_tasks) // 2], "the ceil-median"
    assert first.local_tasks == [t for t in c1_tasks if t != first.global_task]

    requests = trains(learner)
    assert (requests[0].task, requests[0].initial_policy, requests[0].output_policy) == (
        first.global_task, "prior", "glocal-seed3.G1")
    # In an iteration with local tasks, they train as a chain from pi_G,m.
    m = next(s.iteration for s in recorder.states if len(s.local_tasks) >= 2)
    decided = next(s for s in recorder.states if s.iteration == m and s.clusters)
    goals = [r for r, a in zip(requests, recorder.assignments) if a.iteration == m]
    assert goals[0].task == decided.global_task and goals[0].initial_policy == "glocal-seed3." + f"G{m - 1}"
    local = goals[1:]
    assert [r.task for r in local] == decided.local_tasks
    assert local[0].initial_policy == f"glocal-seed3.G{m}"
    for before, after in zip(local, local[1:]):
        learned_before = before.output_policy in the_run.state.learned_policies
        assert after.initial_policy == (before.output_policy if learned_before else before.initial_policy)
    # The next iteration evaluates pi_G,m.
    evaluations = [args for call, args in learner.calls if call == "evaluate"]
    assert evaluations[m][0] == f"glocal-seed3.G{m}"


def test_glocal_learns_tasks_and_stops_when_all_are_learned():
    the_run, learner, recorder = run(step_budget=5_000_000, task_step_budget=200_000)
    state = the_run.state
    assert state.status == STATUS_FINISHED
    assert sorted(state.learned_tasks) == sorted(SMALL) and not state.remaining_tasks
    assert state.total_steps < 5_000_000
    assert state.learned_at_steps == sorted(state.learned_at_steps)
    assert len(state.learned_policies) == len(state.learned_tasks)


def test_an_unlearned_task_returns_to_the_pool():
    impossible = {t: 0.0 for t in ALL_TASKS} | {"G6": 1.0}  # G6 never improves
    learner = SimulatedLearner(difficulty=impossible, seed=1)
    the_run, _, recorder = run(learner=learner, tasks=("A0", "A1", "G6"), step_budget=400_000, max_iter=4)
    assert "G6" in the_run.state.remaining_tasks and "G6" not in the_run.state.learned_tasks
    g6_goals = [r for r in trains(learner) if r.task == "G6"]
    assert len(g6_goals) >= 2, "G6 was offered again in later iterations"
    assert all(r.step_budget <= 60_000 for r in g6_goals), "the per-task budget bounds every attempt"
    evaluations = [args[1] for call, args in learner.calls if call == "evaluate"]
    assert all("G6" in tasks for tasks in evaluations)


def test_two_tasks_form_one_cluster():
    the_run, learner, recorder = run(tasks=("A0", "G6"))
    first = next(s for s in recorder.states if s.clusters)
    assert len(first.clusters) == 1 and math.isnan(first.silhouette)


def test_a_single_task_is_trained_as_the_global_task():
    the_run, learner, recorder = run(tasks=("B2",))
    assert recorder.assignments[0].role == ROLE_GLOBAL and recorder.assignments[0].task == "B2"
    assert the_run.state.learned_tasks == ["B2"]


@pytest.mark.parametrize("score", [0.0, 100.0])
def test_equal_scores_make_one_cluster_whose_middle_task_goes_first(score):
    tasks = ["A0", "B1", "C2", "D3", "E4"]
    clustering = cluster_tasks({t: score for t in tasks})
    assert len(clustering.clusters) == 1
    assert split_global_local(clustering.clusters[0]) == ("C2", ["A0", "B1", "D3", "E4"])


def test_budgets_milestones_and_evaluation_episodes_of_every_strategy():
    """Against a double with N = 4 lockstep envs and budgets that are not multiples of 4: a goal trains
    a multiple of 4 steps, never past its budget; the run's last 1..3 steps cannot be trained, and
    the run ends instead of asking for them forever (``DiesAfter`` stops one that would)."""
    for strategy in STRATEGIES:
        learner = Answers(SimulatedLearner(seed=1, lockstep_envs=4))
        budgets = dict(step_budget=40_002, task_step_budget=8_001)
        the_run = Run(config(strategy, **(SHORT | budgets)), DiesAfter(learner, 5_000))
        run_strategy(the_run)
        state = the_run.state
        assert state.status == STATUS_FINISHED, strategy
        assert all(1 <= request.step_budget <= 40_002 for request, _ in learner.goals), strategy
        assert all(result.steps_used <= request.step_budget and result.steps_used % 4 == 0
                   for request, result in learner.goals), strategy
        assert state.total_steps == sum(result.steps_used for _, result in learner.goals) <= 40_002, strategy
        assert state.total_steps > 40_002 - 4 or not state.remaining_tasks, strategy
        # A finished run's count is final: it stands at every milestone up to the budget.
        assert state.milestone_steps == [10_000, 20_000, 30_000, 40_000], strategy
        for milestone, learned in zip(state.milestone_steps, state.milestone_learned):
            assert learned == sum(1 for s in state.learned_at_steps if s <= milestone)
        # Evaluation episodes are counted beside the training steps, not charged to the budget.
        evaluated_tasks = sum(len(args[1]) for call, args in learner.calls if call == "evaluate")
        assert state.evaluation_episodes == 100 * evaluated_tasks > 0, strategy


@pytest.mark.parametrize("strategy", list(STRATEGIES))
def test_runs_are_deterministic_under_a_seed(strategy):
    """Half the SHORT budget: ALP-GMM-10 still refits its GMMs about 40 times."""
    first, _, _ = run(strategy, **(SHORT | dict(step_budget=20_000)))
    second, _, _ = run(strategy, **(SHORT | dict(step_budget=20_000)))
    assert first.state == second.state


def test_baselines_train_one_policy_and_copy_it_for_every_passing_task():
    for strategy in ("random", "alp_gmm_10", "alp_gmm_250"):
        the_run, learner, recorder = run(strategy, **SHORT)
        requests = trains(learner)
        assert {a.role for a in recorder.assignments} == {ROLE_SAMPLED}
        assert requests[0].initial_policy == "prior"
        assert {r.output_policy for r in requests} == {f"{strategy}-seed3.policy"}
        assert all(r.keep_replay_buffer and not r.task for r in requests)
        copies = [args for call, args in learner.calls if call == "copy"]
        assert [destination for _, destination in copies] == the_run.state.learned_policies
        assert the_run.state.learned_policies == [f"{strategy}-seed3.{t}" for t in the_run.state.learned_tasks]
    sampled = {t for r in trains(learner) for t in r.episode_tasks}
    assert sampled <= set(SMALL)


def test_random_samples_tasks_uniformly():
    the_run, learner, _ = run("random", step_budget=2_000_000, baseline_chunk_episodes=100)
    from collections import Counter

    counts = Counter(t for r in trains(learner) for t in r.episode_tasks)
    assert set(counts) == set(SMALL)
    assert max(counts.values()) < 1.3 * min(counts.values())


def test_no_global_sweeps_the_cluster_with_the_per_task_rule():
    """The paper's "policy trained over all tasks within the cluster", that "arbitrarily sweeps" them."""
    learner = Answers(SimulatedLearner(seed=1))
    the_run, _, recorder = run("glocal_no_global", learner=learner)
    first_state = next(s for s in recorder.states if s.clusters)
    assert not first_state.global_task
    cluster = first_state.clusters[0][0]
    assert sorted(first_state.local_tasks) == sorted(cluster), "the sweep covers the cluster, in some order"
    sweep = learner.goals[: len(cluster)]
    assert [request.task for request, _ in sweep] == first_state.local_tasks
    assert {a.role for a in recorder.assignments[: len(cluster)]} == {ROLE_CLUSTER}
    for index, (request, result) in enumerate(sweep):
        assert request.stop_when_learned and not request.episode_tasks, "each task until it passes B"
        assert request.step_budget == 60_000 and request.eval_interval == 5_000, "the per-task budget"
        assert request.output_policy == f"glocal_no_global-seed3.C1_{index}"
        # One policy through the whole cluster, learned or not.
        assert request.initial_policy == ("prior" if index == 0 else sweep[index - 1][0].output_policy)
        if result.learned:
            learned = the_run.state.learned_tasks.index(request.task)
            assert the_run.state.learned_policies[learned] == request.output_policy
    # The policy at the end of the sweep is the next iteration's prior.
    evaluations = [args for call, args in learner.calls if call == "evaluate"]
    assert evaluations[1][0] == sweep[-1][0].output_policy


def test_no_global_runs_to_the_end_of_its_pool():
    the_run, _, _ = run("glocal_no_global", step_budget=2_000_000)
    state = the_run.state
    assert sorted(state.learned_tasks) == sorted(SMALL) and state.status == STATUS_FINISHED


def test_random_cluster_picks_other_clusters():
    chosen = set()
    for seed in range(6):
        _, _, recorder = run("glocal_random_cluster", seed=seed, step_budget=100_000)
        chosen |= {s.chosen_cluster for s in recorder.states if s.clusters}
    assert len(chosen) > 1, "a random cluster, not always C1"


@pytest.mark.parametrize("strategy", ["random", "alp_gmm_10"])
@pytest.mark.parametrize("baseline_tasks", ["all", "unlearned"])
def test_the_baselines_draw_from_all_tasks_or_the_unlearned_ones(strategy, baseline_tasks):
    learner = Answers(SimulatedLearner(seed=1))
    the_run, _, _ = run(strategy, learner=learner, baseline_tasks=baseline_tasks, **SHORT)
    learned_at = dict(zip(the_run.state.learned_tasks, the_run.state.learned_at_steps))
    assert learned_at.get("A0") == 0, "the prior passes A0 at step 0"
    drawn_once_learned, steps = set(), 0
    for request, result in learner.goals:
        drawn_once_learned |= {t for t in request.episode_tasks if learned_at.get(t, steps + 1) <= steps}
        steps += result.steps_used
    if baseline_tasks == "all":
        assert "A0" in drawn_once_learned, "a learned task is still drawn"
    else:
        assert not drawn_once_learned


class LockstepFailures:
    """N envs stepping together, every episode failing at T, as the learner runs a goal: after s lockstep
    steps N x (s // T) episodes have finished, and a goal ends with its limit's last one or at its budget."""

    def __init__(self, envs: int = 4, max_episode_steps: int = 50):
        self.envs, self.max_episode_steps = envs, max_episode_steps
        self.goals: list[tuple[TrainGoal, TrainResult]] = []

    def evaluate(self, policy, tasks, episodes, seed=None):
        return {task: 0.0 for task in tasks}

    def copy(self, source, destination):
        pass

    def train(self, request: TrainGoal) -> TrainResult:
        rounds = request.step_budget // self.envs // self.max_episode_steps  # whole episodes per env
        finished = min(request.episode_limit, self.envs * rounds)
        if finished == request.episode_limit:
            steps = -(-finished // self.envs) * self.max_episode_steps * self.envs
        else:
            steps = request.step_budget - request.step_budget % self.envs
        episodes = tuple(EpisodeSummary(task, -float(self.max_episode_steps), self.max_episode_steps, False)
                         for task in request.episode_tasks[:finished])
        result = TrainResult(False, -1.0, steps, episodes)
        self.goals.append((request, result))
        return result


@pytest.mark.parametrize("strategy, fit_rate", [("alp_gmm_10", 10), ("alp_gmm_250", 250)])
def test_alp_gmm_refits_on_schedule_with_lockstep_envs_that_finish_episodes_together(strategy, fit_rate):
    """With N = 4 lockstep envs a chunk of k episodes' steps finishes up to N - 1 short; the next goal, the
    remainder, once had a budget of fewer than N episodes' steps and finished none, so ALP-GMM never refitted
    and every later goal was 100 steps of cut episodes (the paper-bench runs of 6e6ac60)."""
    learner = LockstepFailures()
    run(strategy, learner=learner, **(SHORT | dict(step_budget=60_000, baseline_eval_interval=30_000)))
    assert all(result.episodes for _, result in learner.goals), "every goal finishes episodes"
    episodes = sum(len(result.episodes) for _, result in learner.goals)
    steps = sum(result.steps_used for _, result in learner.goals)
    # Nearly every step in a counted episode (a chunk of 10 on 4 envs: 12 finish together, 10 count).
    assert episodes >= 0.8 * steps / learner.max_episode_steps, (episodes, steps)
    assert episodes // fit_rate >= 4, "the GMM refits every fit_rate episodes"


def test_baseline_tasks_must_be_all_or_unlearned():
    with pytest.raises(ValueError, match="baseline_tasks 'some'.*all, unlearned"):
        config("random", baseline_tasks="some")


@pytest.mark.parametrize("strategy, fit_rate, budget", [("alp_gmm_10", 10, 20_000), ("alp_gmm_250", 250, 60_000)])
def test_alp_gmm_draws_every_episode_from_the_gmm_of_its_last_refit(strategy, fit_rate, budget):
    """A goal is the episodes until the next refit (or until the next evaluation, and the next goal
    the rest of them), each a fresh draw: none is a task drawn before a refit and cycled after it,
    as when a goal was fit_rate episodes' worth of steps. (ALP-GMM-250 needs the longer budget to
    refit several times; ALP-GMM-10 refits about 40 times in the shorter one.)"""
    learner = Answers(SimulatedLearner(seed=1))
    run(strategy, learner=learner, **(SHORT | dict(step_budget=budget)))
    assert len(learner.goals) > 3
    since_refit = 0
    for request, result in learner.goals:
        assert request.episode_limit == fit_rate - since_refit
        assert len(request.episode_tasks) >= request.episode_limit
        assert [e.task for e in result.episodes] == list(request.episode_tasks[: len(result.episodes)])
        since_refit = (since_refit + len(result.episodes)) % fit_rate
    if fit_rate * 50 > SHORT["baseline_eval_interval"]:  # T = 50: a whole chunk would run past an evaluation
        assert any(len(result.episodes) < request.episode_limit for request, result in learner.goals[:-1])


@pytest.mark.parametrize("strategy, lockstep_envs", [("random", 1), ("alp_gmm_250", 2)])
def test_baselines_evaluate_at_step_zero_and_then_on_a_fixed_schedule(strategy, lockstep_envs):
    """The policy is checked at step 0, as GloCAL's prior is, then at every k x baseline_eval_interval
    steps: a goal that would run past the next check is cut there (it once ran on to its end, and an
    ALP-GMM-250 goal past several checks), and at the budget's end."""
    interval = 3_000
    learner = SimulatedLearner(seed=1, lockstep_envs=lockstep_envs)
    the_run, _, recorder = run(strategy, learner=learner, **(SHORT | dict(baseline_eval_interval=interval)))
    checked_at = []
    for state in recorder.states:
        if state.status == STATUS_EVALUATING and (not checked_at or checked_at[-1] != state.total_steps):
            checked_at.append(state.total_steps)
    scheduled = list(range(0, the_run.state.total_steps + 1, interval))
    if the_run.steps_left == 0 and the_run.state.total_steps not in scheduled:
        scheduled.append(the_run.state.total_steps)  # the budget's end
    assert len(checked_at) == len(scheduled) >= 5
    # A lockstep learner stops up to N - 1 steps short of a goal's budget.
    assert all(k - learner.lockstep_envs < at <= k for at, k in zip(checked_at, scheduled)), (checked_at, scheduled)


def test_a_run_that_learns_everything_early_stands_at_every_milestone():
    the_run, _, _ = run("glocal", tasks=("A0",), **SHORT)  # the prior passes A0 at its first check
    state = the_run.state
    assert state.total_steps == 0 and state.status == STATUS_FINISHED
    assert state.milestone_steps == [10_000, 20_000, 30_000, 40_000]
    assert state.milestone_learned == [1, 1, 1, 1]


class Killed(Exception):
    pass


class DiesAfter:
    """A learner that dies (like a killed node) on its ``calls``-th call."""

    def __init__(self, learner, calls):
        self.learner, self.left = learner, calls

    def __getattr__(self, name):
        method = getattr(self.learner, name)

        def call(*args):
            self.left -= 1
            if self.left < 0:
                raise Killed()
            return method(*args)

        return call


@pytest.mark.parametrize("strategy", ["glocal", "alp_gmm_250"])
def test_a_killed_run_resumes_from_its_journal(tmp_path, strategy):
    settings = SHORT
    uninterrupted, uninterrupted_learner, _ = run(strategy, **settings)

    journal = tmp_path / "journal.jsonl"
    cfg = config(strategy, **settings)
    # The learner outlives the curriculum node (its policies are on disk): one double throughout.
    learner = SimulatedLearner(seed=1)
    with pytest.raises(Killed):
        run_strategy(Run(cfg, DiesAfter(learner, 7), journal=CallJournal(journal, {"c": 1})))
    assert len(journal.read_text().splitlines()) == 1 + 7

    progress = []
    journaled = CallJournal(journal, {"c": 1}, on_replayed=lambda replayed, total: progress.append((replayed, total)))
    resumed = Run(cfg, learner, journal=journaled)
    run_strategy(resumed)
    assert journaled.replayed == 7
    assert progress == [(n, 7) for n in range(1, 8)]  # what the node reports while it replays
    assert resumed.state == uninterrupted.state
    assert len(learner.calls) == len(uninterrupted_learner.calls), "no call was asked twice"


def test_the_journal_says_what_each_call_cost(tmp_path):
    journal = tmp_path / "journal.jsonl"
    the_run = Run(config("random", **SHORT), SimulatedLearner(seed=1), journal=CallJournal(journal, {}))
    run_strategy(the_run)
    entries = [json.loads(line) for line in journal.read_text().splitlines()[1:]]
    assert sum(e["cost"].get("training_steps", 0) for e in entries) == the_run.state.total_steps > 0
    assert sum(e["cost"].get("evaluation_episodes", 0) for e in entries) == the_run.state.evaluation_episodes > 0


def test_a_journal_of_other_settings_is_refused(tmp_path):
    journal = tmp_path / "journal.jsonl"
    CallJournal(journal, {"strategy": "glocal"})
    with pytest.raises(JournalMismatch, match="other settings"):
        CallJournal(journal, {"strategy": "random"})


def test_a_journal_line_cut_by_a_kill_is_dropped(tmp_path):
    journal = tmp_path / "journal.jsonl"
    Run(config(), SimulatedLearner(), journal=CallJournal(journal, {})).evaluate("prior", ["A0"])
    with open(journal, "a") as stream:
        stream.write('{"key": "call1", "learner": 0, "call": "train", "argu')
    resumed = CallJournal(journal, {})
    assert resumed.replaying and len(journal.read_text().splitlines()) == 2


@pytest.mark.parametrize("changes, message", [
    (dict(tasks=()), "at least one task"),
    (dict(tasks=("A0", "A0")), "repeat"),
    (dict(tasks=("Z9",)), "Z9"),
    (dict(step_budget=0), "step_budget"),
    (dict(threshold=100), "threshold"),
    (dict(k_min=5, k_max=3), "k_min"),
])
def test_bad_settings_are_refused(changes, message):
    with pytest.raises(ValueError, match=message):
        config(**changes)


def test_the_double_refuses_what_the_learner_refuses():
    learner = SimulatedLearner()
    with pytest.raises(KeyError):
        learner.evaluate("nope", ["A0"], 10)
    with pytest.raises(ValueError):
        learner.train(TrainGoal("A0", "prior", "x", 0, 75, 100))


def test_every_named_strategy_exists():
    from glocal_ros.curriculum.codes import STRATEGY_NAMES

    assert tuple(STRATEGIES) == STRATEGY_NAMES


@pytest.mark.parametrize("strategy", ["glocal", "glocal_random_cluster", "glocal_no_global", "random"])
def test_sequential_journals_are_unchanged(tmp_path, strategy):
    """A sequential run (``parallel_locals: false``) asks, seeds and journals exactly what it did before the
    run became a scheduler of outstanding calls: byte for byte (see ``sequential_journals``)."""
    from sequential_journals import REFERENCES, without_keys, write_journal

    written = tmp_path / "journal.jsonl"
    write_journal(strategy, written)
    assert without_keys(written) == without_keys(REFERENCES / f"{strategy}.jsonl")
    entries = [json.loads(line) for line in written.read_text().splitlines()[1:]]
    assert all(entry["learner"] == 0 for entry in entries)
    assert len({entry["key"] for entry in entries}) == len(entries), "every call has a key of its own"


@pytest.mark.parametrize("strategy", ["glocal", "random"])
def test_a_journal_written_before_calls_had_keys_resumes(tmp_path, strategy):
    """A reference journal (no keys: the code before the one scheduler), cut in the middle, and the
    double's store as that run left it at the cut: the run resumes from the journal, asks nothing twice
    and ends as the old run did."""
    from sequential_journals import REFERENCES, SETTINGS, TASKS, without_keys

    reference = REFERENCES / f"{strategy}.jsonl"
    lines = reference.read_text().splitlines(keepends=True)
    cut = len(lines) // 2
    journal = tmp_path / "journal.jsonl"
    journal.write_text("".join(lines[:cut]))
    cfg = RunConfig(strategy, TASKS, **SETTINGS)
    learner = SimulatedLearner(seed=1, lockstep_envs=2)  # its store outlives the curriculum node
    with pytest.raises(Killed):
        run_strategy(Run(cfg, DiesAfter(learner, cut - 1)))
    asked_before = len(learner.calls)
    resumed = CallJournal(journal, cfg.journal_settings())
    run_strategy(Run(cfg, learner, journal=resumed))
    assert resumed.replayed == cut - 1
    assert len(learner.calls) - asked_before == len(lines) - cut, "no journaled call asked again"
    assert without_keys(journal) == without_keys(reference)

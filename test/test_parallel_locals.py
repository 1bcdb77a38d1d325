"""GloCAL with parallel locals (``parallel_locals: true``) over a pool of learner doubles.

The completion order is the test's (``SteppedCalls``): first started first, or last started first.
"""

import json

import pytest

from glocal_ros.curriculum.codes import ROLE_GLOBAL, ROLE_LOCAL, STATUS_FINISHED
from glocal_ros.curriculum.journal import CallJournal
from glocal_ros.curriculum.run import Run
from glocal_ros.curriculum.strategies import run_strategy
from learner_double import Killed, SimulatedLearner, SteppedCalls
from test_curriculum import SHORT, SMALL, Answers, Recorder, config

FIRST_STARTED_FIRST = lambda keys: 0  # noqa: E731
LAST_STARTED_FIRST = lambda keys: len(keys) - 1  # noqa: E731
ORDERS = {"first-started-first": FIRST_STARTED_FIRST, "last-started-first": LAST_STARTED_FIRST}


def parallel_run(pairs=2, choose=FIRST_STARTED_FIRST, journal=None, ends_after=None, learner=None,
                 strategy="glocal", **changes):
    learner = learner or Answers(SimulatedLearner(seed=1, lockstep_envs=2))
    recorder = Recorder()
    calls = SteppedCalls(choose, ends_after)
    # One double for every slot: the learners share one policy store.
    the_run = Run(config(strategy, parallel_locals=True, **(SHORT | changes)), learner, recorder,
                  learners=[learner] * pairs, journal=journal, calls=calls)
    run_strategy(the_run)
    return the_run, learner, recorder, calls


@pytest.mark.parametrize("order", ORDERS)
@pytest.mark.parametrize("pairs", [1, 2, 3])
def test_locals_start_from_the_global_policy_and_overlap_the_next_iteration(order, pairs):
    the_run, learner, recorder, calls = parallel_run(pairs, ORDERS[order])
    state = the_run.state
    assert state.status == STATUS_FINISHED
    assert state.total_steps == sum(result.steps_used for _, result in learner.goals) <= SHORT["step_budget"]
    for assignment in recorder.assignments:
        if assignment.role == ROLE_LOCAL:
            assert assignment.initial_policy == f"glocal-seed3.G{assignment.iteration}", "no chain"
    assert any(a.role == ROLE_LOCAL for a in recorder.assignments)
    # No more calls at once than learners, and never one task twice at once.
    for key, running in calls.overlaps:
        assert len(running) < pairs
        tasks = [k.split("/")[2] for k in (key, *running) if "/local/" in k or "/global/" in k]
        assert len(tasks) == len(set(tasks)), (key, running)
    if pairs > 1:
        assert any("/evaluate" in key and any("/local/" in k for k in running) for key, running in calls.overlaps), \
            "the next iteration's evaluation overlaps locals in flight"
    # Learned tasks were learned by the policy their goal wrote.
    outputs = {request.output_policy: request.task for request, result in learner.goals if result.learned}
    assert {outputs[p] for p in state.learned_policies} == set(state.learned_tasks)


def test_the_budget_counts_the_steps_of_goals_in_flight():
    the_run, learner, recorder, calls = parallel_run(3, LAST_STARTED_FIRST, step_budget=12_000,
                                                     task_step_budget=5_000)
    budgets = {f"m{a.iteration}/{'global' if a.role == ROLE_GLOBAL else 'local'}/{a.task}": a.step_budget
               for a in recorder.assignments}
    for key, running in calls.overlaps:  # what goals in flight reserve, and the new one, fit the budget
        assert sum(budgets.get(k, 0) for k in (key, *running)) <= 12_000
    assert the_run.state.total_steps <= 12_000
    assert any(b < 5_000 for b in budgets.values()), "a goal clipped to what was left after those in flight"


def test_with_plenty_of_budget_parallel_and_sequential_learn_the_same_set():
    plenty = dict(step_budget=3_000_000, task_step_budget=200_000)
    sequential = Run(config("glocal", **(SHORT | plenty)), SimulatedLearner(seed=1))
    run_strategy(sequential)
    parallel, _, _, _ = parallel_run(2, **plenty)
    assert sorted(parallel.state.learned_tasks) == sorted(sequential.state.learned_tasks) == sorted(SMALL)


def test_threads_run_the_calls_when_no_runner_is_given():
    learner = SimulatedLearner(seed=1)
    the_run = Run(config("glocal", parallel_locals=True, **SHORT), learner, learners=[learner, learner])
    run_strategy(the_run)
    assert the_run.state.status == STATUS_FINISHED and the_run.state.learned_tasks


@pytest.mark.parametrize("order", ORDERS)
@pytest.mark.parametrize("share", [0, 0.2, 0.5, 0.8])
def test_a_run_killed_with_calls_in_flight_resumes_from_its_journal(tmp_path, order, share):
    """Cut after a share of the run's answers, with up to 3 calls in flight."""
    uninterrupted, answers, _, _ = parallel_run(3, ORDERS[order])
    cut = round(share * len(answers.calls))
    path = tmp_path / "journal.jsonl"
    settings = config("glocal", parallel_locals=True, **SHORT).journal_settings()
    learner = SimulatedLearner(seed=1, lockstep_envs=2)  # the store outlives the curriculum node
    with pytest.raises(Killed):
        parallel_run(3, ORDERS[order], journal=CallJournal(path, settings), ends_after=cut, learner=learner)
    assert len(path.read_text().splitlines()) == 1 + cut
    journal = CallJournal(path, settings)
    resumed, _, _, calls = parallel_run(3, ORDERS[order], journal=journal, learner=learner)
    assert journal.replayed == cut
    assert resumed.state == uninterrupted.state
    assert all(key not in {k for _, k in calls.started} for key in _keys(path)[:cut]), "no answered call asked again"


def test_calls_in_flight_at_the_kill_may_end_in_another_order_after_it(tmp_path):
    path = tmp_path / "journal.jsonl"
    settings = config("glocal", parallel_locals=True, **SHORT).journal_settings()
    learner = SimulatedLearner(seed=1, lockstep_envs=2)
    with pytest.raises(Killed):
        parallel_run(3, FIRST_STARTED_FIRST, journal=CallJournal(path, settings), ends_after=4, learner=learner)
    resumed, _, _, _ = parallel_run(3, LAST_STARTED_FIRST, journal=CallJournal(path, settings), learner=learner)
    assert resumed.state.status == STATUS_FINISHED
    keys = _keys(path)
    assert len(keys) == len(set(keys)), "every call answered once"


def test_the_journal_says_which_learner_answered(tmp_path):
    path = tmp_path / "journal.jsonl"
    settings = config("glocal", parallel_locals=True, **SHORT).journal_settings()
    assert settings["parallel_locals"] is True
    parallel_run(2, LAST_STARTED_FIRST, journal=CallJournal(path, settings))
    import json

    entries = [json.loads(line) for line in path.read_text().splitlines()[1:]]
    assert {entry["learner"] for entry in entries} == {0, 1}
    assert all(entry["key"].startswith("m") for entry in entries)


def _keys(path):
    import json

    return [json.loads(line)["key"] for line in path.read_text().splitlines()[1:]]


class Gone(RuntimeError):
    """A learner left the graph and did not come back in time."""


class LeavesMidGoal:
    """A learner that fails its first ``fails`` train calls of local tasks, as a killed pair does."""

    def __init__(self, learner, fails):
        self.learner, self.fails, self.failed = learner, fails, []

    def __getattr__(self, name):
        return getattr(self.learner, name)

    def train(self, request):
        if len(self.failed) < self.fails and ".L" in request.output_policy:
            self.failed.append(request.output_policy)
            raise Gone(request.output_policy)
        return self.learner.train(request)


def pool_with_a_leaving_pair(tmp_path, fails):
    store = SimulatedLearner(seed=1, lockstep_envs=2)
    leaving = LeavesMidGoal(store, fails)
    path = tmp_path / "journal.jsonl"
    the_run = Run(config("glocal", parallel_locals=True, **SHORT), store, Recorder(), learners=[store, leaving],
                  journal=CallJournal(path, {}), calls=SteppedCalls(LAST_STARTED_FIRST), resend_on=(Gone,))
    return the_run, leaving, path


def test_a_goal_whose_pair_left_goes_to_a_free_pair_and_the_run_goes_on(tmp_path):
    uninterrupted, _, _, _ = parallel_run(2, LAST_STARTED_FIRST)
    the_run, leaving, path = pool_with_a_leaving_pair(tmp_path, fails=1)
    run_strategy(the_run)
    assert the_run.state.status == STATUS_FINISHED and leaving.failed
    keys = _keys(path)
    assert len(keys) == len(set(keys)), "every call answered once"
    answered = {json.loads(line)["arguments"].get("output_policy") for line in path.read_text().splitlines()[1:]}
    assert set(leaving.failed) <= answered, "the goal of the pair that left was answered after all"
    assert sorted(the_run.state.learned_tasks) == sorted(uninterrupted.state.learned_tasks)


def test_a_call_that_fails_on_every_send_ends_the_run(tmp_path):
    the_run, leaving, _ = pool_with_a_leaving_pair(tmp_path, fails=10**6)
    the_run.learners = [leaving, leaving]
    with pytest.raises(Gone):
        run_strategy(the_run)
    from glocal_ros.curriculum.run import MAX_SENDS

    assert len(leaving.failed) == MAX_SENDS


class AwayAfterLeaving(LeavesMidGoal):
    """A leaving pair that can be watched (``ReturningLearner``): not back for its first ``away_watches``."""

    def __init__(self, learner, fails, away_watches):
        super().__init__(learner, fails)
        self.away_watches, self.watches = away_watches, 0

    def wait_until_ready(self):
        self.watches += 1
        if self.watches <= self.away_watches:
            raise Gone("not back yet")


def test_a_pair_that_left_gets_no_call_until_it_is_back(tmp_path):
    store = SimulatedLearner(seed=1, lockstep_envs=2)
    leaving = AwayAfterLeaving(store, fails=1, away_watches=2)
    path = tmp_path / "journal.jsonl"
    calls = SteppedCalls(LAST_STARTED_FIRST)
    the_run = Run(config("glocal", parallel_locals=True, **SHORT), store, Recorder(), learners=[store, leaving],
                  journal=CallJournal(path, {}), calls=calls, resend_on=(Gone,))
    run_strategy(the_run)
    assert the_run.state.status == STATUS_FINISHED and leaving.failed and leaving.watches == 3
    on_the_leaving_pair = [key for slot, key in calls.started if slot == 1]
    failed = next(i for i, key in enumerate(on_the_leaving_pair) if key.startswith("m") and "/local/" in key)
    assert on_the_leaving_pair[failed + 1:failed + 4] == ["watch learner 1"] * 3, "watched until back, nothing sent"
    assert any(key.startswith("m") for key in on_the_leaving_pair[failed + 4:]), "back in the pool"
    keys = _keys(path)
    assert len(keys) == len(set(keys)), "every call answered once"


def test_a_pool_whose_every_learner_is_away_ends_the_run(tmp_path):
    store = SimulatedLearner(seed=1, lockstep_envs=2)
    leaving = AwayAfterLeaving(store, fails=1, away_watches=10**6)
    the_run = Run(config("glocal", parallel_locals=True, **SHORT), store, Recorder(), learners=[leaving],
                  journal=CallJournal(tmp_path / "journal.jsonl", {}), calls=SteppedCalls(), resend_on=(Gone,))
    with pytest.raises(Gone, match="not back yet"):
        run_strategy(the_run)
    assert leaving.watches == 1


def test_the_strategies_that_overlap_calls_are_the_ones_launch_starts_several_pairs_for():
    """``processes.PARALLEL_STRATEGIES`` (stdlib-only, so not imported from here) names exactly the strategies
    that, given parallel_locals and two learners, ever have two calls out at once."""
    from glocal_app.processes import PARALLEL_STRATEGIES
    from glocal_ros.curriculum.codes import STRATEGY_NAMES

    overlapping = {strategy for strategy in STRATEGY_NAMES
                   if any(running for _, running in parallel_run(2, strategy=strategy)[3].overlaps)}
    assert overlapping == set(PARALLEL_STRATEGIES)

"""A scaling model of a run: what each learner call costs, measured on a recorded run, and the wall-clock
of the same run with K sim/learner pairs, found by driving the curriculum's own code on a virtual clock.

Read top to bottom: read a run directory, time its calls, fit the model, then simulate.

1. ``read_recorded_run``: a run directory's journal (``curriculum/journal.jsonl``: the settings and
   every answered call) and its bag (``bag/``: each CurriculumState's header stamp, the curriculum's
   clock, and the learner's EvaluationResults). The run's wall-clock is its first state to its last,
   as ``bench curriculum`` counts it (node start-up left out). A resumed run (``bag.1/``...) is
   refused: its calls span the kill.
2. ``time_calls`` (sequential runs only): the real strategy is run again through ``Run`` on the
   journal's answers (its ``CallJournal`` over a copy), and each call is placed between the states
   the node published around it. The run is cut at every state published right after an answer:
   a segment holds the calls answered in it (two at most in practice: an evaluation and the copies
   the baselines make at once) and runs from the previous cut; so the segments add up to the
   run's wall-clock and the strategy's own time (the clustering after an evaluation) is charged
   to the call it follows.
3. ``fit_model``: seconds = train_call_s x train calls + evaluate_call_s x evaluate calls +
   copy_call_s x copies + step_s x training steps + eval_episode_s x evaluation episodes, by
   non-negative least squares over the segments. A Train goal's evaluation episodes are those of
   the checks it ran (the learner's EvaluationResults with purpose "train" for its output policy);
   an evaluate call's are tasks x S-bar. Per-call seconds stand for what a call costs whatever its
   size: the goal's start, loading and storing policies, the clustering.
4. ``simulate``: the strategy of a run config, driven by ``RecordedLearner`` (a double that answers
   from a recorded run and says how many seconds each answer took, by the model) on a virtual
   clock: every call goes through ``Run``'s own scheduler to K learners (one for a sequential run),
   and ``VirtualCalls`` (its ``CallRunner``) ends each one its seconds after it started, earliest
   first. Nothing sleeps. The strategy's time
   between calls counts as nothing here (it is inside the calls' segments in 2.).
   The double's rules, for calls the recorded run made and for those it did not:
   - a Train goal on task T: the n-th goal on T gets the recorded run's n-th goal on T (the last
     one when it made fewer); a task it never trained is not learned and spends the goal's whole
     budget, with a check every ``eval_interval`` steps. A goal clipped below the recorded steps is
     not learned and spends the clipped budget, its checks cut in proportion. Goals of sampled
     episodes (baselines) get the recorded ones in order.
   - an evaluation: each task's score in the recorded evaluation nearest in order to this one that
     scored the task (the same one when it did; the earlier on a tie); 0 when none did.
   A run replayed with the recorded run's own settings and K then makes exactly its calls.
5. ``schedule``: runs (their seconds each) on a number of slots, longest first to the slot free
   first: the wall-clock of a grid of runs.
"""

from __future__ import annotations

import heapq
import itertools
import json
import shutil
import tempfile
from collections import defaultdict
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any, Sequence

import numpy as np

from glocal_ros.analysis.runs import _messages, find_bags
from glocal_ros.curriculum.journal import CallJournal, train_result
from glocal_ros.curriculum.learner import TrainGoal, TrainResult
from glocal_ros.curriculum.run import Run, RunConfig, RunState
from glocal_ros.curriculum.strategies import run_strategy
from glocal_ros.topics import CURRICULUM_STATE, EVALUATIONS

#: Where a run directory keeps its journal.
JOURNAL_FILE = Path("curriculum") / "journal.jsonl"
#: The model's terms, in the order of ``CallModel``'s fields.
TERMS = ("train_call_s", "evaluate_call_s", "copy_call_s", "step_s", "eval_episode_s")


# 1. A recorded run.
@dataclass(frozen=True)
class RecordedRun:
    run_dir: Path
    config: RunConfig
    settings: dict  # the journal's first line, as written
    entries: list[dict]  # the answered calls, in the order they came
    pairs: int  # learners that answered: 1 for a sequential journal
    state_stamps_ns: list[int]  # every CurriculumState's header stamp, in order
    goal_eval_episodes: dict[str, int]  # a Train goal's output policy -> episodes of its checks

    @property
    def wall_seconds(self) -> float:
        return (self.state_stamps_ns[-1] - self.state_stamps_ns[0]) / 1e9


def read_recorded_run(run_dir: Path) -> RecordedRun:
    """The journal and bag of ``run_dir``; ``ValueError`` saying what is missing."""
    run_dir = Path(run_dir)
    if not run_dir.is_dir():
        raise ValueError(f"{run_dir}: not a directory")
    journal = run_dir / JOURNAL_FILE
    if not journal.is_file():
        raise ValueError(f"{run_dir}: no {JOURNAL_FILE} (the curriculum's journal): not a run directory, or a "
                         "kept run (bench curriculum keeps no journal)")
    lines = [json.loads(line) for line in journal.read_text().splitlines() if line.strip()]
    if not lines or "config" not in lines[0]:
        raise ValueError(f"{journal}: no settings line")
    settings, entries = lines[0]["config"], lines[1:]
    if not entries:
        raise ValueError(f"{journal}: no answered call")
    config = RunConfig(**{**settings, "tasks": tuple(settings["tasks"])})
    bags = find_bags(run_dir)
    if not bags:
        raise ValueError(f"{run_dir}: no bag/ (the run's recording)")
    if len(bags) > 1:
        raise ValueError(f"{run_dir}: {len(bags)} bags, a resumed run: its calls span the kill; time an "
                         "uninterrupted run")
    if not (bags[0] / "metadata.yaml").is_file():
        raise ValueError(f"{bags[0]}: no metadata.yaml (recorder killed?): `glocal-ros bag repair {bags[0]}`")
    stamps: list[int] = []
    goal_episodes: dict[str, int] = defaultdict(int)
    for topic, _, message in _messages(bags[0], [CURRICULUM_STATE, EVALUATIONS], {}):
        if topic == CURRICULUM_STATE.name:
            stamps.append(int(message.header.stamp.sec) * 1_000_000_000 + int(message.header.stamp.nanosec))
        elif message.purpose == "train":
            goal_episodes[message.policy] += sum(int(score.episodes) for score in message.scores)
    if len(stamps) < 2:
        raise ValueError(f"{bags[0]}: {len(stamps)} curriculum state(s): no run to time")
    pairs = 1 + max((entry.get("learner", 0) for entry in entries), default=0)
    return RecordedRun(run_dir, config, settings, entries, pairs, stamps, dict(goal_episodes))


# 2. The time of each call.
@dataclass(frozen=True)
class CallCost:
    """What a call does, in the model's terms."""

    call: str  # "train", "evaluate" or "copy"
    training_steps: int = 0
    evaluation_episodes: int = 0


@dataclass(frozen=True)
class Segment:
    """A stretch of the run between two cuts, and the calls answered in it."""

    seconds: float
    costs: tuple[CallCost, ...]


def entry_cost(entry: dict, goal_eval_episodes: dict[str, int]) -> CallCost:
    """A journaled call's cost: steps and checks of a Train goal, tasks x S-bar of an evaluation."""
    arguments, answer = entry["arguments"], entry["answer"]
    if entry["call"] == "train":
        return CallCost("train", int(answer["steps_used"]), goal_eval_episodes.get(arguments["output_policy"], 0))
    if entry["call"] == "evaluate":
        return CallCost("evaluate", 0, int(arguments["episodes"]) * len(arguments["tasks"]))
    return CallCost("copy")


class _Counting:
    """A ``RunObserver`` that counts the states the run publishes."""

    def __init__(self) -> None:
        self.states = 0

    def state_changed(self, state: RunState) -> None:
        self.states += 1

    def assigned(self, assignment) -> None:
        pass


class _JournalSpent(RuntimeError):
    pass


class _NoLearner:
    def evaluate(self, *args, **kwargs):
        raise _JournalSpent()

    train = copy = evaluate


class _MarkingJournal(CallJournal):
    """A recorded run's journal that notes, for each answer, the states published before it was taken."""

    def __init__(self, path: Path, settings: dict, counting: _Counting):
        super().__init__(path, settings)
        self.counting = counting
        self.answered_before: list[int] = []

    def next_entry(self) -> dict:
        self.answered_before.append(self.counting.states)
        return super().next_entry()


def time_calls(run: RecordedRun, max_episode_steps: int) -> list[Segment]:
    """The segments of a sequential run (see the module doc, 2.), adding up to its wall-clock."""
    if run.config.parallel_locals:
        raise ValueError(f"{run.run_dir}: a run with parallel_locals; its calls overlap, so time a sequential "
                         "run (K = 1) and --validate this one")
    counting = _Counting()
    with tempfile.TemporaryDirectory() as scratch:
        copy = Path(scratch) / "journal.jsonl"
        shutil.copyfile(run.run_dir / JOURNAL_FILE, copy)
        journal = _MarkingJournal(copy, run.settings, counting)
        try:
            run_strategy(Run(run.config, _NoLearner(), counting, journal=journal), max_episode_steps)
        except _JournalSpent:
            raise ValueError(f"{run.run_dir}: the journal ends before the run does (an interrupted run?)") from None
    answered_before = journal.answered_before
    if len(answered_before) != len(run.entries) or counting.states != len(run.state_stamps_ns):
        raise ValueError(f"{run.run_dir}: its journal replays {len(answered_before)} calls and {counting.states} "
                         f"states, its bag holds {len(run.entries)} calls and {len(run.state_stamps_ns)} states: "
                         "not the run this code makes (another max_episode_steps, or another version?)")
    stamps = run.state_stamps_ns
    calls_at_cut: dict[int, list[CallCost]] = defaultdict(list)
    for entry, states in zip(run.entries, answered_before):
        calls_at_cut[min(states, len(stamps) - 1)].append(entry_cost(entry, run.goal_eval_episodes))
    segments, previous = [], 0
    for cut in sorted(calls_at_cut):
        end = len(stamps) - 1 if cut == max(calls_at_cut) else cut  # the run's last states go to its last call
        segments.append(Segment((stamps[end] - stamps[previous]) / 1e9, tuple(calls_at_cut[cut])))
        previous = end
    return segments


# 3. The model.
@dataclass(frozen=True)
class CallModel:
    train_call_s: float
    evaluate_call_s: float
    copy_call_s: float
    step_s: float  # per training env step
    eval_episode_s: float  # per evaluation episode

    def seconds(self, cost: CallCost) -> float:
        per_call = {"train": self.train_call_s, "evaluate": self.evaluate_call_s, "copy": self.copy_call_s}
        return per_call[cost.call] + self.step_s * cost.training_steps + self.eval_episode_s * cost.evaluation_episodes


def _features(costs: Sequence[CallCost]) -> list[float]:
    return [sum(c.call == "train" for c in costs), sum(c.call == "evaluate" for c in costs),
            sum(c.call == "copy" for c in costs), sum(c.training_steps for c in costs),
            sum(c.evaluation_episodes for c in costs)]


def fit_model(segments: Sequence[Segment]) -> CallModel:
    """Non-negative least squares of the segments' seconds on their calls' terms (a term no call has: 0)."""
    from scipy.optimize import nnls

    if not segments:
        raise ValueError("no timed call to fit")
    features = np.array([_features(s.costs) for s in segments], dtype=float)
    seconds = np.array([s.seconds for s in segments])
    used = features.any(axis=0)
    scale = np.where(used, features.max(axis=0), 1.0)  # steps and episodes are thousands, calls ones
    coefficients = np.zeros(len(TERMS))
    coefficients[used] = nnls(features[:, used] / scale[used], seconds)[0] / scale[used]
    return CallModel(*map(float, coefficients))


def predicted_segments(model: CallModel, segments: Sequence[Segment]) -> list[float]:
    return [sum(model.seconds(c) for c in s.costs) for s in segments]


# 4. The simulation.
class RecordedLearner:
    """A ``Learner`` that answers as a recorded run did (rules: module doc, 4.) and sets ``last_seconds``,
    what its last answer took by ``model``. Policies are names only: every learner shares the store."""

    def __init__(self, run: RecordedRun, model: CallModel):
        self.model = model
        self.goals: dict[str, list[tuple[dict, int]]] = defaultdict(list)  # task ("": sampled) -> answers
        self.evaluations: list[dict[str, float]] = []
        for entry in run.entries:
            if entry["call"] == "train":
                checks = run.goal_eval_episodes.get(entry["arguments"]["output_policy"], 0)
                self.goals[entry["arguments"]["task"]].append((entry["answer"], checks))
            elif entry["call"] == "evaluate":
                self.evaluations.append(entry["answer"])
        self.trained: dict[str, int] = defaultdict(int)
        self.evaluated = 0
        self.last_seconds = 0.0

    def train(self, request: TrainGoal) -> TrainResult:
        recorded = self.goals.get(request.task, [])
        turn = self.trained[request.task]
        self.trained[request.task] += 1
        episodes_per_check = request.eval_episodes or 0
        if recorded:
            answer, checks = recorded[min(turn, len(recorded) - 1)]
            result = train_result(answer)
            if result.steps_used > request.step_budget:  # clipped: it stops short of what it needed
                checks = max(episodes_per_check, checks * request.step_budget // result.steps_used)
                result = TrainResult(False, result.score, request.step_budget, result.episodes)
        else:
            result = TrainResult(False, 0.0, request.step_budget)
            checks = episodes_per_check * (1 + request.step_budget // max(1, request.eval_interval or
                                                                           request.step_budget))
        self.last_seconds = self.model.seconds(CallCost("train", result.steps_used, checks if request.task else 0))
        return result

    def evaluate(self, policy: str, tasks: Sequence[str], episodes: int, seed: int | None = None) -> dict[str, float]:
        turn = self.evaluated
        self.evaluated += 1
        scores = {}
        for task in tasks:
            held = [i for i, recorded in enumerate(self.evaluations) if task in recorded]
            nearest = min(held, key=lambda i: (abs(i - turn), i), default=None)
            scores[task] = 0.0 if nearest is None else float(self.evaluations[nearest][task])
        self.last_seconds = self.model.seconds(CallCost("evaluate", 0, episodes * len(tasks)))
        return scores

    def copy(self, source: str, destination: str) -> None:
        self.last_seconds = self.model.seconds(CallCost("copy"))


@dataclass
class VirtualClock:
    now: float = 0.0


class VirtualCalls:
    """``Run``'s ``CallRunner`` on a virtual clock: a call is answered when it starts and ends its
    ``last_seconds`` later; ``next_done`` moves the clock to the earliest end (the first started on a tie)."""

    def __init__(self, clock: VirtualClock):
        self.clock = clock
        self._ends: list[tuple[float, int, int, str, Any]] = []
        self._order = itertools.count()

    def start(self, slot: int, learner: RecordedLearner, key: str, ask) -> None:
        try:
            answer = ask(learner)
        except Exception as error:  # noqa: BLE001 - handed to the run, as ThreadedCalls does
            answer = error
        heapq.heappush(self._ends, (self.clock.now + learner.last_seconds, next(self._order), slot, key, answer))

    def next_done(self) -> tuple[int, str, Any]:
        end, _, slot, key, answer = heapq.heappop(self._ends)
        self.clock.now = end
        return slot, key, answer


@dataclass(frozen=True)
class Prediction:
    pairs: int
    seconds: float
    learned: int
    total_steps: int
    evaluation_episodes: int


def simulate(config: RunConfig, answers: RecordedRun, model: CallModel, pairs: int,
             max_episode_steps: int) -> Prediction:
    """The wall-clock of a run of ``config`` with ``pairs`` learners, answered as ``answers`` was."""
    if pairs < 1:
        raise ValueError(f"pairs must be at least 1, got {pairs}")
    clock, double = VirtualClock(), RecordedLearner(answers, model)
    run = Run(config, double, learners=[double] * pairs, calls=VirtualCalls(clock))
    run_strategy(run, max_episode_steps)
    return Prediction(pairs, clock.now, len(run.state.learned_tasks), run.state.total_steps,
                      run.state.evaluation_episodes)


def with_pairs(config: RunConfig, pairs: int) -> RunConfig:
    """``config`` run on ``pairs`` learners: sequential with one, parallel locals with more."""
    return replace(config, parallel_locals=pairs > 1)


# 5. Grids of runs.
def schedule(run_seconds: Sequence[float], slots: int) -> float:
    """Wall-clock of runs on ``slots`` at a time: the longest first, each to the slot that is free first."""
    if slots < 1:
        raise ValueError(f"slots must be at least 1, got {slots}")
    free = [0.0] * slots
    for seconds in sorted(run_seconds, reverse=True):
        heapq.heappush(free, heapq.heappop(free) + seconds)
    return max(free)


__all__ = ["CallCost", "CallModel", "Prediction", "RecordedLearner", "RecordedRun", "Segment", "VirtualCalls",
           "fit_model", "read_recorded_run", "schedule", "simulate", "time_calls", "with_pairs"]

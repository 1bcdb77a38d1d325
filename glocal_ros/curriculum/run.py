"""A curriculum run's settings and bookkeeping, shared by every strategy.

``Run`` wraps the learner: it charges every training step to one total
budget, clips each goal to what is left, keeps the learned tasks with the
policy that learned each and the step count when it did, records the
learned count at every milestone, and tells an observer (the node, which
publishes) about each assignment and state change.

Choices:
- Evaluation episodes are not charged to the budget: the paper compares
  strategies at equal training timesteps. The run counts them
  (``RunState.evaluation_episodes``) so that a comparison can show them.
- The learner steps N envs in lockstep and never trains past a goal's
  budget, so it may stop up to N - 1 steps short. When a goal given all the
  steps the run has left trains none of them (and its task did not pass),
  those few steps cannot be spent: the budget counts as spent.
- A finished run's learned count is final, so ``finish`` records it at
  every milestone up to the budget: a run that learned everything early
  stands in the milestone table beside those that used the whole budget.

Every learner call goes through one scheduler, whose calls are outstanding
until answered. ``start_train``, ``start_evaluate`` and ``start_copy``
queue a call under a key that names it (e.g. ``m3/local/B1``; a call the
strategy does not name is ``call<n>``, n its place in the run); ``train``,
``evaluate`` and ``copy`` queue one and wait for its answer, and a
sequential strategy calls only those, so that it is the K = 1 case: one
call outstanding at a time. The queue goes first in, first out to the free
learners (lowest index first); ``wait_for``, ``wait_any`` and ``wait_all``
take answers in the order they come and hand each to its call's
``when_done`` in the strategy's thread, so every decision is made between
two answers. A ``CallJournal`` records each answer with its key and the
learner that gave it, in the order they came; a resumed run takes its
answers from it in that order (queuing nothing on the learners until the
journal is spent), then sends the calls still outstanding, the ones in
flight at the kill among them, in any order.

Seeds: a call's episodes and SAC's sampling are a function of the run seed
and the call, not of what the learner did before (limits:
``Trainer._seeded``). A run without ``parallel_locals`` asks its calls in
one order, which its strategy fixes: the n-th call (0-based, copies
counted) gets ``derived_seed(seed, n)``, as sequential runs always have,
so their journals resume. With ``parallel_locals`` the order of the calls
depends on which learner answers first, so a call's seed comes from the
run seed and its key. A journal line without a key was written by a
sequential run before calls had keys: it answers the one call outstanding.

A call whose learner went away (``resend_on``: a killed pair that did not
come back in time) goes back to the front of the queue, to the next free
learner (a Train goal resumes from its checkpoint in the shared policy
store), up to ``MAX_SENDS`` sends in all. The learner that failed it gets no
call until it is ready again: a ``ReturningLearner`` is watched
(``wait_until_ready``, in its slot, so that the slot is taken meanwhile);
a watch that ends without the learner back starts again while another
learner is up, and ends the run when every learner is away.
The budget counts the steps reserved by goals in flight: a new goal is
clipped to what is left after them, and a goal hands back what it did not use
when it ends.
"""

from __future__ import annotations

import math
import queue
import threading
from collections import deque
from dataclasses import asdict, dataclass, field, replace
from typing import Any, Callable, Protocol, Sequence

from glocal_ros.clustering import Clustering
from glocal_ros.curriculum.codes import (
    ROLE_CLUSTER, ROLE_GLOBAL, ROLE_LOCAL, ROLE_SAMPLED, STATUS_EVALUATING, STATUS_FINISHED, STATUS_STARTING,
    STATUS_TRAINING, STATUS_TRAINING_GLOBAL, STATUS_TRAINING_LOCAL, BASELINE_TASKS,
)
from glocal_ros.curriculum.journal import CallJournal, JournalMismatch, plain, train_result
from glocal_ros.curriculum.learner import (PAPER_EVAL_EPISODES, Learner, ReturningLearner, TrainGoal,
                                           TrainResult, paper_threshold)
from glocal_ros.seeds import derived_seed
from glocal_ros.tasks import sorted_tasks, validate_tasks

#: Most times an outstanding call is sent to a learner before its failure ends the run.
MAX_SENDS = 3
#: The key a slot's watch runs under (never a call's: call keys have no spaces).
_WATCH_KEY = "watch learner {slot}"

_STATUS_OF_ROLE = {ROLE_GLOBAL: STATUS_TRAINING_GLOBAL, ROLE_LOCAL: STATUS_TRAINING_LOCAL,
                   ROLE_SAMPLED: STATUS_TRAINING, ROLE_CLUSTER: STATUS_TRAINING}


@dataclass(frozen=True)
class RunConfig:
    """Settings of a run; the paper's values are the defaults where it gives them."""

    strategy: str
    tasks: tuple[str, ...]
    initial_policy: str = "prior"  # pi_init, trained on A0
    seed: int = 0
    step_budget: int = 4_000_000  # training env steps, all tasks (the paper compares at 4M)
    task_step_budget: int = 200_000  # the paper's "maximum amount of training time" per task
    eval_episodes: int = PAPER_EVAL_EPISODES  # S-bar
    threshold: float = paper_threshold()  # B
    eval_interval: int = 10_000  # env steps between checks of "score > B" while a task trains
    k_min: int = 2
    k_max: int = 6
    max_iter: int = 1_000
    milestone_interval: int = 1_000_000
    baseline_eval_interval: int = 100_000  # baselines: env steps between evaluations on every unlearned task
    baseline_chunk_episodes: int = 100  # random: episodes sampled per Train goal
    baseline_tasks: str = "all"  # baselines draw from "all" tasks or the "unlearned" ones (see ``baselines``)
    parallel_locals: bool = False  # GloCAL: local tasks on free learners at once (``glocal``); baselines ignore it

    def __post_init__(self) -> None:
        if not self.tasks:
            raise ValueError("a run needs at least one task")
        validate_tasks(self.tasks)
        if len(set(self.tasks)) != len(self.tasks):
            raise ValueError(f"tasks repeat: {list(self.tasks)}")
        for name in ("step_budget", "task_step_budget", "eval_episodes", "max_iter", "milestone_interval",
                     "baseline_eval_interval", "baseline_chunk_episodes"):
            if getattr(self, name) < 1:
                raise ValueError(f"{name} must be at least 1, got {getattr(self, name)}")
        if not 0 <= self.threshold < self.eval_episodes:
            raise ValueError(f"threshold {self.threshold} must lie in [0, eval_episodes={self.eval_episodes})")
        if self.baseline_tasks not in BASELINE_TASKS:
            raise ValueError(f"baseline_tasks {self.baseline_tasks!r}: expected one of {', '.join(BASELINE_TASKS)}")
        if not 2 <= self.k_min <= self.k_max:
            raise ValueError(f"need 2 <= k_min <= k_max, got {self.k_min}, {self.k_max}")

    @property
    def run_id(self) -> str:
        return f"{self.strategy}-seed{self.seed}"

    def policy_name(self, suffix: str) -> str:
        """Policies of a run carry its id, so runs can share a policy store."""
        return f"{self.run_id}.{suffix}"

    def journal_settings(self) -> dict[str, Any]:
        """The settings a journal's first line holds: ``parallel_locals`` only when set, so that sequential
        runs write (and resume) the journals they wrote before it existed."""
        settings = asdict(self)
        if not self.parallel_locals:
            del settings["parallel_locals"]
        return settings


@dataclass(frozen=True)
class Assignment:
    seq: int
    iteration: int
    role: int  # ROLE_*
    task: str
    episode_tasks: tuple[str, ...]
    initial_policy: str
    output_policy: str
    step_budget: int


@dataclass
class RunState:
    """What glocal_interfaces/msg/CurriculumState carries."""

    run_id: str
    seed: int
    strategy: str
    step_budget: int
    milestone_interval: int
    remaining_tasks: list[str]
    current_policy: str
    status: int = STATUS_STARTING
    iteration: int = 0
    total_steps: int = 0
    evaluation_episodes: int = 0
    silhouette: float = math.nan
    clusters: list[tuple[tuple[str, ...], tuple[float, ...]]] = field(default_factory=list)
    chosen_cluster: int = 0
    global_task: str = ""
    local_tasks: list[str] = field(default_factory=list)
    current_task: str = ""
    learned_tasks: list[str] = field(default_factory=list)
    learned_policies: list[str] = field(default_factory=list)
    learned_at_steps: list[int] = field(default_factory=list)
    milestone_steps: list[int] = field(default_factory=list)
    milestone_learned: list[int] = field(default_factory=list)


class RunObserver(Protocol):
    def state_changed(self, state: RunState) -> None: ...

    def assigned(self, assignment: Assignment) -> None: ...


class _NoObserver:
    def state_changed(self, state: RunState) -> None:
        pass

    def assigned(self, assignment: Assignment) -> None:
        pass


class CallRunner(Protocol):
    """Where outstanding calls run: ``start`` one on a learner, ``next_done`` waits for any to end."""

    def start(self, slot: int, learner: Learner, key: str, ask: Callable[[Learner], Any]) -> None: ...

    def next_done(self) -> tuple[int, str, Any]:
        """(slot, key, answer or the exception the call raised) of the next call to end."""


class ThreadedCalls:
    """Each call in a thread of its own (learners block until they answer); answers in the order they end."""

    def __init__(self) -> None:
        self._done: queue.Queue[tuple[int, str, Any]] = queue.Queue()

    def start(self, slot: int, learner: Learner, key: str, ask: Callable[[Learner], Any]) -> None:
        def work() -> None:
            try:
                outcome = ask(learner)
            except Exception as error:  # noqa: BLE001 - handed to the run, which decides
                outcome = error
            self._done.put((slot, key, outcome))

        threading.Thread(target=work, name=f"learner{slot}:{key}", daemon=True).start()

    def next_done(self) -> tuple[int, str, Any]:
        return self._done.get()


@dataclass
class _Call:
    key: str
    name: str  # "train", "evaluate" or "copy"
    task: str  # the task a train call decides; ""
    arguments: dict  # as journaled
    ask: Callable[[Learner], Any]
    load: Callable[[Any], Any]  # a journaled answer as the learner gives it
    cost: Callable[[Any], dict[str, int]]
    done: Callable[[Any], None]
    reserved_steps: int = 0


class Run:
    def __init__(self, config: RunConfig, learner: Learner, observer: RunObserver | None = None, *,
                 learners: Sequence[Learner] = (), journal: CallJournal | None = None,
                 calls: CallRunner | None = None, resend_on: tuple[type[BaseException], ...] = ()):
        """``learners`` (default: ``learner`` alone) answer the calls, run by ``calls`` (default: a thread
        each) and journaled in ``journal`` (default: none). A call that raises one of ``resend_on`` (its
        learner went away and did not come back in time) goes back to the front of the queue, for the next
        free learner, up to ``MAX_SENDS`` times in all; any other exception ends the run (which resumes
        from its journal)."""
        self.config = config
        self.learners = list(learners) or [learner]
        self.journal = journal
        self.calls = calls or ThreadedCalls()
        self._outstanding: dict[str, _Call] = {}  # by key: queued or running, not answered
        self._queued: deque[str] = deque()
        self._running: dict[int, str] = {}  # learner slot -> key (a call's, or its watch's)
        self._watched: set[int] = set()  # slots whose learner failed a call and is not back yet
        self.resend_on = resend_on
        self._sends: dict[str, int] = {}  # key -> times sent to a learner
        self.observer = observer or _NoObserver()
        self.state = RunState(run_id=config.run_id, seed=config.seed, strategy=config.strategy,
                              step_budget=config.step_budget, milestone_interval=config.milestone_interval,
                              remaining_tasks=sorted_tasks(config.tasks), current_policy=config.initial_policy)
        self._assignments = 0
        self._calls = 0  # calls queued so far: the next one's place in the run
        self._stranded_steps = 0  # the budget's last steps, fewer than the learner's lockstep batch

    # What strategies ask.
    @property
    def steps_left(self) -> int:
        """The budget less the steps trained, stranded, and reserved by goals in flight."""
        reserved = sum(call.reserved_steps for call in self._outstanding.values())
        return max(0, self.config.step_budget - self.state.total_steps - self._stranded_steps - reserved)

    @property
    def over(self) -> bool:
        """Every task learned, or the budget spent and no goal in flight to hand any back."""
        return not self.state.remaining_tasks or (self.steps_left == 0 and not self._outstanding)

    @property
    def tasks_in_flight(self) -> set[str]:
        return {call.task for call in self._outstanding.values() if call.task}

    @property
    def in_flight(self) -> int:
        return len(self._outstanding)

    def is_learned(self, task: str) -> bool:
        return task in self.state.learned_tasks

    # Calls that wait for their answer: a sequential strategy asks only these.
    def evaluate(self, policy: str, tasks: list[str], key: str = "") -> dict[str, float]:
        """The scores of ``policy`` on ``tasks`` (S-bar episodes each)."""
        scores: dict[str, float] = {}
        self.wait_for(self.start_evaluate(policy, tasks, key, scores.update))
        return scores

    def train(self, role: int, request: TrainGoal, key: str = "") -> TrainResult:
        """Run one goal, its budget clipped to what the run has left, judged by the run's B and S-bar."""
        results: list[TrainResult] = []
        self.wait_for(self.start_train(role, request, key, results.append))
        return results[0]

    def copy(self, source: str, destination: str, key: str = "") -> None:
        """Store a copy of policy ``source`` as ``destination``."""
        self.wait_for(self.start_copy(source, destination, key))

    # Outstanding calls (see the module doc): each returns its key.
    def start_evaluate(self, policy: str, tasks: list[str], key: str,
                       when_done: Callable[[dict[str, float]], None]) -> str:
        key, seed = self._key_and_seed(key)
        episodes = self.config.eval_episodes
        self._update(status=STATUS_EVALUATING, current_task="")

        def done(scores: dict[str, float]) -> None:
            self.state.evaluation_episodes += episodes * len(tasks)
            when_done(scores)

        self._queue(_Call(key, "evaluate", "", plain({"policy": policy, "tasks": list(tasks), "episodes": episodes,
                                                       "seed": seed}),
                          lambda learner: learner.evaluate(policy, list(tasks), episodes, seed), lambda a: a,
                          lambda answer: {"evaluation_episodes": episodes * len(answer)}, done))
        return key

    def start_train(self, role: int, request: TrainGoal, key: str,
                    when_done: Callable[[TrainResult], None]) -> str:
        """Queue one goal, clipped to the steps left after those in flight (at least 1 must be left)."""
        steps_left = self.steps_left
        if steps_left < 1:
            raise ValueError(f"no steps left for {key or 'a goal'}")
        key, seed = self._key_and_seed(key)
        request = replace(request, step_budget=min(request.step_budget, steps_left),
                          threshold=self.config.threshold, eval_episodes=self.config.eval_episodes, seed=seed)
        self.observer.assigned(Assignment(self._assignments, self.state.iteration, role, request.task,
                                          request.episode_tasks, request.initial_policy, request.output_policy,
                                          request.step_budget))
        self._assignments += 1

        def done(result: TrainResult) -> None:
            self.state.total_steps += result.steps_used
            if request.step_budget == steps_left and result.steps_used == 0 and not result.learned:
                self._stranded_steps += request.step_budget
            # A milestone the goal ended on exactly waits: the strategy may mark a task learned at it.
            self._record_milestones(through=self.state.total_steps - 1)
            self._update()
            when_done(result)

        self._queue(_Call(key, "train", request.task, plain(request), lambda learner: learner.train(request),
                          train_result, lambda answer: {"training_steps": answer.steps_used}, done,
                          reserved_steps=request.step_budget))
        self._update(status=_STATUS_OF_ROLE[role], current_task=request.task)
        return key

    def start_copy(self, source: str, destination: str, key: str,
                   when_done: Callable[[None], None] = lambda answer: None) -> str:
        key, _ = self._key_and_seed(key)
        self._queue(_Call(key, "copy", "", {"source": source, "destination": destination},
                          lambda learner: learner.copy(source, destination), lambda answer: None,
                          lambda answer: {}, when_done))
        return key

    def wait_for(self, key: str) -> None:
        while key in self._outstanding:
            self._take_answer()

    def wait_any(self) -> None:
        self._take_answer()

    def wait_all(self) -> None:
        while self._outstanding:
            self._take_answer()

    def _key_and_seed(self, key: str) -> tuple[str, int]:
        """The next call's key (``call<n>`` when the strategy names none) and seed (see the module doc)."""
        index = self._calls
        self._calls += 1
        key = key or f"call{index}"
        if self.config.parallel_locals:
            return key, derived_seed(self.config.seed, *key.encode())
        return key, derived_seed(self.config.seed, index)

    def _queue(self, call: _Call) -> None:
        if call.key in self._outstanding:
            raise ValueError(f"call {call.key} is outstanding already")
        self._outstanding[call.key] = call
        self._queued.append(call.key)
        self._dispatch()

    def _dispatch(self) -> None:
        """Queued calls to free learners, first in first out; none while answers come from the journal."""
        if self.journal is not None and self.journal.replaying:
            return
        free = [slot for slot in range(len(self.learners)) if slot not in self._running]
        while self._queued and free:
            slot, key = free.pop(0), self._queued.popleft()
            self._running[slot] = key
            self._sends[key] = self._sends.get(key, 0) + 1
            self.calls.start(slot, self.learners[slot], key, self._outstanding[key].ask)

    def _take_answer(self) -> None:
        """The next answer, from the journal while it lasts, else from the learners; handed to its call."""
        if not self._outstanding:
            raise RuntimeError("no call is outstanding")
        if self.journal is not None and self.journal.replaying:
            entry = self.journal.next_entry()
            key = entry.get("key") or self._only_outstanding()  # written before sequential calls had keys
            call = self._outstanding.get(key)
            if call is None or (call.name, call.arguments) != (entry["call"], entry["arguments"]):
                raise JournalMismatch(f"{self.journal.path}, entry {self.journal.replayed}: journaled {key} "
                                      f"{entry['call']} {entry['arguments']}, but the run has no such call "
                                      "outstanding (a run of other code?)")
            self._queued.remove(call.key)
            answer = call.load(entry["answer"])
        else:
            self._dispatch()
            slot, key, answer = self.calls.next_done()
            del self._running[slot]
            if slot in self._watched:
                self._watch_ended(slot, answer)
                return
            if isinstance(answer, self.resend_on) and self._sends[key] < MAX_SENDS:
                self._queued.appendleft(key)  # a Train goal sent again resumes from its checkpoint
                self._watch(slot)
                self._dispatch()
                return
            if isinstance(answer, BaseException):
                raise answer
            call = self._outstanding[key]
            if self.journal is not None:
                self.journal.record(key, slot, call.name, call.arguments, answer, call.cost(answer))
        del self._outstanding[call.key]
        call.done(answer)
        self._dispatch()

    def _only_outstanding(self) -> str:
        if len(self._outstanding) != 1:
            raise JournalMismatch(f"{self.journal.path}: a line without a key (a sequential run's) while "
                                  f"{len(self._outstanding)} calls are outstanding")
        return next(iter(self._outstanding))

    def _watch(self, slot: int) -> None:
        """Take ``slot`` until its learner is ready again (see the module doc)."""
        learner = self.learners[slot]
        if not isinstance(learner, ReturningLearner):
            return
        self._watched.add(slot)
        self._running[slot] = _WATCH_KEY.format(slot=slot)
        self.calls.start(slot, learner, self._running[slot], lambda learner: learner.wait_until_ready())

    def _watch_ended(self, slot: int, outcome: Any) -> None:
        """The slot is free when its learner is back; watched again while another is up; else the run ends."""
        self._watched.discard(slot)
        if isinstance(outcome, BaseException):
            if len(self._watched) + 1 == len(self.learners):
                raise outcome
            self._watch(slot)
        self._dispatch()

    def mark_learned(self, task: str, policy: str) -> None:
        if self.is_learned(task):
            return
        self.state.learned_tasks.append(task)
        self.state.learned_policies.append(policy)
        self.state.learned_at_steps.append(self.state.total_steps)
        self.state.remaining_tasks.remove(task)
        self._update()

    def show_clustering(self, clustering: Clustering, chosen: int, global_task: str, local_tasks: list[str]) -> None:
        self._update(silhouette=clustering.silhouette,
                     clusters=[(c.tasks, c.scores) for c in clustering.clusters], chosen_cluster=chosen,
                     global_task=global_task, local_tasks=list(local_tasks))

    def begin_iteration(self, iteration: int) -> None:
        self._update(iteration=iteration, clusters=[], global_task="", local_tasks=[], silhouette=math.nan)

    def set_current_policy(self, policy: str) -> None:
        self._update(current_policy=policy)

    def finish(self) -> None:
        self._record_milestones(through=self.config.step_budget)
        self._update(status=STATUS_FINISHED, current_task="")

    def _record_milestones(self, through: int) -> None:
        """Learned counts at every milestone up to ``through`` steps: tasks learned at or before it."""
        interval = self.config.milestone_interval
        while (len(self.state.milestone_steps) + 1) * interval <= through:
            milestone = (len(self.state.milestone_steps) + 1) * interval
            self.state.milestone_steps.append(milestone)
            self.state.milestone_learned.append(sum(1 for s in self.state.learned_at_steps if s <= milestone))

    def _update(self, **changes) -> None:
        for key, value in changes.items():
            setattr(self.state, key, value)
        self.observer.state_changed(self.state)

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
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import Protocol

from glocal_ros.clustering import Clustering
from glocal_ros.curriculum.codes import (
    ROLE_CLUSTER, ROLE_GLOBAL, ROLE_LOCAL, ROLE_SAMPLED, STATUS_EVALUATING, STATUS_FINISHED, STATUS_STARTING,
    STATUS_TRAINING, STATUS_TRAINING_GLOBAL, STATUS_TRAINING_LOCAL, BASELINE_TASKS,
)
from glocal_ros.curriculum.learner import (PAPER_EVAL_EPISODES, Learner, TrainRequest, TrainResult,
                                           paper_threshold)
from glocal_ros.tasks import sorted_tasks, validate_tasks

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


class Run:
    def __init__(self, config: RunConfig, learner: Learner, observer: RunObserver | None = None):
        self.config = config
        self.learner = learner
        self.observer = observer or _NoObserver()
        self.state = RunState(run_id=config.run_id, seed=config.seed, strategy=config.strategy,
                              step_budget=config.step_budget, milestone_interval=config.milestone_interval,
                              remaining_tasks=sorted_tasks(config.tasks), current_policy=config.initial_policy)
        self._assignments = 0
        self._stranded_steps = 0  # the budget's last steps, fewer than the learner's lockstep batch

    # What strategies ask.
    @property
    def steps_left(self) -> int:
        return max(0, self.config.step_budget - self.state.total_steps - self._stranded_steps)

    @property
    def over(self) -> bool:
        """Every task learned, or the budget spent."""
        return not self.state.remaining_tasks or self.steps_left == 0

    def is_learned(self, task: str) -> bool:
        return task in self.state.learned_tasks

    def evaluate(self, policy: str, tasks: list[str]) -> dict[str, float]:
        self._update(status=STATUS_EVALUATING, current_task="")
        scores = self.learner.evaluate(policy, tasks, self.config.eval_episodes)
        self.state.evaluation_episodes += self.config.eval_episodes * len(tasks)
        return scores

    def train(self, role: int, request: TrainRequest) -> TrainResult:
        """Run one goal, its budget clipped to what the run has left, judged by the run's B and S-bar."""
        steps_left = self.steps_left
        request = replace(request, step_budget=min(request.step_budget, steps_left),
                          threshold=self.config.threshold, eval_episodes=self.config.eval_episodes)
        self.observer.assigned(Assignment(self._assignments, self.state.iteration, role, request.task,
                                          request.episode_tasks, request.initial_policy, request.output_policy,
                                          request.step_budget))
        self._assignments += 1
        self._update(status=_STATUS_OF_ROLE[role], current_task=request.task)
        result = self.learner.train(request)
        self.state.total_steps += result.steps_used
        if request.step_budget == steps_left and result.steps_used == 0 and not result.learned:
            self._stranded_steps = steps_left
        # A milestone the goal ended on exactly waits: the strategy may mark a task learned at it.
        self._record_milestones(through=self.state.total_steps - 1)
        self._update()
        return result

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

"""What a curriculum needs of a learner, as a protocol and plain data."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol, Sequence, runtime_checkable

#: S-bar: evaluation episodes of a score, the paper's 100.
PAPER_EVAL_EPISODES = 100
#: B as a share of S-bar: the paper's 75 of 100.
PAPER_THRESHOLD_FRACTION = 0.75


def paper_threshold(eval_episodes: int = PAPER_EVAL_EPISODES) -> float:
    """B for a score out of ``eval_episodes``: the paper's share of S-bar."""
    return PAPER_THRESHOLD_FRACTION * eval_episodes


@dataclass(frozen=True)
class TrainGoal:
    """Train ``initial_policy`` into ``output_policy``: one Train goal, as the curriculum asks it and the
    learner runs it (glocal_interfaces/action/Train.action; ``node_common.train_goal`` is the one
    translation to and from the message and its sentinels). A run's goals carry its B and S-bar
    (``Run.train``)."""

    task: str  # whose score decides "learned"; "" when only episode_tasks are trained
    initial_policy: str
    output_policy: str
    step_budget: int
    threshold: float = paper_threshold()  # B: learned when the score is above it
    eval_episodes: int = PAPER_EVAL_EPISODES  # S-bar
    episode_tasks: tuple[str, ...] = ()  # tasks of successive episodes; () trains ``task``
    episode_limit: int = 0  # end the goal once this many training episodes have finished; 0: no limit
    eval_interval: int = 0  # env steps between evaluations of ``task``; 0: at the end only
    stop_when_learned: bool = False  # end the goal at the first evaluation above B (checked before its first step)
    keep_replay_buffer: bool = False
    seed: int | None = None  # None: the learner's own random streams; else the goal is repeatable


def passes_threshold(score: float, threshold: float) -> bool:
    """The paper's "learned": a score (successes out of S-bar) above B. The one place that decides it."""
    return score > threshold


@dataclass(frozen=True)
class EpisodeSummary:
    """One training episode that ran to its end (success or time limit): EpisodeOutcome.msg."""

    task: str
    episode_return: float
    length: int
    success: bool


@dataclass(frozen=True)
class TrainResult:
    learned: bool
    score: float  # successes in the last evaluation of the task; -1 when none ran
    steps_used: int  # training env steps: never more than the budget (a lockstep learner may stop short of it)
    episodes: tuple[EpisodeSummary, ...] = ()  # every finished training episode, in order


class Learner(Protocol):
    def evaluate(self, policy: str, tasks: Sequence[str], episodes: int, seed: int | None = None) -> dict[str, float]:
        """Score ``policy`` on every task: successes out of ``episodes`` runs (repeatable with a ``seed``)."""

    def train(self, request: TrainGoal) -> TrainResult:
        """Train as ``request`` says; blocks until the goal ends."""

    def copy(self, source: str, destination: str) -> None:
        """Store a copy of policy ``source`` as ``destination``."""


@runtime_checkable
class ReturningLearner(Learner, Protocol):
    """A learner of a pool that can go away and come back (a killed pair, restarted)."""

    def wait_until_ready(self) -> None:
        """Block until the learner is back and takes calls; raise when it did not come back in time."""

"""A novel object, fine-tuned from the best of a finished run's policies: the paper's second future work.

The paper ends: the global task "acts as a meta task, suiting well for few-shot
learning on novel tasks ... which could be thought as unknown objects not existing
in the dataset". A finished GloCAL run holds one global policy per iteration
(``<run_id>.G<m>``, trained on its cluster's global task). ``adapt`` scores each of
them, the run's last policy and the prior on the new object, and fine-tunes the best.

ROS-free: it drives any ``glocal_ros.curriculum.learner.Learner`` (the graph's
``RosLearner``, or a test double). The choices the paper leaves open:

- **Which bit.** The object is the task ``<name>@<proxy>`` (``glocal_ros.tasks``):
  each candidate sees it under the one-hot bit of the task it last trained on
  (its ``PolicyRecord.task``; a global policy's global task, the prior's A0), so
  that only the shape is new to it. The chosen one is fine-tuned under its own.
- **The same footing.** Every candidate is scored on the same seeded episodes
  (one evaluation seed; the object's drops depend on the seed, not on the bit).
- **Ties** go to the earlier candidate in ``candidates``' order: the global
  policies by iteration, then the run's last policy, then the prior; so a global
  policy is chosen unless another scores more.
- **Already passing.** The goal checks the score before its first step, as a
  curriculum's goals do: a candidate that passes B is stored unchanged (0 steps).
"""

from __future__ import annotations

import re
from dataclasses import asdict, dataclass
from typing import Mapping, Sequence

from glocal_ros.curriculum.learner import Learner, TrainGoal
from glocal_ros.seeds import MAX_SEED, derived_seed
from glocal_ros.tasks import PRIOR_TASK, check_novel_name, novel_task, task_index

#: The strategies that train global tasks; their global policies are ``<run_id>.G<m>``
#: (``glocal_ros.curriculum.glocal``). The baselines name a learned task's policy ``<run_id>.<TASK>``, so a
#: name alone does not tell (``random-seed0.G3``).
GLOBAL_STRATEGIES = ("glocal", "glocal_random_cluster")
_GLOBAL_POLICY = re.compile(r"^(?P<run>.+)\.G(?P<iteration>[1-9][0-9]*)$")
#: The streams of an adaptation's seed: its candidates' evaluation, and its goal.
EVALUATION_STREAM, TRAINING_STREAM = 0, 1


class NoGlobalPolicyError(ValueError):
    """The run holds no global policy to adapt from."""


@dataclass(frozen=True)
class Candidate:
    """A policy to start from, what it is to the run, and the grid task whose bit it sees the object under."""

    policy: str
    roles: tuple[str, ...]  # "global 3" (pi_G,3), "last" (the run's last-trained policy), "prior"
    proxy: str


@dataclass(frozen=True)
class AdaptSettings:
    """The run's B and S-bar, the goal's budget and evaluation interval, and the seed of it all."""

    step_budget: int
    threshold: float
    eval_episodes: int
    eval_interval: int
    seed: int = 0

    def __post_init__(self) -> None:
        if self.step_budget < 1 or self.eval_episodes < 1 or self.eval_interval < 0:
            raise ValueError(f"need step_budget >= 1, eval_episodes >= 1, eval_interval >= 0: {self}")
        if not 0 <= self.seed <= MAX_SEED:
            raise ValueError(f"seed must be in 0..{MAX_SEED}, got {self.seed}")


@dataclass(frozen=True)
class Adaptation:
    """What ``adapt`` did: every candidate's score, the one it started from and how far the goal got."""

    object_name: str
    scores: tuple[tuple[Candidate, float], ...]  # in candidates' order
    chosen: Candidate
    task: str  # the goal's: <name>@<chosen proxy>
    output_policy: str
    learned: bool
    steps_to_b: int | None  # training steps until the score passed B; None when it never did
    final_score: float
    steps_used: int
    settings: AdaptSettings

    def to_dict(self) -> dict:
        return {"object": self.object_name, "task": self.task, "output_policy": self.output_policy,
                "chosen": asdict(self.chosen),
                "candidates": [{**asdict(candidate), "score": score} for candidate, score in self.scores],
                "learned": self.learned, "steps_to_b": self.steps_to_b, "final_score": self.final_score,
                "steps_used": self.steps_used, "settings": asdict(self.settings)}


def run_candidates(run_id: str, strategy: str, tasks: Mapping[str, str], last_policy: str, prior: str = "prior",
                   prior_task: str = PRIOR_TASK) -> list[Candidate]:
    """The candidates of run ``run_id`` of ``strategy``: its global policies by iteration, its last policy (the
    curriculum's ``current_policy`` at the end), then ``prior``; a policy in two roles is listed once. ``tasks``
    maps the run's stored policies to the task each last trained on. ``NoGlobalPolicyError`` when the run holds
    no global policy."""
    if strategy not in GLOBAL_STRATEGIES:
        raise NoGlobalPolicyError(f"run {run_id} holds no global policy: strategy {strategy} trains no global "
                                  f"task (only {' and '.join(GLOBAL_STRATEGIES)} do)")
    globals_ = sorted((int(match["iteration"]), name) for name in tasks
                      if (match := _GLOBAL_POLICY.match(name)) and match["run"] == run_id)
    if not globals_:
        raise NoGlobalPolicyError(f"run {run_id} holds no global policy ({run_id}.G<m>) in its store")
    roles: dict[str, list[str]] = {}
    proxies = {name: tasks[name] for name in tasks}
    for iteration, name in globals_:
        roles.setdefault(name, []).append(f"global {iteration}")
    if last_policy:
        if last_policy not in tasks:
            raise ValueError(f"run {run_id}'s last policy {last_policy!r} is not in its store")
        roles.setdefault(last_policy, []).append("last")
    roles.setdefault(prior, []).append("prior")
    proxies.setdefault(prior, prior_task)
    for name in roles:
        task_index(proxies[name])  # the task a run's policy trained on is a grid task
    return [Candidate(name, tuple(roles[name]), proxies[name]) for name in roles]


def choose(scores: Sequence[tuple[Candidate, float]]) -> Candidate:
    """The candidate with the highest score; ties to the earliest."""
    if not scores:
        raise ValueError("no candidate to choose from")
    best = max(score for _, score in scores)
    return next(candidate for candidate, score in scores if score == best)


def adapt(learner: Learner, object_name: str, candidates: Sequence[Candidate], output_policy: str,
          settings: AdaptSettings) -> Adaptation:
    """Score every candidate on the object, then fine-tune the best into ``output_policy`` until B or the budget."""
    check_novel_name(object_name)
    evaluation_seed = derived_seed(settings.seed, EVALUATION_STREAM)
    scores = []
    for candidate in candidates:
        task = novel_task(object_name, candidate.proxy)
        score = learner.evaluate(candidate.policy, [task], settings.eval_episodes, seed=evaluation_seed)[task]
        scores.append((candidate, float(score)))
    chosen = choose(scores)
    task = novel_task(object_name, chosen.proxy)
    result = learner.train(TrainGoal(task, chosen.policy, output_policy, settings.step_budget,
                                     threshold=settings.threshold, eval_episodes=settings.eval_episodes,
                                     eval_interval=settings.eval_interval, stop_when_learned=True,
                                     seed=derived_seed(settings.seed, TRAINING_STREAM)))
    return Adaptation(object_name, tuple(scores), chosen, task, output_policy, result.learned,
                      result.steps_used if result.learned else None, result.score, result.steps_used, settings)

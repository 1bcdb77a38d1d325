"""An honest test double of the learner for curriculum tests: no ROS, no RL.

Every task has a hidden difficulty (a novel object, ``NAME@PROXY``, is its proxy's task); a policy is its competence on every task
(the chance that one evaluation episode succeeds). Training on a task raises
competence on it at a rate that grows with the competence already there
and shrinks with difficulty, and spills over to grid neighbours: so the
order of training matters, as a curriculum assumes. Scores are binomial
draws from a seeded stream. The double refuses what the real learner
refuses (unknown policy, empty budget, name clashes on copy).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from glocal_ros.curriculum.learner import EpisodeSummary, TrainGoal, TrainResult
from glocal_ros.tasks import ALL_TASKS, grid_coordinates, grid_task, one_hot_bit, task_index


def grid_difficulty(task: str) -> float:
    """The letter's difficulty, 0 (A) .. 6/7 (G): hard, never impossible."""
    return grid_coordinates(task)[0] / 7


@dataclass
class SimulatedLearner:
    difficulty: dict[str, float] = field(default_factory=lambda: {t: grid_difficulty(t) for t in ALL_TASKS})
    seed: int = 0
    learn_rate: float = 2e-4  # per training step, for an easy task from zero competence
    transfer: float = 0.5  # share of a gain that reaches a grid neighbour at distance 1
    max_episode_steps: int = 50
    lockstep_envs: int = 1  # N: a goal trains a multiple of N steps, never past its budget, as the learner does

    def __post_init__(self):
        self._rng = np.random.default_rng(self.seed)
        prior = np.array([0.9 * math.exp(-1.2 * _distance("A0", t)) for t in ALL_TASKS])
        self.policies: dict[str, np.ndarray] = {"prior": prior}
        self.calls: list[tuple[str, object]] = []

    def evaluate(self, policy: str, tasks, episodes: int, seed: int | None = None) -> dict[str, float]:
        self.calls.append(("evaluate", (policy, tuple(tasks))))
        competence = self._policy(policy)
        rng = self._rng if seed is None else np.random.default_rng(seed)
        return {t: float(rng.binomial(episodes, competence[one_hot_bit(t)])) for t in tasks}

    def train(self, request: TrainGoal) -> TrainResult:
        self.calls.append(("train", request))
        rng = self._rng if request.seed is None else np.random.default_rng(request.seed)
        if request.step_budget < 1:
            raise ValueError(f"step_budget must be at least 1, got {request.step_budget}")
        competence = self._policy(request.initial_policy).copy()
        tasks = list(request.episode_tasks) or [request.task]
        budget = request.step_budget - request.step_budget % self.lockstep_envs
        chunk = request.eval_interval or budget
        steps, score, learned, episodes = 0, -1.0, False, []
        if request.task and request.stop_when_learned:  # "until S > B" checks first, as the learner does
            score = float(rng.binomial(request.eval_episodes, competence[one_hot_bit(request.task)]))
            learned = score > request.threshold
        limit = request.episode_limit or math.inf
        while steps < budget and not (learned and request.stop_when_learned) and len(episodes) < limit:
            chunk_steps = min(chunk, budget - steps)
            new = self._episodes(competence, tasks, chunk_steps, rng, first=len(episodes),
                                 most=limit - len(episodes))
            if len(episodes) + len(new) >= limit:  # the goal ends with the limit's last episode
                chunk_steps = min(chunk_steps, -(-sum(e.length for e in new) // self.lockstep_envs)
                                  * self.lockstep_envs)
            for task in tasks:
                self._practise(competence, task, chunk_steps / len(tasks))
            episodes += new
            steps += chunk_steps
            if request.task:
                score = float(rng.binomial(request.eval_episodes, competence[one_hot_bit(request.task)]))
                learned = score > request.threshold
        self.policies[request.output_policy] = competence
        return TrainResult(learned, score, steps, tuple(episodes))

    def copy(self, source: str, destination: str) -> None:
        self.calls.append(("copy", (source, destination)))
        if destination in self.policies:
            raise ValueError(f"policy {destination!r} exists already")
        self.policies[destination] = self._policy(source).copy()

    def _policy(self, name: str) -> np.ndarray:
        if name not in self.policies:
            raise KeyError(f"unknown policy {name!r}")
        return self.policies[name]

    def _practise(self, competence: np.ndarray, task: str, steps: float) -> None:
        task = grid_task(task)  # a novel object is, to the double, the task whose bit it borrows
        index = task_index(task)
        rate = self.learn_rate * (1 - self.difficulty[task]) ** 2 * (competence[index] + 0.02)
        gain = (1 - competence[index]) * (1 - math.exp(-rate * steps))
        for other in ALL_TASKS:
            share = 1.0 if other == task else self.transfer ** _distance(task, other)
            j = task_index(other)
            competence[j] = min(1.0, competence[j] + share * gain * (1 - competence[j]))

    def _episodes(self, competence: np.ndarray, tasks: list[str], steps: int, rng: np.random.Generator,
                  first: int = 0, most: float = math.inf) -> list[EpisodeSummary]:
        """Episodes in ``steps`` (the last one cut), at most ``most``; the ``first``-th of ``tasks`` starts."""
        episodes, used, turn = [], 0, first
        while used < steps and len(episodes) < most:
            task = tasks[turn % len(tasks)]
            turn += 1
            success = bool(rng.random() < competence[one_hot_bit(task)])
            length = min(int(rng.integers(15, 30)) if success else self.max_episode_steps, steps - used)
            used += length
            episodes.append(EpisodeSummary(task, -float(length), length, success))
        return episodes


def _distance(a: str, b: str) -> float:
    (ra, ca), (rb, cb) = grid_coordinates(a), grid_coordinates(b)
    return math.hypot(ra - rb, ca - cb)


class SteppedCalls:
    """A ``CallRunner`` for tests: a started call runs only when the test's ``choose`` picks it to end next.

    ``choose`` gets the keys of the started calls in the order they started and returns the index of the
    one to end: so the test, not thread timing, decides the completion order. ``started`` lists every
    (slot, key) in the order they started; ``ends_after`` answers that many calls, then raises ``Killed``
    as a killed curriculum node would stop.
    """

    def __init__(self, choose=lambda keys: 0, ends_after: int | None = None):
        self.choose, self.left = choose, ends_after
        self.running: list[tuple[int, object, str, object]] = []
        self.started: list[tuple[int, str]] = []
        self.overlaps: list[tuple[str, tuple[str, ...]]] = []  # a call's key, and the keys running when it started

    def start(self, slot, learner, key, ask):
        self.overlaps.append((key, tuple(k for _, _, k, _ in self.running)))
        self.running.append((slot, learner, key, ask))
        self.started.append((slot, key))

    def next_done(self):
        if self.left is not None:
            if self.left == 0:
                raise Killed()
            self.left -= 1
        slot, learner, key, ask = self.running.pop(self.choose([k for _, _, k, _ in self.running]))
        try:
            answer = ask(learner)
        except Exception as error:  # noqa: BLE001 - as ThreadedCalls hands it on
            answer = error
        return slot, key, answer


class Killed(Exception):
    pass

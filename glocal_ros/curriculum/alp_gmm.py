"""ALP-GMM teacher (Portelas et al., 2019) over the discrete A0..G6 task grid.

A baseline of the GloCAL paper: Gaussian mixtures are fitted on
``[x, y, alp]`` rows of recent training episodes, and the next task is drawn
from a mixture component chosen in proportion to its mean absolute learning
progress (ALP), or uniformly at random with probability ``random_fraction``.

The original works on a continuous task space; choices made for 49 discrete
objects:

- Task space: ``grid_coordinates(task)`` divided by 6, so both axes span
  [0, 1] on the full grid whatever subset of ``tasks`` a run uses (distances
  then do not depend on the subset). Only ``tasks`` are candidates (``retire``
  takes one out: the baselines' ``unlearned`` option); a point
  drawn from a Gaussian is snapped to the nearest of them (Euclidean), which
  replaces the original's clipping to the task-space box.
- Returns are normalised to [0, 1] with ``[min_return, max_return]`` (default
  ``[-50, 0]``: reward -1 per step, at most T = 50 steps) and clipped.
- ALP of an episode: absolute difference between its normalised return and
  that of the nearest earlier episode in task space, i.e. the latest earlier
  episode of the same task when there is one; otherwise the nearest task
  played before, ties going to the most recent. The very first episode has
  ALP 0 (the original waits for 5 episodes; with repeated tasks one suffices).
- Refit after every ``fit_rate`` updates, the first fit after ``fit_rate``
  updates (the original's bootstrap phase of ``fit_rate`` random episodes).
  The GMM sees the last ``history_size`` episodes; the original uses the last
  ``fit_rate`` (= 250). The default ``max(fit_rate, 250)`` keeps that 250
  episode window when refitting more often (``fit_rate=10``), so a refit
  never sees fewer episodes than in the original.
- k ranges over ``[k_min, k_max]`` capped at the number of distinct rows:
  episodes of one task share (x, y), and more components than distinct points
  cannot be fitted. The lowest AIC wins, ties going to the smaller k.
- A Gaussian is chosen in proportion to the ALP coordinate of its mean; when
  all are ~0 (nothing is being learned) in proportion to its mixture weight
  (the original picks uniformly among Gaussians there).
- All randomness, the GMM seeds included, comes from one
  ``numpy.random.Generator`` seeded by ``seed``: the same seed and the same
  ``update`` calls give the same tasks.
"""

from __future__ import annotations

import math
import warnings
from collections import deque
from typing import Sequence

import numpy as np
from sklearn.exceptions import ConvergenceWarning
from sklearn.mixture import GaussianMixture
from threadpoolctl import threadpool_limits

from glocal_ros.tasks import COMPLEXITY_LEVELS, DIFFICULTY_LEVELS, grid_coordinates, validate_tasks

_GRID_SCALE = (float(len(DIFFICULTY_LEVELS) - 1), float(len(COMPLEXITY_LEVELS) - 1))
_ALP_EPS = 1e-8  # mean ALPs below this count as "no progress anywhere"


class AlpGmmSampler:
    """Absolute Learning Progress - Gaussian Mixture Model task sampler.

    :param tasks: Candidate tasks (names on the A0..G6 grid); duplicates are dropped.
    :param fit_rate: Number of ``update`` calls between two GMM fits (250 and 10 in the paper).
    :param seed: Seed of the sampler's random generator.
    :param random_fraction: Probability of a uniformly random task once a GMM is fitted.
    :param k_min: Smallest number of Gaussians tried.
    :param k_max: Largest number of Gaussians tried.
    :param history_size: Number of most recent episodes a fit sees (default ``max(fit_rate, 250)``).
    :param min_return: Episode return mapped to 0 (lower ones are clipped).
    :param max_return: Episode return mapped to 1 (higher ones are clipped).
    """

    def __init__(
        self,
        tasks: Sequence[str],
        fit_rate: int,
        seed: int = 0,
        random_fraction: float = 0.2,
        k_min: int = 2,
        k_max: int = 10,
        history_size: int | None = None,
        min_return: float = -50.0,
        max_return: float = 0.0,
    ) -> None:
        self.tasks: tuple[str, ...] = tuple(dict.fromkeys(validate_tasks(tasks)))  # the candidates
        if not self.tasks:
            raise ValueError("tasks is empty")
        self._known = frozenset(self.tasks)  # candidates and retired ones: what ``update`` accepts
        if fit_rate < 1:
            raise ValueError(f"fit_rate must be >= 1, got {fit_rate}")
        if not 0.0 <= random_fraction <= 1.0:
            raise ValueError(f"random_fraction must be in [0, 1], got {random_fraction}")
        if not 1 <= k_min <= k_max:
            raise ValueError(f"need 1 <= k_min <= k_max, got k_min={k_min}, k_max={k_max}")
        if history_size is None:
            history_size = max(fit_rate, 250)
        if history_size < 1:
            raise ValueError(f"history_size must be >= 1, got {history_size}")
        if not min_return < max_return:
            raise ValueError(f"need min_return < max_return, got {min_return} >= {max_return}")
        self.fit_rate = fit_rate
        self.random_fraction = random_fraction
        self.k_min, self.k_max = k_min, k_max
        self.history_size = history_size
        self.min_return, self.max_return = min_return, max_return

        self._rng = np.random.default_rng(seed)
        self._coords = np.array([self._position(task) for task in self.tasks])
        self._rows: deque[tuple[float, float, float]] = deque(maxlen=history_size)
        self._alps: list[float] = []
        self._last_return: dict[str, float] = {}  # latest normalised return of each task played
        self._last_episode: dict[str, int] = {}  # and the update count at which it was played
        self._gmm: GaussianMixture | None = None

    @property
    def fitted(self) -> bool:
        """Whether a GMM has been fitted (after the first ``fit_rate`` updates)."""
        return self._gmm is not None

    @property
    def updates_before_refit(self) -> int:
        """``update`` calls until the next GMM fit: the episodes that the current GMM still draws."""
        return self.fit_rate - len(self._alps) % self.fit_rate

    @property
    def alps(self) -> tuple[float, ...]:
        """ALP of every episode passed to ``update``, in order."""
        return tuple(self._alps)

    def sample(self) -> str:
        """The task of the next training episode."""
        if self._gmm is None or self._rng.random() < self.random_fraction:
            return self.tasks[self._rng.integers(len(self.tasks))]
        alp_means = np.clip(self._gmm.means_[:, 2], 0.0, None)
        weights = alp_means if alp_means.sum() > _ALP_EPS else self._gmm.weights_
        index = self._rng.choice(len(weights), p=weights / weights.sum())
        point = self._rng.multivariate_normal(self._gmm.means_[index], self._gmm.covariances_[index])
        nearest = np.argmin(np.sum((self._coords - point[:2]) ** 2, axis=1))
        return self.tasks[nearest]

    def update(self, task: str, episode_return: float) -> None:
        """Record one finished training episode of ``task``; refit every ``fit_rate`` calls."""
        validate_tasks([task])
        if task not in self._known:
            raise ValueError(f"task {task!r} is not one of this sampler's tasks")
        if not math.isfinite(episode_return):
            raise ValueError(f"episode_return must be finite, got {episode_return}")
        normalised = (episode_return - self.min_return) / (self.max_return - self.min_return)
        normalised = min(max(normalised, 0.0), 1.0)
        alp = abs(normalised - self._nearest_earlier_return(task)) if self._last_return else 0.0

        self._alps.append(alp)
        self._rows.append((*self._position(task), alp))
        self._last_return[task] = normalised
        self._last_episode[task] = len(self._alps)
        if len(self._alps) % self.fit_rate == 0:
            self._refit()

    def retire(self, task: str) -> None:
        """Draw ``task`` no more: points then snap to the nearest remaining candidate. Its episodes
        stay in the history that fits see, and ``update`` still takes episodes drawn before."""
        if task not in self.tasks:
            raise ValueError(f"task {task!r} is not a candidate of this sampler")
        if len(self.tasks) == 1:
            raise ValueError(f"{task!r} is the last candidate")
        self.tasks = tuple(t for t in self.tasks if t != task)
        self._coords = np.array([self._position(t) for t in self.tasks])

    def _nearest_earlier_return(self, task: str) -> float:
        if task in self._last_return:
            return self._last_return[task]
        # Integer grid distances: both axes share one scale, and exact ties can be broken by recency.
        row, col = grid_coordinates(task)

        def key(other: str) -> tuple[int, int]:
            other_row, other_col = grid_coordinates(other)
            return (other_row - row) ** 2 + (other_col - col) ** 2, -self._last_episode[other]

        return self._last_return[min(self._last_return, key=key)]

    def _refit(self) -> None:
        data = np.array(self._rows)
        n_distinct = len(np.unique(data, axis=0))
        # One seed per refit, shared by all k, as the original seeds every candidate alike.
        seed = int(self._rng.integers(2**31 - 1))
        best, best_aic = None, math.inf
        for k in range(min(self.k_min, n_distinct), min(self.k_max, n_distinct) + 1):
            # 3x3 covariances: BLAS threads only add wake-ups (several times slower on a busy 2-core machine).
            with warnings.catch_warnings(), threadpool_limits(1):
                # EM stopping at max_iter on near-duplicate points is expected, not worth a log line.
                warnings.simplefilter("ignore", ConvergenceWarning)
                gmm = GaussianMixture(k, covariance_type="full", random_state=seed).fit(data)
            aic = gmm.aic(data)
            if aic < best_aic:
                best, best_aic = gmm, aic
        self._gmm = best

    @staticmethod
    def _position(task: str) -> tuple[float, float]:
        row, col = grid_coordinates(task)
        return row / _GRID_SCALE[0], col / _GRID_SCALE[1]

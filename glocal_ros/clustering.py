"""Task clustering by evaluation score (GloCAL, Section III-C).

k-means on the scores of the remaining tasks, the number of clusters chosen
by the highest silhouette coefficient, clusters ordered by mean score, and
the global task taken as the ceiling of the median of the best cluster.

Choices the paper leaves open, made here:
- k ranges over ``[k_min, k_max]``, capped at the number of distinct scores
  and at ``n - 1`` (the silhouette needs 2 <= k <= n - 1); when no k is left
  (two tasks, all scores equal, ...) there is one cluster and the
  silhouette is reported as NaN. The paper forms one cluster when 2 tasks
  are left; so does this, whatever their scores.
- Ties in silhouette go to the smaller k (coarser, larger first cluster).
- Equal scores inside a cluster keep grid order (A0 before A1 ...), so the
  descending order, and with it the global task, is deterministic.
- ``k-means`` uses ``n_init=10`` restarts seeded by ``seed``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Mapping

import numpy as np
from sklearn.cluster import KMeans
from sklearn.metrics import silhouette_score

from glocal_ros.tasks import task_index


@dataclass(frozen=True)
class Cluster:
    tasks: tuple[str, ...]  # descending score
    scores: tuple[float, ...]  # same order

    @property
    def mean_score(self) -> float:
        return float(np.mean(self.scores))


@dataclass(frozen=True)
class Clustering:
    clusters: tuple[Cluster, ...]  # descending mean score: clusters[0] is C_1
    silhouette: float  # NaN when one cluster was formed without a choice


def descending(tasks_scores: Mapping[str, float]) -> list[tuple[str, float]]:
    """``(task, score)`` pairs by descending score, equal scores in grid order."""
    return sorted(tasks_scores.items(), key=lambda item: (-item[1], task_index(item[0])))


def cluster_tasks(scores: Mapping[str, float], k_min: int = 2, k_max: int = 6, seed: int = 0) -> Clustering:
    """Cluster tasks by score; ``scores`` maps each remaining task to its evaluation score."""
    if not scores:
        raise ValueError("no task to cluster")
    if not 2 <= k_min <= k_max:
        raise ValueError(f"need 2 <= k_min <= k_max, got k_min={k_min}, k_max={k_max}")
    tasks = list(scores)
    values = np.array([scores[t] for t in tasks], dtype=float).reshape(-1, 1)
    distinct = len(np.unique(values))
    k_top = min(k_max, distinct, len(tasks) - 1)
    if len(tasks) <= 2 or k_top < k_min:
        return Clustering((_cluster(scores),), math.nan)

    best_silhouette, best_labels = -math.inf, None
    for k in range(k_min, k_top + 1):
        labels = KMeans(n_clusters=k, n_init=10, random_state=seed).fit_predict(values)
        if len(np.unique(labels)) < 2:
            continue
        silhouette = float(silhouette_score(values, labels))
        if silhouette > best_silhouette:
            best_silhouette, best_labels = silhouette, labels
    if best_labels is None:
        return Clustering((_cluster(scores),), math.nan)

    clusters = [
        _cluster({t: scores[t] for t, label in zip(tasks, best_labels) if label == k})
        for k in np.unique(best_labels)
    ]
    clusters.sort(key=lambda c: (-c.mean_score, task_index(c.tasks[0])))
    return Clustering(tuple(clusters), best_silhouette)


def global_task_index(cluster_size: int) -> int:
    """Index of the global task in a cluster sorted by descending score.

    The paper's ceil(median): the 1-based position ceil((n + 1) / 2), i.e.
    the middle task for odd n and the lower of the two middle ones for even n.
    """
    if cluster_size < 1:
        raise ValueError("an empty cluster has no global task")
    return cluster_size // 2


def split_global_local(cluster: Cluster) -> tuple[str, list[str]]:
    """The global task of ``cluster`` and its local tasks in training order (descending score)."""
    index = global_task_index(len(cluster.tasks))
    return cluster.tasks[index], [t for i, t in enumerate(cluster.tasks) if i != index]


def _cluster(scores: Mapping[str, float]) -> Cluster:
    ordered = descending(scores)
    return Cluster(tuple(t for t, _ in ordered), tuple(float(s) for _, s in ordered))

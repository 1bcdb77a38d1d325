import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from glocal_ros.clustering import cluster_tasks, descending, global_task_index, split_global_local
from glocal_ros.tasks import ALL_TASKS


def test_two_clear_groups_are_found_and_ordered_by_mean():
    scores = {"A0": 90, "A1": 85, "A2": 88, "B0": 10, "B1": 5, "B2": 12}
    clustering = cluster_tasks(scores)
    assert len(clustering.clusters) == 2
    best, worst = clustering.clusters
    assert set(best.tasks) == {"A0", "A1", "A2"} and set(worst.tasks) == {"B0", "B1", "B2"}
    assert best.tasks == ("A0", "A2", "A1")  # descending score
    assert clustering.silhouette > 0.9


def test_silhouette_picks_three_groups_when_there_are_three():
    scores = {"A0": 95, "A1": 96, "B0": 50, "B1": 52, "C0": 0, "C1": 1, "C2": 2}
    clustering = cluster_tasks(scores, k_min=2, k_max=5)
    assert [set(c.tasks) for c in clustering.clusters] == [{"A0", "A1"}, {"B0", "B1"}, {"C0", "C1", "C2"}]


@pytest.mark.parametrize("scores", [
    {"A0": 40, "A1": 40, "A2": 40, "A3": 40},  # all equal: silhouette undefined
    {"A0": 0, "A1": 0, "A2": 0},  # all zero
    {"C3": 70, "D4": 10},  # two tasks: the paper forms one cluster
    {"G6": 3},  # one task
])
def test_single_cluster_cases(scores):
    clustering = cluster_tasks(scores)
    assert len(clustering.clusters) == 1
    assert set(clustering.clusters[0].tasks) == set(scores)
    assert math.isnan(clustering.silhouette)


def test_ceil_median_global_task():
    # 1-based position ceil((n + 1) / 2) of the descending order.
    assert [global_task_index(n) for n in (1, 2, 3, 4, 5, 6)] == [0, 1, 1, 2, 2, 3]
    scores = {"A0": 90, "A1": 80, "A2": 70, "A3": 60, "G0": 0, "G1": 1, "G2": 0}
    cluster = cluster_tasks(scores).clusters[0]
    assert cluster.tasks == ("A0", "A1", "A2", "A3")
    global_task, local_tasks = split_global_local(cluster)
    assert global_task == "A2"
    assert local_tasks == ["A0", "A1", "A3"]


def test_equal_scores_keep_grid_order():
    assert [t for t, _ in descending({"B1": 5, "A3": 5, "A0": 7})] == ["A0", "A3", "B1"]


def test_deterministic_under_seed():
    rng = np.random.default_rng(3)
    scores = {t: float(s) for t, s in zip(ALL_TASKS, rng.integers(0, 101, size=49))}
    assert cluster_tasks(scores, 2, 8, seed=5) == cluster_tasks(scores, 2, 8, seed=5)


def test_bad_arguments():
    with pytest.raises(ValueError):
        cluster_tasks({})
    with pytest.raises(ValueError):
        cluster_tasks({"A0": 1, "A1": 2}, k_min=1)
    with pytest.raises(ValueError):
        cluster_tasks({"A0": 1, "A1": 2}, k_min=4, k_max=3)


@settings(max_examples=60, deadline=None)
@given(st.dictionaries(st.sampled_from(ALL_TASKS), st.integers(0, 100), min_size=1, max_size=49),
       st.integers(2, 4), st.integers(0, 4))
def test_clustering_properties(scores, k_min, k_extra):
    clustering = cluster_tasks(scores, k_min=k_min, k_max=k_min + k_extra)
    clusters = clustering.clusters
    # A partition of the tasks ...
    assert sorted(t for c in clusters for t in c.tasks) == sorted(scores)
    # ... ordered by descending mean, each sorted by descending score ...
    means = [c.mean_score for c in clusters]
    assert means == sorted(means, reverse=True)
    for c in clusters:
        assert list(c.scores) == sorted(c.scores, reverse=True)
        assert list(c.scores) == [scores[t] for t in c.tasks]
    # ... into 1 or k_min..k_max clusters, contiguous in score (1-D k-means never interleaves).
    assert len(clusters) == 1 or k_min <= len(clusters) <= k_min + k_extra
    for upper, lower in zip(clusters, clusters[1:]):
        assert min(upper.scores) >= max(lower.scores)
    assert math.isnan(clustering.silhouette) == (len(clusters) == 1)

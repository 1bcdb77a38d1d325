"""``glocal_ros.analysis.estimates``: IQM, probability of improvement and their bootstrap CIs, checked against rliable.

The reference numbers below were computed once with rliable 1.2.0 itself (arch 7.2.0,
pandas 2.3.3, numpy 2.4.6, scipy 1.17.1, in a throwaway venv: rliable is not a
dependency of the project), for each case, as::

    from rliable import library as rly, metrics
    np.random.seed(0)  # rliable's StratifiedBootstrap draws from numpy's global generator
    points, cis = rly.get_interval_estimates({"x": x, "y": y},
                                             lambda s: np.array([metrics.aggregate_iqm(s)]), reps=50000)
    np.random.seed(0)
    poi, poi_ci = rly.get_interval_estimates({"xy": [x, y]}, metrics.probability_of_improvement, reps=50000)

(defaults: method='percentile', 95%, task_bootstrap=False). Point estimates must agree exactly;
intervals up to the Monte Carlo error of 50,000 resamples from another random stream (20 seeds of
ours stayed within 0.6% of the data's span for the IQM and 0.005 for the probability of
improvement; resampling whole runs instead of runs within each task misses ``three_tasks`` by 11%).
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.stats import trim_mean

from glocal_ros.analysis.estimates import (
    BOOTSTRAP_REPS,
    CONFIDENCE,
    Interval,
    few_seeds_note,
    improvement_interval,
    iqm,
    iqm_interval,
    milestone_estimates,
    probability_of_improvement,
)

# (runs x tasks) scores of X and Y, and rliable's (point, low, high) of IQM(X), IQM(Y) and P(X > Y).
RLIABLE_CASES = {
    # 3 seeds of one task, integer counts: bench curriculum's milestones.
    "three_seeds": dict(
        x=[[8], [13], [12]], y=[[11], [12], [12]],
        iqm_x=(11.0, 8.0, 13.0), iqm_y=(11.666666666666666, 11.0, 12.0), poi=(0.5555555555555556, 0.0, 1.0)),
    # 10 and 12 runs of one task: trim_mean cuts 2 and 3 runs from each end.
    "ten_runs": dict(
        x=[[3.1], [0.2], [5.5], [2.2], [9.0], [4.4], [4.1], [1.0], [7.7], [6.3]],
        y=[[2.0], [2.5], [3.0], [0.1], [8.8], [1.9], [4.0], [4.1], [2.2], [3.3], [5.0], [0.7]],
        iqm_x=(4.266666666666667, 2.283333333333333, 6.366666666666667),
        iqm_y=(2.8333333333333335, 1.8333333333333333, 3.966666666666667),
        poi=(0.6583333333333333, 0.4083333333333333, 0.8833333333333333)),
    # 6 and 7 runs x 3 tasks: a run good on one task is good on all (so resampling runs within each
    # task, not whole runs, matters), and ties between X and Y.
    "three_tasks": dict(
        x=[[0, 1, 0], [1, 2, 2], [2, 3, 4], [3, 4, 6], [4, 5, 8], [5, 6, 10]],
        y=[[0, 1, 0], [1, 1, 1], [1, 2, 2], [2, 2, 3], [2, 3, 4], [3, 3, 5], [4, 4, 6]],
        iqm_x=(3.4, 2.2, 4.6), iqm_y=(2.1818181818181817, 1.4545454545454546, 3.0),
        poi=(0.6587301587301586, 0.4761904761904761, 0.8253968253968255)),
}
IQM_TOLERANCE = 0.015  # of the span of the case's scores
POI_TOLERANCE = 0.01


@pytest.mark.parametrize("name", RLIABLE_CASES)
def test_iqm_and_its_interval_agree_with_rliable(name: str) -> None:
    case = RLIABLE_CASES[name]
    span = np.ptp(np.concatenate([np.ravel(case["x"]), np.ravel(case["y"])]))
    for scores, (point, low, high) in ((case["x"], case["iqm_x"]), (case["y"], case["iqm_y"])):
        assert iqm(scores) == pytest.approx(point, rel=1e-12)
        interval = iqm_interval(scores)
        assert interval.point == pytest.approx(point, rel=1e-12)
        assert interval.low == pytest.approx(low, abs=IQM_TOLERANCE * span)
        assert interval.high == pytest.approx(high, abs=IQM_TOLERANCE * span)


@pytest.mark.parametrize("name", RLIABLE_CASES)
def test_probability_of_improvement_and_its_interval_agree_with_rliable(name: str) -> None:
    case = RLIABLE_CASES[name]
    point, low, high = case["poi"]
    assert probability_of_improvement(case["x"], case["y"]) == pytest.approx(point, rel=1e-12)
    interval = improvement_interval(case["x"], case["y"])
    assert interval.point == pytest.approx(point, rel=1e-12)
    assert interval.low == pytest.approx(low, abs=POI_TOLERANCE)
    assert interval.high == pytest.approx(high, abs=POI_TOLERANCE)


def test_three_seeds_the_interval_is_exactly_the_seeds_range() -> None:
    # A resample of one seed three times has probability 1/27 > 2.5%: both ends are atoms.
    assert iqm_interval([8, 13, 12]) == Interval(11.0, 8.0, 13.0)
    assert iqm_interval([13, 13, 13]) == Interval(13.0, 13.0, 13.0)
    # Exhaustively: the IQM of 3 is their mean, and the 27 resamples' percentiles are min and max.
    resamples = [np.mean([a, b, c]) for a in (8, 13, 12) for b in (8, 13, 12) for c in (8, 13, 12)]
    assert np.percentile(np.repeat(resamples, 1000), [2.5, 97.5]).tolist() == [8.0, 13.0]


def test_iqm_is_the_25_percent_trimmed_mean_of_runs_and_tasks_pooled() -> None:
    assert iqm([1, 2, 3]) == 2.0  # trims nothing below 4 values
    assert iqm([0, 1, 2, 100]) == 1.5  # trims one from each end
    scores = np.arange(24.0).reshape(8, 3) ** 2 * [1, 10, 1]  # task 1 on another scale
    assert iqm(scores) == pytest.approx(trim_mean(scores.ravel(), 0.25))
    assert iqm(scores) != pytest.approx(np.mean(trim_mean(scores, 0.25, axis=0)))  # pooled, not per task
    with pytest.raises(ValueError):
        iqm([])


def test_probability_of_improvement_counts_ties_half_and_averages_tasks() -> None:
    assert probability_of_improvement([1, 2, 3], [1, 2, 3]) == 0.5
    assert probability_of_improvement([13, 13, 13], [13, 13, 13]) == 0.5
    assert probability_of_improvement([5, 6], [1, 2, 3]) == 1.0
    assert probability_of_improvement([1, 2, 3], [5, 6]) == 0.0
    assert probability_of_improvement([2], [1, 2, 3]) == pytest.approx((1 + 0.5) / 3)
    x, y = [[1, 5], [2, 5]], [[0, 6], [3, 6], [1, 6]]
    assert probability_of_improvement(x, y) == pytest.approx((3.5 / 6 + 0.0) / 2)  # task 0: 1>0, 1=1, 2>0, 2>1
    assert probability_of_improvement(y, x) + probability_of_improvement(x, y) == pytest.approx(1.0)
    with pytest.raises(ValueError, match="same tasks"):
        probability_of_improvement([[1, 2]], [[1, 2, 3]])


def test_intervals_are_reproducible_and_seeded() -> None:
    scores = RLIABLE_CASES["ten_runs"]["x"]
    assert iqm_interval(scores) == iqm_interval(scores)
    assert iqm_interval(scores, seed=1) != iqm_interval(scores, seed=2)
    narrow = iqm_interval(scores, confidence=0.5)
    wide = iqm_interval(scores)
    assert wide.low < narrow.low <= narrow.point <= narrow.high < wide.high
    assert improvement_interval([1, 2, 3], [2, 3, 4], reps=1000) == improvement_interval([1, 2, 3], [2, 3, 4],
                                                                                          reps=1000)
    with pytest.raises(ValueError, match="confidence"):
        iqm_interval(scores, confidence=95)


def test_milestone_estimates_per_strategy_and_step() -> None:
    values = {"glocal": {1000: [1, 2, 3], 2000: [4, 5, 6]},
              "random": {1000: [0, 1, 1], 2000: [6, 6]},
              "alp_gmm_10": {1000: [2]}}
    estimates = milestone_estimates(values, "glocal", reps=2000)
    assert estimates.steps == [1000, 2000] and estimates.reference == "glocal"
    assert estimates.runs["random"] == {1000: 3, 2000: 2} and estimates.runs["alp_gmm_10"][2000] == 0
    assert estimates.iqm["glocal"][1000] == iqm_interval([1, 2, 3], reps=2000)
    assert estimates.iqm["alp_gmm_10"][2000] is None
    assert set(estimates.improvement) == {"random", "alp_gmm_10"}
    assert estimates.improvement["random"][2000] == improvement_interval([4, 5, 6], [6, 6], reps=2000)
    assert estimates.improvement["random"][2000].point == pytest.approx(1 / 6)
    assert estimates.improvement["alp_gmm_10"][2000] is None
    assert (estimates.confidence, estimates.reps, estimates.fewest_runs()) == (CONFIDENCE, 2000, 1)
    alone = milestone_estimates({"glocal": values["glocal"]}, "glocal", reps=100)
    assert alone.reference is None and alone.improvement == {}
    assert milestone_estimates(values, None, reps=100).improvement == {}
    assert BOOTSTRAP_REPS == 50_000  # rliable's default


def test_few_seeds_note_says_what_three_seeds_cannot() -> None:
    note = few_seeds_note(3)
    assert "the IQM trims none" in note and "3.7%" in note and "min to max" in note and "weak evidence" in note
    assert "min to max" not in few_seeds_note(3, confidence=0.9)  # 3.7% is below 5%
    assert few_seeds_note(4) == ""
    assert few_seeds_note(1).startswith("Few seeds: with 1 run a strategy's IQM is that run and its interval the run")
    assert few_seeds_note(0) == "" and few_seeds_note(10) == ""

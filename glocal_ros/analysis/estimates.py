"""Few-seed statistics as rliable computes them: IQM and probability of improvement, with bootstrap CIs.

The field's convention for comparing RL algorithms over a handful of seeds
(Agarwal et al., "Deep Reinforcement Learning at the Edge of the Statistical
Precipice", NeurIPS 2021; its library ``rliable``), written here against the
published definitions and the library's source (``rliable/metrics.py`` and
``rliable/library.py`` of version 1.2.0) rather than imported: rliable pulls
arch, pandas, seaborn and absl for four array operations. ``test_estimates``
checks the IQM, the probability of improvement and both intervals against
numbers that rliable 1.2.0 computed on fixed data.

Scores are a ``(runs, tasks)`` array: ``scores[n, m]`` is run ``n``'s score
on task ``m``; a 1-D array is one task. In this project a run is one seed of
a strategy, there is one task, and the score is the objects learned at a
milestone (:func:`milestone_estimates`).

- **IQM** (:func:`iqm`): the interquartile mean, the mean of the middle 50% of
  all runs x tasks pooled: ``scipy.stats.trim_mean(scores, 0.25, axis=None)``
  (rliable's ``aggregate_iqm``). trim_mean cuts ``int(0.25 * N)`` values from
  each end, so for fewer than 4 values it cuts none and the IQM *is* the mean.
- **Probability of improvement** (:func:`probability_of_improvement`):
  ``P(X > Y)``, per task the Mann-Whitney U statistic of X over Y divided by
  ``n_x * n_y`` (a tie counts 1/2), averaged over tasks (rliable's
  ``probability_of_improvement``). 0.5: no difference either way.
- **Stratified bootstrap CI** (:func:`iqm_interval`, :func:`improvement_interval`):
  each resample draws runs with replacement within each task (rliable's
  ``StratifiedBootstrap``, tasks not resampled: ``task_bootstrap=False``); for
  the probability of improvement X and Y are resampled independently
  (``StratifiedIndependentBootstrap``). The interval is the percentile one,
  rliable's default ``method='percentile'``: ``numpy.percentile`` (linear
  interpolation) of the statistic over the resamples at ``(1 - confidence) / 2``
  and its complement, as ``arch``'s ``conf_int`` computes it. rliable's defaults
  are kept: ``reps = 50,000`` resamples, 95% confidence.

Choices this module makes where rliable leaves them open:

- Reproducible: every interval draws from ``numpy.random.default_rng(seed)``,
  ``seed = BOOTSTRAP_SEED`` unless told, a fresh generator per interval, so
  the same scores give the same interval whatever else a report holds.
  (rliable draws from numpy's global generator, so its numbers depend on what
  ran before, whatever ``random_state`` it is given.) Strategies with as many
  runs thus share their resampling pattern. The stream differs from
  rliable's: intervals agree with its up to Monte Carlo error, and exactly
  where each percentile falls inside one atom of a discrete bootstrap
  distribution (as with 3 seeds of integer counts).
- Few seeds: with ``n`` runs of one task a resample that repeats one run
  ``n`` times has probability ``n ** -n``; for ``n <= 3`` that is above 2.5%, so
  the 95% interval of the IQM is exactly the runs' min to max. Such an
  interval says how far apart the seeds are, not how precise the mean is,
  and the percentile bootstrap, which only redraws the values observed,
  undercovers at such n rather than overcovers; :func:`few_seeds_note` says
  so in words for a table.
- A group without runs has no estimate (None), and a probability of
  improvement needs runs on both sides.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

#: rliable's defaults (``get_interval_estimates``): 50,000 resamples, a 95% interval.
BOOTSTRAP_REPS = 50_000
CONFIDENCE = 0.95
#: The seed of every interval unless told otherwise (see the module's docstring).
BOOTSTRAP_SEED = 0
#: The fraction trimmed from each end for the IQM.
IQM_TRIM = 0.25
# Resamples evaluated at once: bounds the memory of a bootstrap of many runs (reps x runs x tasks values).
_CHUNK_VALUES = 4_000_000


@dataclass(frozen=True)
class Interval:
    """A point estimate and its bootstrap confidence interval ``[low, high]``."""

    point: float
    low: float
    high: float

    def cell(self, digits: int = 1) -> str:
        """``'13.3 [13.0, 14.0]'``."""
        return f"{self.point:.{digits}f} [{self.low:.{digits}f}, {self.high:.{digits}f}]"


def _trim_mean(values: np.ndarray, axis: int | None) -> np.ndarray | float:
    from scipy.stats import trim_mean  # scipy is slow to import: only when an estimate is due (the CLI imports us)

    return trim_mean(values, IQM_TRIM, axis=axis)


def as_scores(scores: Sequence[float] | np.ndarray) -> np.ndarray:
    """``scores`` as a float ``(runs, tasks)`` array (a 1-D sequence is one task); ValueError if it has no run."""
    array = np.asarray(scores, dtype=float)
    if array.ndim == 1:
        array = array[:, None]
    if array.ndim != 2 or array.shape[0] == 0 or array.shape[1] == 0:
        raise ValueError(f"scores must be (runs, tasks) with at least one of each, not of shape {array.shape}")
    return array


def iqm(scores: Sequence[float] | np.ndarray) -> float:
    """The interquartile mean of all runs x tasks pooled (rliable's ``aggregate_iqm``)."""
    return float(_trim_mean(as_scores(scores), axis=None))


def probability_of_improvement(x: Sequence[float] | np.ndarray, y: Sequence[float] | np.ndarray) -> float:
    """``P(X > Y)`` averaged over tasks, a tie counting 1/2: the Mann-Whitney U of X over Y / (n_x n_y)."""
    x, y = as_scores(x), as_scores(y)
    return float(_improvement(x[None], y[None])[0])


def _improvement(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Probability of improvement of each resample: ``x`` (reps, n_x, tasks) over ``y`` (reps, n_y, tasks)."""
    if x.shape[2] != y.shape[2]:
        raise ValueError(f"X has {x.shape[2]} tasks and Y {y.shape[2]}: they must be scored on the same tasks")
    difference = x[:, :, None, :] - y[:, None, :, :]  # (reps, n_x, n_y, tasks)
    wins = (difference > 0).mean(axis=(1, 2)) + 0.5 * (difference == 0).mean(axis=(1, 2))
    return wins.mean(axis=1)


def _resample(rng: np.random.Generator, scores: np.ndarray, reps: int) -> np.ndarray:
    """``reps`` stratified resamples of ``scores`` (runs, tasks): runs drawn with replacement within each task."""
    runs, tasks = scores.shape
    index = rng.integers(0, runs, size=(reps, runs, tasks))
    return scores[index, np.arange(tasks)]


def _percentile_interval(point: float, values: np.ndarray, confidence: float) -> Interval:
    if not 0 < confidence < 1:
        raise ValueError(f"confidence must be in (0, 1), not {confidence}")
    alpha = (1 - confidence) / 2
    low, high = np.percentile(values, [100 * alpha, 100 * (1 - alpha)])
    return Interval(point, float(low), float(high))


def _chunks(reps: int, values_per_rep: int) -> list[int]:
    size = max(1, _CHUNK_VALUES // max(1, values_per_rep))
    return [min(size, reps - start) for start in range(0, reps, size)]


def iqm_interval(scores: Sequence[float] | np.ndarray, reps: int = BOOTSTRAP_REPS, confidence: float = CONFIDENCE,
                 seed: int = BOOTSTRAP_SEED) -> Interval:
    """The IQM of ``scores`` and its stratified-bootstrap percentile interval."""
    scores = as_scores(scores)
    rng = np.random.default_rng(seed)
    values = np.concatenate([
        _trim_mean(_resample(rng, scores, chunk).reshape(chunk, -1), axis=1)
        for chunk in _chunks(reps, scores.size)])
    return _percentile_interval(iqm(scores), values, confidence)


def improvement_interval(x: Sequence[float] | np.ndarray, y: Sequence[float] | np.ndarray,
                         reps: int = BOOTSTRAP_REPS, confidence: float = CONFIDENCE,
                         seed: int = BOOTSTRAP_SEED) -> Interval:
    """``P(X > Y)`` and its interval, X and Y resampled independently (each stratified by task)."""
    x, y = as_scores(x), as_scores(y)
    rng = np.random.default_rng(seed)
    values = np.concatenate([
        _improvement(_resample(rng, x, chunk), _resample(rng, y, chunk))
        for chunk in _chunks(reps, x.shape[0] * y.shape[0] * x.shape[1])])
    return _percentile_interval(probability_of_improvement(x, y), values, confidence)


@dataclass(frozen=True)
class MilestoneEstimates:
    """IQM per strategy and milestone, and the reference's probability of improvement over each other strategy."""

    steps: list[int]
    runs: dict[str, dict[int, int]]  # strategy -> step -> runs that reached it
    iqm: dict[str, dict[int, Interval | None]]  # strategy -> step -> IQM (None: no run reached it)
    improvement: dict[str, dict[int, Interval | None]]  # other strategy -> step -> P(reference > it)
    reference: str | None  # None: no probability of improvement (no reference runs, or no other strategy)
    confidence: float
    reps: int

    def fewest_runs(self) -> int:
        """The fewest runs behind any estimate (0 when there is none)."""
        counts = [n for per_step in self.runs.values() for n in per_step.values() if n > 0]
        return min(counts, default=0)


def milestone_estimates(values: Mapping[str, Mapping[int, Sequence[float]]], reference: str | None,
                        reps: int = BOOTSTRAP_REPS, confidence: float = CONFIDENCE,
                        seed: int = BOOTSTRAP_SEED) -> MilestoneEstimates:
    """The estimates of ``values`` (strategy -> milestone step -> one score per run: ``MilestoneTable.values``).

    Each milestone is one task with one score per run; ``reference`` (or None
    for none) is compared with every other strategy at each step both reached.
    """
    steps = sorted({step for per_step in values.values() for step in per_step})
    runs = {strategy: {step: len(per_step.get(step, ())) for step in steps} for strategy, per_step in values.items()}
    iqms = {strategy: {step: (iqm_interval(per_step[step], reps, confidence, seed) if per_step.get(step) else None)
                       for step in steps}
            for strategy, per_step in values.items()}
    has_reference = reference is not None and reference in values and len(values) > 1
    improvement: dict[str, dict[int, Interval | None]] = {}
    if has_reference:
        mine = values[reference]
        for strategy, per_step in values.items():
            if strategy == reference:
                continue
            improvement[strategy] = {
                step: (improvement_interval(mine[step], per_step[step], reps, confidence, seed)
                       if mine.get(step) and per_step.get(step) else None)
                for step in steps}
    return MilestoneEstimates(steps, runs, iqms, improvement, reference if has_reference else None, confidence, reps)


def few_seeds_note(fewest_runs: int, confidence: float = CONFIDENCE) -> str:
    """What estimates over as few as ``fewest_runs`` runs of one task can and cannot say; '' for 4 runs or more."""
    if not 0 < fewest_runs < 4:
        return ""
    repeat = float(fewest_runs) ** -fewest_runs
    if fewest_runs == 1:
        notes = ["with 1 run a strategy's IQM is that run and its interval the run itself: no estimate yet"]
    else:
        notes = [f"with {fewest_runs} runs the IQM trims none (it cuts int(n/4) from each end) and is the mean"]
    if 1 < fewest_runs and repeat > (1 - confidence) / 2:
        notes.append(f"a resample repeating one run {fewest_runs} times has probability {fewest_runs}^-{fewest_runs} "
                     f"= {repeat:.1%}, above {(1 - confidence) / 2:.1%}, so the {confidence:.0%} interval of the IQM "
                     "is the runs' min to max: it shows how far apart the seeds are, not a precise estimate")
    notes.append("the percentile bootstrap draws only the values observed, so at this few runs of a single task "
                 "(rliable's intervals lean on pooling many tasks) its intervals are if anything too narrow: a "
                 "probability of improvement whose interval excludes 0.5 is weak evidence, to be read beside "
                 "Welch's p")
    return f"Few seeds: {'; '.join(notes)}."

"""The paper's figures from recorded runs, as PNG files (matplotlib, Agg backend).

- :func:`plot_learned_vs_steps`: learned objects vs training steps, mean and spread over seeds (Fig. 4).
- :func:`plot_milestone_violins`: learned objects at each milestone, Welch p vs GloCAL (Fig. 5).
- :func:`plot_milestone_estimates`: IQM with its bootstrap interval per strategy at each milestone, and the
  reference's probability of improvement over each other strategy (rliable's statistics).
- :func:`plot_learned_grid`: the 7x7 object grid, fraction of seeds that learned each object (Fig. 7).
- :func:`plot_timeline`: one run's iterations with global (*) and local tasks, learned ticked (Fig. 3).

Each function draws one file and closes its figure, so a report of many runs
does not accumulate open figures.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import matplotlib

matplotlib.use("Agg")  # files only: no display, and no GUI toolkit needed on a headless machine

import matplotlib.pyplot as plt  # noqa: E402 - after choosing the backend
import numpy as np  # noqa: E402
from matplotlib.figure import Figure  # noqa: E402
from matplotlib.ticker import FuncFormatter  # noqa: E402

from glocal_ros.analysis.estimates import Interval, MilestoneEstimates  # noqa: E402
from glocal_ros.analysis.runs import (  # noqa: E402
    MilestoneTable,
    RunData,
    format_steps,
    learned_curve_band,
)
from glocal_ros.tasks import ALL_TASKS, COMPLEXITY_LEVELS, DIFFICULTY_LEVELS, NUM_TASKS, grid_coordinates  # noqa: E402

DPI = 120
SIGNIFICANCE = 0.05
GLOBAL_COLOR = "#e377c2"  # the paper highlights global tasks pink, local tasks blue, learned green
LOCAL_COLOR = "#1f77b4"
LEARNED_COLOR = "#2ca02c"

# Fixed colours, so a strategy looks the same in every figure and every report.
_STRATEGY_COLORS = {
    "glocal": "#d62728",
    "random": "#7f7f7f",
    "alp_gmm_250": "#1f77b4",
    "alp_gmm_10": "#ff7f0e",
    "glocal_no_global": "#9467bd",
    "glocal_random_cluster": "#8c564b",
}
_EXTRA_COLORS = ("#17becf", "#bcbd22", "#e377c2", "#2ca02c", "#aec7e8", "#98df8a")


def strategy_colors(strategies: Sequence[str]) -> dict[str, str]:
    """A colour per strategy: the paper's strategies fixed, others from a spare palette."""
    colors, extra = {}, iter(_EXTRA_COLORS * (1 + len(strategies) // len(_EXTRA_COLORS)))
    for strategy in strategies:
        colors[strategy] = _STRATEGY_COLORS.get(strategy) or next(extra)
    return colors


def _steps_axis(ax) -> None:
    ax.xaxis.set_major_formatter(FuncFormatter(lambda x, _: format_steps(int(x)) if x >= 0 else ""))


def _save(fig: Figure, path: Path) -> Path:
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=DPI, bbox_inches="tight")
    plt.close(fig)
    return path


def format_p(p: float | None) -> str:
    """'p=0.012*' (starred below SIGNIFICANCE), 'p<0.001*', or 'n/a' when there is no test."""
    if p is None:
        return "n/a"
    star = "*" if p < SIGNIFICANCE else ""
    return f"p<0.001{star}" if p < 0.001 else f"p={p:.3f}{star}"


def _task_total(groups: dict[str, list[RunData]]) -> int:
    return max((len(run.tasks) for runs in groups.values() for run in runs), default=NUM_TASKS)


def plot_learned_vs_steps(groups: dict[str, list[RunData]], path: Path, band: str = "minmax") -> Path:
    """Mean learned objects vs training steps per strategy, with a min-max (or +-std) band over seeds."""
    if band not in ("minmax", "std"):
        raise ValueError(f"band must be 'minmax' or 'std', not {band!r}")
    colors = strategy_colors(list(groups))
    fig, ax = plt.subplots(figsize=(7, 4.5))
    for strategy, runs in groups.items():
        steps, mean, std, low, high = learned_curve_band(runs)
        color = colors[strategy]
        ax.step(steps, mean, where="post", color=color, lw=2, label=f"{strategy} (n={len(runs)})")
        if len(runs) > 1:
            lower, upper = (low, high) if band == "minmax" else (mean - std, mean + std)
            ax.fill_between(steps, lower, upper, step="post", color=color, alpha=0.2, lw=0)
    total = _task_total(groups)
    ax.axhline(total, color="black", ls=":", lw=1)
    ax.set_ylim(0, total + 2)
    ax.set_xlim(left=0)
    _steps_axis(ax)
    ax.set_xlabel("training steps")
    ax.set_ylabel(f"learned objects (of {total})")
    spread = "min-max" if band == "minmax" else "±1 std"
    ax.set_title(f"Learned objects vs training steps (mean, {spread} over seeds)")
    ax.grid(alpha=0.3)
    ax.legend(loc="lower right", fontsize=8)
    return _save(fig, path)


def plot_milestone_violins(table: MilestoneTable, path: Path, total_tasks: int = NUM_TASKS) -> Path | None:
    """One panel per milestone: violins of learned objects per strategy, p of Welch's t-test vs the reference.

    Groups with fewer than two distinct values have no density to draw and
    show only their points. Returns None when no run reached a milestone.
    """
    if not table.steps:
        return None
    strategies = list(table.values)
    colors = strategy_colors(strategies)
    rng = np.random.default_rng(0)  # jitter of the seed dots; fixed so the figure is reproducible
    fig, axes = plt.subplots(1, len(table.steps), figsize=(1.2 + 0.9 * len(strategies) * len(table.steps), 4.8),
                             sharey=True, squeeze=False)
    for ax, step in zip(axes[0], table.steps):
        for position, strategy in enumerate(strategies, start=1):
            values = np.asarray(table.values[strategy].get(step, []), dtype=float)
            if values.size == 0:
                continue
            if np.unique(values).size > 1:
                parts = ax.violinplot([values], positions=[position], widths=0.8, showmeans=True,
                                      showextrema=True)
                for body in parts["bodies"]:
                    body.set_facecolor(colors[strategy])
                    body.set_alpha(0.35)
                for key in ("cmeans", "cmins", "cmaxes", "cbars"):
                    parts[key].set_color(colors[strategy])
            ax.scatter(position + rng.uniform(-0.08, 0.08, values.size), values, s=12, color=colors[strategy],
                       zorder=3)
            if table.reference is not None and strategy != table.reference:
                p = table.p_values[strategy][step]
                ax.text(position, values.max() + 1.0, format_p(p), ha="center", va="bottom", fontsize=7,
                        fontweight="bold" if p is not None and p < SIGNIFICANCE else "normal")
        ax.set_xticks(range(1, len(strategies) + 1), strategies, rotation=45, ha="right", fontsize=8)
        ax.set_xlim(0.4, len(strategies) + 0.6)
        ax.set_title(f"{format_steps(step)} steps")
        ax.grid(axis="y", alpha=0.3)
    axes[0][0].set_ylim(0, total_tasks + 4)
    axes[0][0].set_ylabel("learned objects")
    note = (f"Welch's t-test p vs {table.reference}; * p < {SIGNIFICANCE}" if table.reference is not None
            else "no t-test: a single strategy, or no reference strategy")
    fig.suptitle(f"Learned objects at each milestone ({note})", fontsize=10)
    return _save(fig, path)


def _interval_bars(ax, xs: np.ndarray, intervals: Sequence[Interval | None], color: str, label: str) -> None:
    """One strategy's points with their intervals as error bars, at ``xs``; None: nothing drawn there."""
    drawn = [(x, interval) for x, interval in zip(xs, intervals) if interval is not None]
    if not drawn:
        return
    points = np.array([[i.point, i.point - i.low, i.high - i.point] for _, i in drawn])
    ax.errorbar([x for x, _ in drawn], points[:, 0], yerr=points[:, 1:].T, fmt="o", color=color, ms=5, capsize=3,
                lw=1.5, label=label)


def plot_milestone_estimates(estimates: MilestoneEstimates, path: Path, total_tasks: int = NUM_TASKS) -> Path | None:
    """Top: IQM of learned objects per strategy at each milestone with its interval; below (when there is a
    reference): its probability of improvement over each other strategy with its interval, 0.5 dashed.

    Strategies are side by side within each milestone. Returns None when no run reached a milestone.
    """
    if not estimates.steps:
        return None
    strategies = list(estimates.iqm)
    colors = strategy_colors(strategies)
    panels = 2 if estimates.reference is not None else 1
    width = max(6.0, 1.5 + 0.3 * len(strategies) * len(estimates.steps))
    fig, axes = plt.subplots(panels, 1, figsize=(width, 3.8 * panels), squeeze=False)
    positions = np.arange(len(estimates.steps))
    labels = [format_steps(step) for step in estimates.steps]

    def offsets(count: int) -> np.ndarray:
        return (np.arange(count) - (count - 1) / 2) * min(0.8 / max(count, 1), 0.15)

    ax = axes[0][0]
    for offset, strategy in zip(offsets(len(strategies)), strategies):
        _interval_bars(ax, positions + offset, [estimates.iqm[strategy][step] for step in estimates.steps],
                       colors[strategy], f"{strategy} (n={max(estimates.runs[strategy].values())})")
    ax.set_xticks(positions, labels)
    ax.set_xlabel("training steps (milestone)")
    ax.set_ylabel(f"IQM of learned objects (of {total_tasks})")
    ax.set_ylim(-0.5, total_tasks + 1)
    ax.set_title(f"IQM, {estimates.confidence:.0%} stratified bootstrap interval", fontsize=10)
    ax.grid(axis="y", alpha=0.3)
    ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=8)
    if estimates.reference is not None:
        ax = axes[1][0]
        others = list(estimates.improvement)
        for offset, strategy in zip(offsets(len(others)), others):
            _interval_bars(ax, positions + offset, [estimates.improvement[strategy][step] for step in estimates.steps],
                           colors[strategy], f"over {strategy}")
        ax.axhline(0.5, color="black", ls="--", lw=1)
        ax.set_xticks(positions, labels)
        ax.set_xlabel("training steps (milestone)")
        ax.set_ylabel(f"P({estimates.reference} > strategy)")
        ax.set_ylim(-0.05, 1.05)
        ax.set_title(f"Probability of improvement of {estimates.reference}, {estimates.confidence:.0%} interval",
                     fontsize=10)
        ax.grid(axis="y", alpha=0.3)
        ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=8)
    fewest = estimates.fewest_runs()
    fig.suptitle(f"rliable's statistics over seeds ({estimates.reps:,} bootstrap resamples; as few as {fewest} "
                 f"seed{'s' if fewest != 1 else ''} per estimate)", fontsize=10)
    fig.tight_layout()
    return _save(fig, path)


def learned_fraction_grid(runs: Sequence[RunData]) -> np.ndarray:
    """7x7 (difficulty A..G x complexity 0..6): fraction of ``runs`` having the task that learned it.

    NaN where no run had the task.
    """
    had = np.zeros((len(DIFFICULTY_LEVELS), len(COMPLEXITY_LEVELS)))
    learned = np.zeros_like(had)
    for run in runs:
        run_learned = set(run.learned_tasks)
        for task in run.tasks:
            if task not in ALL_TASKS:
                continue
            row, col = grid_coordinates(task)
            had[row, col] += 1
            learned[row, col] += task in run_learned
    with np.errstate(invalid="ignore"):
        return np.where(had > 0, learned / np.maximum(had, 1), np.nan)


def plot_learned_grid(groups: dict[str, list[RunData]], path: Path) -> Path:
    """One 7x7 panel per strategy: the fraction of seeds that learned each object; objects not in the runs grey."""
    cmap = matplotlib.colormaps["Greens"].with_extremes(bad="#d9d9d9")
    ncols = min(3, len(groups))
    nrows = -(-len(groups) // ncols)
    fig, axes = plt.subplots(nrows, ncols, figsize=(3.9 * ncols + 1.0, 3.9 * nrows + 0.4), squeeze=False,
                             layout="constrained")
    image = None
    for ax, (strategy, runs) in zip(axes.flat, groups.items()):
        fractions = learned_fraction_grid(runs)
        image = ax.imshow(np.ma.masked_invalid(fractions), cmap=cmap, vmin=0, vmax=1)
        for (row, col), value in np.ndenumerate(fractions):
            task = DIFFICULTY_LEVELS[row] + COMPLEXITY_LEVELS[col]
            text = task if np.isnan(value) else f"{task}\n{value:.0%}"
            ax.text(col, row, text, ha="center", va="center", fontsize=6.5,
                    color="white" if not np.isnan(value) and value > 0.6 else "black")
        mean_learned = np.mean([len(run.learned_tasks) for run in runs])
        ax.set_title(f"{strategy} (n={len(runs)}): {mean_learned:.1f}/{len(runs[0].tasks)} learned", fontsize=9)
        ax.set_xticks(range(len(COMPLEXITY_LEVELS)), list(COMPLEXITY_LEVELS))
        ax.set_yticks(range(len(DIFFICULTY_LEVELS)), list(DIFFICULTY_LEVELS))
        ax.set_xlabel("shape complexity")
        ax.set_ylabel("grasp difficulty")
    for ax in list(axes.flat)[len(groups):]:
        ax.set_visible(False)
    if image is not None:
        fig.colorbar(image, ax=axes.ravel().tolist(), shrink=0.6, label="fraction of seeds that learned it")
    fig.suptitle("Objects learned by the end of each run (grey: not a task of the run)", fontsize=10)
    return _save(fig, path)


def plot_timeline(run: RunData, path: Path) -> Path | None:
    """The curriculum of one GloCAL-family run: tasks per iteration, global starred, learned ticked.

    Returns None when the run has no iteration with a global or local task.
    """
    records = [r for r in run.iteration_timeline() if r.tasks]
    if not records:
        return None
    appearing = {task for record in records for task in record.tasks}
    tasks = [t for t in ALL_TASKS if t in appearing] + sorted(appearing - set(ALL_TASKS))
    row = {task: i for i, task in enumerate(tasks)}
    fig, ax = plt.subplots(figsize=(max(6.0, 0.55 * len(records) + 3), max(3.0, 0.22 * len(tasks) + 1.5)))
    for record in records:
        x = record.iteration
        if record.global_task:
            ax.scatter(x, row[record.global_task], marker="*", s=160, color=GLOBAL_COLOR, zorder=3,
                       edgecolors="black", linewidths=0.4)
        ax.scatter([x] * len(record.local_tasks), [row[t] for t in record.local_tasks], marker="o", s=45,
                   color=LOCAL_COLOR, zorder=3)
        learned = [t for t in record.tasks if t in record.learned]
        ax.scatter([x + 0.28] * len(learned), [row[t] for t in learned], marker=r"$\checkmark$", s=60,
                   color=LEARNED_COLOR, zorder=4)
    # Legend entries drawn off-data, so the legend shows each kind once.
    ax.scatter([], [], marker="*", s=160, color=GLOBAL_COLOR, edgecolors="black", linewidths=0.4,
               label="global task (*)")
    ax.scatter([], [], marker="o", s=45, color=LOCAL_COLOR, label="local task")
    ax.scatter([], [], marker=r"$\checkmark$", s=60, color=LEARNED_COLOR, label="learned in this iteration")
    ax.set_yticks(range(len(tasks)), tasks, fontsize=7)
    ax.invert_yaxis()  # A0 (easiest) at the top, as on the object grid
    ax.set_xticks([r.iteration for r in records],
                  [f"{r.iteration}\n{format_steps(r.start_steps)}" for r in records], fontsize=7)
    ax.set_xlim(records[0].iteration - 0.7, records[-1].iteration + 0.9)
    ax.set_xlabel("iteration (total steps at its start)")
    ax.set_ylabel("task")
    ax.grid(alpha=0.25)
    ax.set_title(f"Curriculum of {run.label}: {len(records)} iterations, "
                 f"{len(run.learned_tasks)}/{len(run.tasks)} learned", fontsize=10)
    ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=8)
    return _save(fig, path)

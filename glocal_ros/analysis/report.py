"""``glocal-ros report RUN_DIR... --out DIR``: figures and a markdown summary of recorded runs.

Reads bags only (never a live graph): each RUN_DIR's ``bag/``, ``bag.1/``...
The report has the runs table, learned objects at each milestone per strategy
with Welch's t-test p against GloCAL, the interquartile mean with its 95%
stratified bootstrap interval and GloCAL's probability of improvement over
each other strategy (rliable's statistics, ``glocal_ros.analysis.estimates``),
the paper's figures (learned vs steps, milestone violins, object grid,
curriculum timelines) with one of those estimates, and the list of bags read.
"""

from __future__ import annotations

import argparse
import shlex
import sys
from collections.abc import Iterable, Sequence
from pathlib import Path

from glocal_ros.analysis.estimates import Interval, MilestoneEstimates, few_seeds_note, milestone_estimates
from glocal_ros.analysis.runs import (
    CURRICULUM_STATE_TOPIC,
    REFERENCE_STRATEGY,
    MilestoneTable,
    RunData,
    format_steps,
    group_by_strategy,
    is_glocal_family,
    milestone_table,
    read_runs,
)
from glocal_ros.recording import table_topic
from glocal_ros.topics import EPISODES_TOPIC

REPORT_NAME = "report.md"
LEARNED_VS_STEPS_PNG = "learned_vs_steps.png"
MILESTONES_PNG = "milestones_violin.png"
GRID_PNG = "learned_grid.png"
ESTIMATES_PNG = "milestones_iqm.png"


def timeline_png(run: RunData) -> str:
    return f"timeline_{run.strategy}_seed{'unknown' if run.seed is None else run.seed}.png"


def markdown_table(header: Sequence[str], rows: Iterable[Sequence[object]]) -> list[str]:
    lines = ["| " + " | ".join(header) + " |", "|" + "|".join("---" for _ in header) + "|"]
    lines += ["| " + " | ".join(str(cell) for cell in row) + " |" for row in rows]
    return lines


def _episodes_cell(run: RunData) -> str:
    if run.episodes is None:
        return "-"
    return f"{run.episodes.train}/{run.episodes.eval} ({run.episodes.complete})"


def runs_section(runs: Sequence[RunData]) -> list[str]:
    rows = [
        (run.run_dir, run.strategy, "?" if run.seed is None else run.seed,
         f"{run.total_steps:,}" + (f" / {run.step_budget:,}" if run.step_budget else ""),
         f"{len(run.learned_tasks)}/{len(run.tasks)}", run.iterations, "yes" if run.finished else "no",
         _episodes_cell(run), len(run.bags_read) + len(run.bags_skipped))
        for run in runs
    ]
    return ["## Runs", "",
            *markdown_table(("run", "strategy", "seed", "steps / budget", "learned", "iterations", "finished",
                     "episodes train/eval (not interrupted)", "bags"), rows), ""]


def final_section(groups: dict[str, list[RunData]]) -> list[str]:
    rows = []
    for strategy, runs in groups.items():
        learned = [len(run.learned_tasks) for run in runs]
        mean = sum(learned) / len(learned)
        std = (sum((x - mean) ** 2 for x in learned) / (len(learned) - 1)) ** 0.5 if len(learned) > 1 else 0.0
        evaluations = [run.evaluation_episodes for run in runs]
        rows.append((strategy, len(runs), f"{mean:.1f} ± {std:.1f}", min(learned), max(learned),
                     f"{sum(run.finished for run in runs)}/{len(runs)}",
                     f"{sum(run.total_steps for run in runs) / len(runs):,.0f}",
                     "-" if None in evaluations else f"{sum(evaluations) / len(evaluations):,.0f}"))
    return ["## Learned objects at the end of each run", "",
            *markdown_table(("strategy", "seeds", "learned (mean ± std)", "min", "max", "finished",
                     "training steps (mean)", "evaluation episodes (mean)"), rows),
            "", "Evaluation episodes are not charged to the training-step budget (the paper's comparison "
            "is at equal training timesteps); -: a run's states predate the count.", ""]


def _stats_cell(table: MilestoneTable, strategy: str, step: int) -> str:
    stats = table.stats(strategy, step)
    if stats is None:
        return "-"
    mean, std, n = stats
    return f"{mean:.1f} ± {std:.1f} (n={n})" if n > 1 else f"{mean:.0f} (n=1)"


def p_value_cell(p: float | None) -> str:
    if p is None:
        return "n/a"
    return (f"{p:.2e}" if p < 0.001 else f"{p:.3f}") + ("*" if p < 0.05 else "")


def milestones_section(table: MilestoneTable) -> list[str]:
    lines = ["## Learned objects at each milestone", ""]
    if not table.steps:
        return lines + ["No run reached a milestone.", ""]
    header = ("strategy", *(format_steps(step) for step in table.steps))
    lines += markdown_table(header, ((s, *(_stats_cell(table, s, step) for step in table.steps)) for s in table.values))
    lines.append("")
    lines.append("Mean ± sample standard deviation over the seeds that reached the milestone.")
    lines.append("")
    return lines + p_value_section(table, table.steps)


def p_value_section(table: MilestoneTable, steps: Sequence[int]) -> list[str]:
    """Welch's t-test of the reference strategy against each other one, at ``steps``: a heading and a table."""
    if table.reference is None:
        return ["No t-test: it needs runs of `glocal` and of at least one other strategy.", ""]
    lines = [f"### Welch's t-test, {table.reference} vs each strategy (two-sided p; * p < 0.05)", ""]
    lines += markdown_table(("strategy", *(format_steps(step) for step in steps)),
                            ((s, *(p_value_cell(p.get(step)) for step in steps)) for s, p in table.p_values.items()))
    return lines + ["", "n/a: a group has fewer than 2 seeds at that milestone, or both are constant and equal.", ""]


def improvement_cell(interval: Interval | None) -> str:
    """``'0.56 [0.00, 1.00]'``, starred when the interval excludes 0.5 (no difference); ``-`` without one."""
    if interval is None:
        return "-"
    return interval.cell(2) + ("*" if interval.low > 0.5 or interval.high < 0.5 else "")


def estimates_section(estimates: MilestoneEstimates, steps: Sequence[int]) -> list[str]:
    """The IQM of each strategy with its interval, and the reference's probability of improvement, at ``steps``."""
    confidence = f"{estimates.confidence:.0%}"
    lines = [f"### Interquartile mean with {confidence} stratified bootstrap interval (rliable)", ""]
    rows = []
    for strategy, per_step in estimates.iqm.items():
        seeds = max(estimates.runs[strategy].values(), default=0)
        cells = []
        for step in steps:
            interval, n = per_step.get(step), estimates.runs[strategy].get(step, 0)
            cells.append("-" if interval is None else interval.cell() + (f" (n={n})" if n != seeds else ""))
        rows.append((strategy, seeds, *cells))
    lines += markdown_table(("strategy", "seeds", *(format_steps(step) for step in steps)), rows)
    lines += ["", "IQM [low, high]: the mean of the middle 50% of the seeds' learned objects (rliable's "
              f"`aggregate_iqm`), and its {confidence} percentile interval over {estimates.reps:,} resamples of the "
              "seeds (seeded: the same runs give the same table).", ""]
    note = few_seeds_note(estimates.fewest_runs(), estimates.confidence)
    few_seeds = [note, ""] if note else []
    if estimates.reference is None:
        return lines + [f"No probability of improvement: it needs runs of `{REFERENCE_STRATEGY}` and of at least "
                        "one other strategy.", "", *few_seeds]
    lines += [f"### Probability of improvement of {estimates.reference} over each strategy, {confidence} interval "
              "(* the interval excludes 0.5)", ""]
    lines += markdown_table(("strategy", *(format_steps(step) for step in steps)),
                            ((strategy, *(improvement_cell(per_step.get(step)) for step in steps))
                             for strategy, per_step in estimates.improvement.items()))
    return lines + ["", f"P({estimates.reference} > strategy): over every pair of a {estimates.reference} seed and "
                    "a seed of the strategy, the share in which it learned more, a tie counting 1/2 (rliable's "
                    "`probability_of_improvement`); 0.5 is no difference either way. Both sides are resampled "
                    "independently for the interval.", "", *few_seeds]


def timeline_section(run: RunData) -> list[str]:
    records = run.iteration_timeline()
    rows = [(r.iteration, f"{r.start_steps:,}", r.global_task or "-", ", ".join(r.local_tasks) or "-",
             ", ".join(t for t in r.tasks if t in r.learned) or "-") for r in records]
    return [f"### Curriculum of {run.label}", "",
            *markdown_table(("iteration", "steps at start", "global task", "local tasks", "learned in it"), rows), ""]


def _count(run: RunData, table_name: str) -> int:
    """Messages of the table's topic ``table_name`` in ``run``'s bags, under whatever namespace they were recorded."""
    return sum(count for topic, count in run.message_counts.items()
               if (spec := table_topic(topic)) is not None and spec.name == table_name)


def bags_section(runs: Sequence[RunData], unread: Sequence[Path]) -> list[str]:
    lines = ["## Bags", ""]
    for run in runs:
        for bag in run.bags_read:
            lines.append(f"- `{bag}`")
        for bag, reason in run.bags_skipped:
            lines.append(f"- `{bag}`: **skipped** ({reason})")
    lines += [f"- `{run_dir}`: **no run read** (see the warnings)" for run_dir in unread]
    total_states = sum(_count(run, CURRICULUM_STATE_TOPIC) for run in runs)
    total_episodes = sum(_count(run, EPISODES_TOPIC) for run in runs)
    lines += ["", f"{total_states} curriculum states and {total_episodes} episode records in the bags read.", ""]
    return lines


def write_report(run_dirs: Sequence[Path], out_dir: Path, count_episodes: bool = True,
                 all_timelines: bool = False) -> Path:
    """Read the runs of ``run_dirs``, write the figures and ``report.md`` to ``out_dir``; return the markdown's path.

    ``count_episodes=False`` skips decoding /glocal/episodes, the slow part of a
    long run. Timelines are drawn for the first seed of each GloCAL-family
    strategy, or for every such run with ``all_timelines``.
    Raises ValueError when none of ``run_dirs`` holds a readable run.
    """
    from glocal_ros.analysis import figures  # matplotlib: only when a report is written

    run_dirs = [Path(d) for d in run_dirs]
    runs = read_runs(run_dirs, count_episodes=count_episodes)
    if not runs:
        raise ValueError(f"no readable run in {', '.join(map(str, run_dirs))}")
    unread = [d for d in run_dirs if d not in {run.run_dir for run in runs}]
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    groups = group_by_strategy(runs)
    table = milestone_table(groups)
    estimates = milestone_estimates(table.values, table.reference)
    total_tasks = max(len(run.tasks) for run in runs)

    made: list[tuple[str, Path | None]] = [
        ("Learned objects vs training steps (Fig. 4)",
         figures.plot_learned_vs_steps(groups, out_dir / LEARNED_VS_STEPS_PNG)),
        ("Learned objects at each milestone, p vs glocal (Fig. 5)",
         figures.plot_milestone_violins(table, out_dir / MILESTONES_PNG, total_tasks)),
        (f"IQM and probability of improvement at each milestone, {estimates.confidence:.0%} intervals (rliable)",
         figures.plot_milestone_estimates(estimates, out_dir / ESTIMATES_PNG, total_tasks)),
        ("Objects learned per strategy (Fig. 7)", figures.plot_learned_grid(groups, out_dir / GRID_PNG)),
    ]
    timeline_runs = [run for strategy, group in groups.items() if is_glocal_family(strategy)
                     for run in (group if all_timelines else group[:1])]
    drawn_timelines = []
    for run in timeline_runs:
        path = figures.plot_timeline(run, out_dir / timeline_png(run))
        made.append((f"Curriculum of {run.label} (Fig. 3)", path))
        if path is not None:
            drawn_timelines.append(run)

    lines = ["# GloCAL report", "",
             f"`glocal-ros report {' '.join(shlex.quote(str(d)) for d in run_dirs)}`: {len(runs)} run(s) of "
             f"{len(groups)} strateg{'y' if len(groups) == 1 else 'ies'}.", ""]
    lines += runs_section(runs)
    lines += final_section(groups)
    lines += milestones_section(table)
    if table.steps:
        lines += estimates_section(estimates, table.steps)
    lines += ["## Figures", ""]
    for title, path in made:
        lines.append(f"- [{title}]({path.name})" if path is not None else f"- {title}: nothing to draw")
    lines.append("")
    for title, path in made:
        if path is not None:
            lines += [f"![{title}]({path.name})", ""]
    if drawn_timelines:
        lines += ["## Curriculum timelines", ""]
        for run in drawn_timelines:
            lines += timeline_section(run)
    lines += bags_section(runs, unread)

    report = out_dir / REPORT_NAME
    report.write_text("\n".join(lines))
    return report


def cmd_report(args: argparse.Namespace) -> int:
    out = args.out if args.out is not None else args.run_dirs[0] / "report"
    report = write_report(args.run_dirs, out, count_episodes=not args.no_episodes, all_timelines=args.all_timelines)
    print(report)
    sys.stdout.flush()
    return 0


def add_report_command(commands) -> None:
    """Register ``report`` on the ``glocal-ros`` subparsers ``commands``."""
    report = commands.add_parser("report", help="figures and a markdown summary of recorded runs (reads bags only)")
    report.add_argument("run_dirs", nargs="+", type=Path, help="run directories, each with bag/ (and bag.1/...)")
    report.add_argument("--out", type=Path, default=None, help="output directory (default: FIRST_RUN_DIR/report)")
    report.add_argument("--no-episodes", action="store_true",
                        help="do not decode /glocal/episodes (faster on long runs; no episode counts)")
    report.add_argument("--all-timelines", action="store_true",
                        help="a timeline for every GloCAL-family run, not only the first seed of each strategy")
    report.set_defaults(func=cmd_report)

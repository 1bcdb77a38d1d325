"""``glocal-ros bench curriculum``: the paper's comparison, every strategy side by side on the real simulation.

Underneath is ``glocal-ros experiment``: each strategy x seed is one run of
the whole graph (recorder, sim, learner and curriculum nodes) into
``OUT/<strategy>-seed<N>/``, all from the same prior, on the same tasks, at
the same training-step budget (the preset's, or ``--budget``). Finished runs
are kept and interrupted ones resumed, so the same command continues a bench
that was stopped, and ``--strategies`` / ``--seeds`` run parts of it.

The table is read from the bags alone (``glocal_ros.analysis``), of every
run directory under OUT and of those given with ``--merge`` (run directories,
or other benches' OUT): runs made on other days or machines are tabulated
together, provided they share the tasks and the budget. It has:

- learned objects per strategy at each milestone: mean and (min-max) over
  seeds, and Welch's two-sided t-test of GloCAL against each strategy;
- at each milestone, the interquartile mean with its 95% stratified bootstrap
  interval per strategy and GloCAL's probability of improvement over each
  other strategy with its interval (rliable's statistics, as ``glocal-ros
  report`` has them: ``glocal_ros.analysis.estimates``);
- the ratios GloCAL / random and GloCAL / each ALP-GMM at each milestone
  (equal training budget: evaluation episodes are not charged to it, as in
  the paper), of the means over seeds;
- per strategy: runs finished, evaluation episodes, training steps and the
  curriculum's wall-clock (its first state to its last, per bag);
- the paper's numbers at 4M steps beside the shares learned here;
- the report's figures (``glocal-ros report`` over the same runs, written
  beside the table in ``curriculum/``).

Before any node starts, ``check_bench`` refuses unknown strategies, a budget
below one evaluation, and an OUT or KEEP that holds runs of other settings
(another preset or budget): they would be mixed into the table.

Kept runs. A bench takes hours and OUT (tens of megabytes per run, in
``runs/``) is not something to commit. Each finished run is therefore kept,
as it finishes, in KEEP (by default beside the table: ``curriculum.md`` ->
``curriculum-runs/``): its ``run.json``, its curriculum state and its bags
reduced to the curriculum's and the learner's topics (``KEPT_TOPICS``, a few
hundred kilobytes), which is all the table and the report's figures read, and
the code that made it (``glocal_app.provenance``), which the table names.
A run resumed after its launch was killed (a session's end) has a bag the
recorder never closed; keeping the run repairs that bag first, as
``glocal-ros bag repair`` does, so the bench goes on instead of stopping.
A bench started where OUT lacks a kept run copies it into OUT first, so it
counts as finished and is not run again: commit KEEP, and a bench stopped on
one machine goes on from its last finished run on another.
"""

from __future__ import annotations

import shutil
import statistics
import tempfile
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Sequence

from glocal_app.processes import RUN_FILE, STATE_FILE, RunOptions, preset_parameters, recorded_run_settings
from glocal_app.provenance import CODE_FILE, describe_code, run_code_versions
from glocal_ros import topics
from glocal_ros.tasks import NUM_TASKS

if TYPE_CHECKING:
    from glocal_ros.analysis.runs import RunData

#: The preset the bench runs by default: 16 objects; six strategies x 3 seeds took 65 minutes on 2 cores.
BENCH_PRESET = "bench"
DEFAULT_OUT = Path("runs/bench-curriculum")
DEFAULT_RESULTS = Path("bench/results/curriculum.md")
#: The strategies GloCAL's ratios are taken against: the paper's baselines.
BASELINES = ("random", "alp_gmm_250", "alp_gmm_10")
#: The paper's learned objects of 49 at 4M training steps (Fig. 6 and 7, and the ablations' text).
PAPER_LEARNED_AT_4M = {"glocal": 49, "random": 41, "alp_gmm_250": 41, "alp_gmm_10": 42, "glocal_no_global": 39,
                       "glocal_random_cluster": 10}


#: What a kept run's bags hold: what the table and the figures read (the curriculum's state and
#: assignments), and the learner's evaluations and progress.
KEPT_TOPICS = (topics.CURRICULUM_STATE, topics.TASK_ASSIGNMENT, topics.EVALUATIONS, topics.TRAINING_PROGRESS)


def kept_runs_dir(results: Path) -> Path:
    """Where a bench keeps its finished runs unless told: beside its table (``curriculum.md`` -> ``curriculum-runs``)."""
    return results.with_name(f"{results.stem}-runs")


def bench_run_dirs(out: Path) -> list[Path]:
    """The run directories of a bench's OUT (each with a ``run.json``), or OUT itself when it is one run."""
    if (out / RUN_FILE).is_file():
        return [out]
    # A folder whose name starts with a dot is a copy being made (``keep_run``).
    return sorted(path.parent for path in out.glob(f"*/{RUN_FILE}") if not path.parent.name.startswith("."))


def check_bench(strategies: Sequence[str], seeds: Sequence[int], out: Path, options: RunOptions,
                keep: Path | None = None) -> None:
    """``ValueError`` for what ``experiment`` refuses, and for any run under OUT or ``keep`` of another preset,
    budget or learner profile."""
    from glocal_app.experiment import check_experiment

    check_experiment(strategies, seeds, out, options)
    wanted = (options.preset, options.step_budget, options.learner_profile)
    for run_dir in bench_run_dirs(out) + (bench_run_dirs(keep) if keep is not None else []):
        found = recorded_run_settings(run_dir) or {}
        if (found.get("preset"), found.get("step_budget"), found.get("learner_profile")) != wanted:
            raise ValueError(f"{run_dir} is a run of preset {found.get('preset')}, budget "
                             f"{found.get('step_budget') or 'of its preset'} and learner profile "
                             f"{_profile_of(found.get('preset'), found.get('learner_profile'))}, not of preset "
                             f"{options.preset}, budget {options.step_budget or 'of its preset'} and learner profile "
                             f"{_profile_of(options.preset, options.learner_profile)}: choose another --out or "
                             "--keep")


def _profile_of(preset: object, learner_profile: object) -> str:
    """A run's learner profile in words: the one it was given, or its preset's as the preset says now."""
    from learner_node.profiles import DEFAULT_PROFILE

    if learner_profile:
        return str(learner_profile)
    try:
        parameters = preset_parameters(str(preset), "learner_node")
    except (OSError, ValueError):
        return "of its preset"
    return f"{parameters.get('learner_profile', DEFAULT_PROFILE)} (its preset's)"


def read_bench_runs(run_dirs: Sequence[Path]) -> list[RunData]:
    """The runs of ``run_dirs``; ``ValueError`` when there is none, or they differ in tasks or budget."""
    from glocal_ros.analysis.runs import read_runs  # rosbags: not at the CLI's start

    runs = read_runs(run_dirs, count_episodes=False)
    if not runs:
        raise ValueError(f"no readable run in {', '.join(map(str, run_dirs)) or 'no directory'}")
    first = runs[0]
    for run in runs[1:]:
        if set(run.tasks) != set(first.tasks) or run.step_budget != first.step_budget:
            raise ValueError(f"{run.run_dir} ({len(run.tasks)} tasks, budget {run.step_budget:,}) and "
                             f"{first.run_dir} ({len(first.tasks)} tasks, budget {first.step_budget:,}) are not "
                             f"runs at equal settings: tabulate them apart")
    return runs


@dataclass(frozen=True)
class Spread:
    """Mean, min and max over seeds."""

    mean: float
    low: float
    high: float
    n: int

    @classmethod
    def of(cls, values: Sequence[float]) -> Spread | None:
        if not values:
            return None
        return cls(statistics.fmean(values), min(values), max(values), len(values))

    def cell(self, digits: int = 1) -> str:
        if self.n == 1:
            return f"{self.mean:.{digits}f} (n=1)"
        return f"{self.mean:.{digits}f} ({self.low:.{digits}f}-{self.high:.{digits}f})"


def _cell(spread: Spread | None, digits: int = 1) -> str:
    return "-" if spread is None else spread.cell(digits)


def _ratio(numerator: Spread | None, denominator: Spread | None) -> str:
    if numerator is None or denominator is None or denominator.mean == 0:
        return "-"
    return f"{numerator.mean / denominator.mean:.2f}x"


def curriculum_bench_report(runs: Sequence[RunData], command: str, figures_report: Path | None = None) -> str:
    """The markdown of ``bench/results/curriculum.md`` for ``runs`` (``read_bench_runs``).

    ``figures_report``: the ``report.md`` that ``glocal-ros report`` wrote over the same runs, in a
    folder beside the table; its figures are shown.
    """
    from glocal_ros.analysis.estimates import milestone_estimates
    from glocal_ros.analysis.report import (ESTIMATES_PNG, GRID_PNG, LEARNED_VS_STEPS_PNG, MILESTONES_PNG,
                                            estimates_section, markdown_table, p_value_section)
    from glocal_ros.analysis.runs import REFERENCE_STRATEGY, format_steps, group_by_strategy, milestone_table

    groups = group_by_strategy(runs)
    table = milestone_table(groups)
    tasks, budget = runs[0].tasks, runs[0].step_budget
    milestones = [step for step in table.steps if step <= budget]
    spread = {strategy: {step: Spread.of(table.values[strategy].get(step, [])) for step in milestones}
              for strategy in groups}
    presets = sorted({str((recorded_run_settings(run.run_dir) or {}).get("preset", "?")) for run in runs})
    lines = ["# bench curriculum: every strategy at one training budget, on the real simulation", "",
             f"Command: `{command}`  ",
             f"{len(runs)} runs of {len(groups)} strategies, preset {', '.join(presets)}; "
             f"{f'all {NUM_TASKS}' if len(tasks) == NUM_TASKS else len(tasks)} objects ({', '.join(tasks)}); "
             f"{budget:,} training steps per run, the same prior and tasks for every run. Learned: a score above "
             f"B in an evaluation (evaluation episodes are not charged to the budget, as in the paper). Runs "
             f"read: {', '.join(f'`{run.run_dir}`' for run in runs)}.", ""]

    lines += ["## Learned objects at each milestone", "",
              "Mean (min-max) over seeds; n = seeds that reached it.", ""]
    header = ("strategy", "seeds", *(format_steps(step) for step in milestones))
    lines += markdown_table(header, ((strategy, len(group), *(_cell(spread[strategy][step]) for step in milestones))
                                     for strategy, group in groups.items()))
    lines.append("")

    reference = spread.get(REFERENCE_STRATEGY)
    compared = [b for b in BASELINES if b in groups]
    if reference is not None and compared:
        lines += ["## GloCAL / baseline at equal budget (ratio of mean learned objects)", ""]
        lines += markdown_table(
            ("ratio", *(format_steps(step) for step in milestones)),
            ((f"glocal / {b}", *(_ratio(reference[step], spread[b][step]) for step in milestones)) for b in compared))
        lines.append("")
    lines += p_value_section(table, milestones)
    if milestones:
        within_budget = {strategy: {step: per_step[step] for step in milestones if step in per_step}
                         for strategy, per_step in table.values.items()}
        lines += estimates_section(milestone_estimates(within_budget, table.reference), milestones)

    lines += ["## Cost per strategy", ""]
    rows = []
    for strategy, group in groups.items():
        evaluations = [run.evaluation_episodes for run in group if run.evaluation_episodes is not None]
        seconds = [run.curriculum_seconds for run in group]
        rows.append((strategy, f"{sum(run.finished for run in group)}/{len(group)}",
                     _cell(Spread.of([len(run.learned_tasks) for run in group])),
                     _cell(Spread.of([run.total_steps for run in group]), 0),
                     _cell(Spread.of(evaluations), 0),
                     _cell(Spread.of([s / 60 for s in seconds])), f"{sum(seconds) / 60:.0f}"))
    lines += markdown_table(("strategy", "finished", "learned at the end", "training steps", "evaluation episodes",
                             "minutes per run", "minutes in all"), rows)
    lines += ["", "Minutes: the curriculum's wall-clock, its first state to its last (node start-up and the "
              "report not counted).", ""]

    lines += ["## Beside the paper (its 49 objects at 4M steps, 10 seeds)", ""]
    rows = []
    for strategy, group in groups.items():
        final = Spread.of([len(run.learned_tasks) for run in group])
        paper = PAPER_LEARNED_AT_4M.get(strategy)
        rows.append((strategy, "-" if paper is None else f"{paper}/{NUM_TASKS} ({paper / NUM_TASKS:.0%})",
                     f"{final.mean:.1f}/{len(tasks)} ({final.mean / len(tasks):.0%})"))
    lines += markdown_table(("strategy", "paper, learned at 4M", f"here, learned at {format_steps(budget)} (mean)"),
                            rows)
    lines.append("")

    lines += ["## The code of each run", "",
              "The commit this package ran from at each launch of the run (`RUN_DIR/code.jsonl`, "
              "`glocal_app.provenance`; a resumed run lists each; dirty: tracked files changed).", ""]
    lines += markdown_table(("run", "code"), ((run.run_dir.name, describe_code(run_code_versions(run.run_dir)))
                                              for run in runs))
    lines.append("")

    if figures_report is not None:
        figures_dir = figures_report.parent
        relative = figures_dir.name
        lines += ["## Figures", "", f"From `glocal-ros report` over the same runs: [{relative}/"
                  f"{figures_report.name}]({relative}/{figures_report.name}).", ""]
        for title, name in (("Learned objects vs training steps", LEARNED_VS_STEPS_PNG),
                            ("Learned objects at each milestone", MILESTONES_PNG),
                            ("IQM and probability of improvement at each milestone", ESTIMATES_PNG),
                            ("Objects learned per strategy", GRID_PNG)):
            if (figures_dir / name).is_file():
                lines += [f"![{title}]({relative}/{name})", ""]
    return "\n".join(lines)


def tabulate_curriculum_bench(run_dirs: Sequence[Path], command: str, results: Path) -> str:
    """Read ``run_dirs``, write the report's figures beside ``results`` and return the table's markdown."""
    from glocal_ros.analysis.report import write_report

    runs = read_bench_runs(run_dirs)
    figures_dir = results.with_suffix("")
    figures_report = write_report([run.run_dir for run in runs], figures_dir, count_episodes=False)
    return curriculum_bench_report(runs, command, figures_report)


def bench_inputs(out: Path, merge: Sequence[Path], keep: Path | None = None) -> list[Path]:
    """OUT's run directories, the runs kept in ``keep`` that OUT lacks, and those of ``merge`` (each a run
    directory or another bench's OUT), once each."""
    run_dirs = bench_run_dirs(out)
    if keep is not None:
        run_dirs += [d for d in bench_run_dirs(keep) if not (out / d.name).exists()]
    for source in merge:
        found = bench_run_dirs(source)
        if not found:
            raise ValueError(f"{source} holds no run (no run.json in it or its subdirectories)")
        run_dirs += [d for d in found if d.resolve() not in {r.resolve() for r in run_dirs}]
    return run_dirs


def keep_run(run_dir: Path, keep: Path) -> Path | None:
    """Keep the finished run ``run_dir`` in ``keep`` (see the module's docstring); None when it is kept already.

    The copy is made in a folder beside and renamed in, so a kept run is whole or absent. A bag of the run
    that was cut (a launch killed before it resumed: its recorder never closed the bag) is repaired first
    (``glocal_ros.bag_repair``, the original kept beside it); the run is finished, so no recorder writes it.
    """
    from glocal_ros.bag_repair import bag_is_intact, copy_topics, repair_bag
    from glocal_ros.analysis.runs import find_bags
    from glocal_ros.recording import table_topic

    destination = keep / run_dir.name
    if destination.exists():
        return None
    keep.mkdir(parents=True, exist_ok=True)
    staging = Path(tempfile.mkdtemp(prefix=f".{run_dir.name}.", dir=keep))
    try:
        shutil.copy2(run_dir / RUN_FILE, staging / RUN_FILE)
        if (run_dir / CODE_FILE).is_file():
            shutil.copy2(run_dir / CODE_FILE, staging / CODE_FILE)
        (staging / STATE_FILE).parent.mkdir(parents=True)
        shutil.copy2(run_dir / STATE_FILE, staging / STATE_FILE)
        for bag in find_bags(run_dir):
            if not bag_is_intact(bag):
                repaired = repair_bag(bag)
                print(f"{bag}: cut by a killed launch, repaired ({sum(repaired.counts.values())} messages; "
                      f"the original kept as {repaired.damaged})", flush=True)
            copy_topics(bag, staging / bag.name, lambda topic: table_topic(topic, KEPT_TOPICS) is not None)
        staging.rename(destination)
    except BaseException:
        shutil.rmtree(staging, ignore_errors=True)
        if destination.is_dir():  # another bench kept it meanwhile
            return None
        raise
    return destination


def keep_finished_runs(out: Path, keep: Path) -> list[Path]:
    """Keep every finished run of OUT that ``keep`` lacks; the copies made."""
    from glocal_app.launch import run_finished

    return [kept for run_dir in bench_run_dirs(out) if run_finished(run_dir)
            if (kept := keep_run(run_dir, keep)) is not None]


def restore_kept_runs(keep: Path, out: Path) -> list[Path]:
    """Copy into OUT the runs kept in ``keep`` that it lacks, so that they count as finished there."""
    restored = []
    for kept in bench_run_dirs(keep):
        if not (out / kept.name).exists():
            shutil.copytree(kept, out / kept.name)
            restored.append(out / kept.name)
    return restored

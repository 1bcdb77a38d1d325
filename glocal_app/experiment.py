"""``glocal-ros experiment``: strategies x seeds, each run a ``launch``, then one report over them all.

Runs go into ``OUT/<strategy>-seed<N>/``; runs already finished are skipped,
the others resumed. The launches run here one after another, or, with a Ray
address, as Ray tasks on a cluster (``glocal_app.ray_runs``); either way each
is ``launch_run``.
"""

from __future__ import annotations

from pathlib import Path
from typing import Callable, Iterator, Sequence

from glocal_app.exit_codes import EXIT_FAILED, EXIT_INTERRUPTED
from glocal_app.launch import launch, run_finished, write_run_report
from glocal_app.processes import RunOptions, check_run_dir
from glocal_ros.curriculum.codes import STRATEGY_NAMES

#: A run of an experiment: its strategy, seed and run directory (``experiment_runs``).
PlannedRun = tuple[str, int, Path]


def experiment_runs(strategies: Sequence[str], seeds: Sequence[int], out: Path) -> list[PlannedRun]:
    """``(strategy, seed, OUT/<strategy>-seed<N>)`` of every run of an experiment, in the order they run."""
    return [(strategy, seed, out / f"{strategy}-seed{seed}") for strategy in strategies for seed in seeds]


def check_experiment(strategies: Sequence[str], seeds: Sequence[int], out: Path, options: RunOptions) -> RunOptions:
    """Everything ``experiment`` refuses, checked before its first node starts; ``ValueError`` says what.
    The options checked (``RunOptions.check``: the machine's cores are the command line's to check).

    Strategies must be known and not repeat, seeds non-negative and not repeat, the options hold for every
    strategy, and no run directory may hold a run of other settings (another preset, budget or number of
    pairs): its runs would be mixed into this experiment's report.
    """
    unknown = [s for s in strategies if s not in STRATEGY_NAMES]
    if unknown or not strategies:
        raise ValueError(f"unknown strategies {unknown}: expected some of {', '.join(STRATEGY_NAMES)}")
    if len(set(strategies)) != len(strategies) or len(set(seeds)) != len(seeds) or not seeds:
        raise ValueError(f"strategies {list(strategies)} and seeds {list(seeds)} must each be given once")
    if min(seeds) < 0:
        raise ValueError(f"seeds must be non-negative integers, got {list(seeds)}")
    options = options.check(strategies, force=True)
    for strategy, seed, run_dir in experiment_runs(strategies, seeds, out):
        check_run_dir(run_dir, options.settings(strategy, seed))
    return options


def launch_run(strategy: str, seed: int, run_dir: Path, options: RunOptions) -> int:
    """``launch`` one run of an experiment (or resume it) into ``run_dir``, without its own report; its exit code.

    The one way an experiment starts a run, here or in a Ray task (``glocal_app.ray_runs``), so that both
    start the same graph with the same parameters.
    """
    return launch(strategy, seed, run_dir, options, report=False)


def launch_here(runs: Sequence[PlannedRun], options: RunOptions) -> Iterator[tuple[Path, int]]:
    """Each run launched on this machine, one after another: its run directory and exit code, as it ends."""
    for strategy, seed, run_dir in runs:
        yield run_dir, launch_run(strategy, seed, run_dir, options)


def experiment(strategies: Sequence[str], seeds: Sequence[int], out: Path, options: RunOptions, report: bool = True,
               finished: Callable[[Path], object] | None = None, ray_address: str | None = None,
               ray_cpus_per_run: int | None = None, prepare: Callable[[], object] | None = None) -> int:
    """Every strategy x seed as its own run under ``out``; finished runs are kept, others (re)launched.

    The runs go one after another here, each with ``options`` (``RunOptions``: preset, budget, profile,
    pairs, namespace, clock) and ``launch``'s domain choice, after ``check_experiment`` passed; then one report
    over all of them (unless ``report`` is off).
    ``finished(run_dir)`` is called as each launched run finishes; ``prepare()`` once everything
    was checked, before runs are told finished or not (what must not happen for refused input).

    With ``ray_address`` (``HOST:PORT`` of a Ray cluster, or ``local``) the runs that are not
    finished are Ray tasks of ``ray_cpus_per_run`` CPUs each instead (``glocal_app.ray_runs``), and
    come back into ``out`` as they end; the cluster is checked (reachable, a node large enough for
    one run) before any run starts.
    """
    options = check_experiment(strategies, seeds, out, options)
    runs = experiment_runs(strategies, seeds, out)
    cluster = None
    if ray_address is not None:
        from glocal_app.ray_runs import RayCluster

        cluster = RayCluster.connect(ray_address, ray_cpus_per_run)
    failed = []
    try:
        if prepare is not None:
            prepare()
        pending = []
        for run in runs:
            if run_finished(run[2]):
                print(f"{run[2].name}: finished before")
            else:
                pending.append(run)
        outcomes = launch_here(pending, options) if cluster is None else cluster.run(pending, options)
        for run_dir, code in outcomes:
            if code == EXIT_INTERRUPTED:
                return code
            if code:
                failed.append(run_dir.name)
            elif finished is not None and run_finished(run_dir):
                finished(run_dir)
    except KeyboardInterrupt:  # on Ray: the runs in progress were cancelled (``RayCluster.run``)
        print("interrupted; the same command resumes the experiment")
        return EXIT_INTERRUPTED
    finally:
        if cluster is not None:
            cluster.close()
    if report:
        write_run_report([run_dir for _, _, run_dir in runs], out / "report")
    if failed:
        print(f"failed runs: {', '.join(failed)} (the same command retries them)")
    return EXIT_FAILED if failed else 0

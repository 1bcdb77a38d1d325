"""Argument types and options that several ``glocal-ros`` commands share (their exit codes: ``exit_codes``)."""

from __future__ import annotations

import argparse
import sys
from dataclasses import fields
from pathlib import Path

from glocal_app.processes import RunOptions
from glocal_app.ray_runs import DEFAULT_CPUS_PER_RUN
from glocal_ros.curriculum.codes import STRATEGY_NAMES
from learner_node.profiles import DEFAULT_PROFILE, PROFILES, learner_profile

def command_line() -> str:
    """The command as the user typed it: benches write it beside what it produced."""
    return "glocal-ros " + " ".join(sys.argv[1:])


def name_list(text: str) -> list[str]:
    """An argparse type: comma-separated names (checked by whoever takes them)."""
    return [name.strip() for name in text.split(",") if name.strip()]


def number_list(text: str) -> list[int]:
    """An argparse type: comma-separated non-negative integers (seeds, pair counts, ...)."""
    items = [item.strip() for item in text.split(",")]
    if not all(item.isdigit() for item in items):
        raise argparse.ArgumentTypeError(f"{text!r}: expected comma-separated non-negative integers, e.g. 0,1,2")
    return [int(item) for item in items]


def profile_name(text: str) -> str:
    """An argparse type: a learner profile, with departures or not (``learner_node.profiles.learner_profile``),
    as its canonical name."""
    try:
        return learner_profile(text.strip()).name
    except ValueError as error:
        raise argparse.ArgumentTypeError(str(error)) from None


def profile_list(text: str) -> list[str]:
    """An argparse type: comma-separated learner profiles (``profile_name``)."""
    return [profile_name(name) for name in text.split(",")]


def count(minimum: int):
    """An argparse type: an integer of at least ``minimum``."""
    def parse(text: str) -> int:
        value = int(text)
        if value < minimum:
            raise argparse.ArgumentTypeError(f"{value} is below {minimum}")
        return value
    parse.__name__ = "int"  # argparse names the type in its message: "invalid int value"
    return parse



def positive_float(text: str) -> float:
    """An argparse type: a number above 0."""
    value = float(text)
    if not value > 0:
        raise argparse.ArgumentTypeError(f"{text} is not positive")
    return value


positive_float.__name__ = "float"


def print_progress(stage: str, done: int, total: int) -> None:
    if done == total or done % max(1, total // 20) == 0:
        print(f"{stage}: {done}/{total}", flush=True)


def add_experiment_arguments(parser: argparse.ArgumentParser, preset: str) -> None:
    """What ``experiment`` and ``bench curriculum`` share: which runs, at which preset and budget."""
    parser.add_argument("--strategies", type=name_list, default=list(STRATEGY_NAMES),
                        help=f"comma-separated, of {', '.join(STRATEGY_NAMES)} (default: all)")
    parser.add_argument("--seeds", type=number_list, default=[0, 1, 2], help="comma-separated (default: 0,1,2)")
    parser.add_argument("--preset", default=preset, help=f"a parameter file of assets/params (default: {preset})")
    parser.add_argument("--ray", default=None, metavar="ADDRESS",
                        help="run the runs as tasks of the Ray cluster at ADDRESS (HOST:PORT of its head, e.g. "
                             "10.0.0.5:6379), or of a Ray instance started on this machine (local); the run "
                             "directories come back to --out (default: one after another, here)")
    parser.add_argument("--ray-cpus-per-run", type=count(1), default=DEFAULT_CPUS_PER_RUN, metavar="N",
                        help=f"CPUs each run reserves on its Ray node (default: {DEFAULT_CPUS_PER_RUN})")


def add_graph_arguments(parser: argparse.ArgumentParser) -> None:
    """What ``launch`` and ``experiment`` share about the graph: its namespace and clock."""
    parser.add_argument("--namespace", default="", metavar="NS",
                        help="run every node under /NS (e.g. robot1), so that several graphs can share a "
                             "ROS domain; topics are then recorded as /NS/...")
    parser.add_argument("--use-sim-time", action="store_true",
                        help="sim_node and recorder_node on the sim's clock (/clock, /NS/clock under a "
                             "namespace), which advances by the control period per step; the learner's and the "
                             "curriculum's timeouts stay wall-clock")


def add_run_arguments(parser: argparse.ArgumentParser) -> None:
    """What ``launch``, ``experiment`` and ``bench curriculum`` may replace of the preset: the budget and the
    learner profile (``processes.RunOptions``, whose fields the options are named after)."""
    parser.add_argument("--step-budget", "--budget", type=count(1), default=None, metavar="STEPS",
                        help="training steps of every run, instead of the preset's step_budget")
    add_profile_argument(parser, default=None)


def run_options(args: argparse.Namespace) -> RunOptions:
    """The ``RunOptions`` of a command's arguments: each field from the argument of its name, where the command
    has one (``--step-budget`` -> ``step_budget``), else the field's default."""
    return RunOptions(**{field.name: getattr(args, field.name) for field in fields(RunOptions)
                         if hasattr(args, field.name)})


def add_pairs_arguments(parser: argparse.ArgumentParser, remote: bool = False) -> None:
    """``--pairs`` and ``--force`` (and, with ``remote``, ``--remote-pairs``), checked by ``check_pairs_arguments``
    (set as the command's ``check``)."""
    parser.add_argument("--pairs", type=int, default=1, metavar="K",
                        help="sim/learner pairs, each in its namespace pair0..pairK-1 under the run's, training "
                             "GloCAL's local tasks at once (parallel_locals); default 1: one pair, no pair "
                             "namespace, the sequential run")
    parser.add_argument("--force", action="store_true",
                        help="start more pairs than this machine has cores")
    if remote:
        parser.add_argument("--remote-pairs", type=int, default=0, metavar="R",
                            help="of the K pairs, the last R are started on other hosts (`glocal-ros pair`), "
                                 "not here; the launch waits for them on your ROS_DOMAIN_ID (default 0)")


def check_pairs_arguments(args: argparse.Namespace) -> None:
    """``ValueError`` for pairs that ``processes.check_pairs`` refuses with any of the command's strategies."""
    from glocal_app.processes import check_pairs

    strategies = args.strategies if hasattr(args, "strategies") else [args.strategy]
    remote = getattr(args, "remote_pairs", 0)
    for strategy in strategies:
        check_pairs(args.pairs, strategy, args.force, args.use_sim_time, remote=remote)


def add_profile_argument(parser: argparse.ArgumentParser, default: str | None = DEFAULT_PROFILE) -> None:
    """``--learner-profile`` (or ``--profile``): the learner profile; a default of None leaves it to the preset."""
    parser.add_argument("--learner-profile", "--profile", default=default, type=profile_name,
                        help=f"the learner profile: how policies learn and are scored, {' or '.join(PROFILES)}, "
                             "with departures (base+departure...) or not (learner_node/profiles.py)"
                             + ("; default: the preset's" if default is None else ""))


def add_prior_store_argument(command: argparse.ArgumentParser) -> None:
    command.add_argument("--prior-store", type=Path, default=None, metavar="DIR",
                         help="a policy store searched for the prior before the profile's shipped one "
                              "(train-prior --out; for a set of another A0)")


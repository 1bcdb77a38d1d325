"""``glocal-ros``: the command line of the project.

This module holds the commands that start or call the graph (run, evaluate,
launch, experiment, adapt) and puts the parser together; each other group of
commands lives in a module of its own (``assets_cli``, ``bench_cli``,
``policy_cli``, ``bag_cli``, ``glocal_ros.analysis.report``) with its
parser, its handlers and its argument checks. Subcommands that talk to a
running graph import rclpy lazily, so the ROS-free ones (assets, report,
...) work without a ROS environment.

Every command is checked before it runs, in one place (``main``): argparse
types reject a bad value, then the command's ``check`` (set with
``set_defaults``) fills in defaults that need other arguments and rejects
combinations; a ``ValueError`` from either, or from the command itself,
ends the command with its message and ``EXIT_USAGE``, not a traceback.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
from pathlib import Path

from glocal_app.arguments import (
    add_experiment_arguments,
    add_graph_arguments,
    add_pairs_arguments,
    add_run_arguments,
    check_pairs_arguments,
    positive_float,
    run_options,
)
from glocal_app.assets_cli import add_assets_commands
from glocal_app.bag_cli import add_bag_commands
from glocal_app.bench_cli import add_bench_commands
from glocal_app.exit_codes import EXIT_OK, EXIT_USAGE
from glocal_app.nodes import NODES
from glocal_app.policy_cli import add_policy_commands
from glocal_app.processes import FOXGLOVE_HOST, FOXGLOVE_PORT, FoxgloveEndpoint
from glocal_ros.curriculum.codes import STRATEGY_NAMES
from glocal_ros.tasks import parse_task_list

#: The ament package that installs the nodes' executables.
PACKAGE = "glocal_ros"


def node_executable(node: str) -> Path:
    """Where ``ros2 run glocal_ros NODE`` finds NODE: ``<prefix>/lib/glocal_ros/NODE`` via the ament index."""
    from ament_index_python.packages import PackageNotFoundError, get_package_prefix

    # A bare venv has no AMENT_PREFIX_PATH; its prefix is where `make setup` installed the package.
    os.environ.setdefault("AMENT_PREFIX_PATH", sys.prefix)
    try:
        prefix = Path(get_package_prefix(PACKAGE))
    except PackageNotFoundError:
        raise SystemExit(f"package {PACKAGE} is not in the ament index (AMENT_PREFIX_PATH): run `make setup`")
    executable = prefix / "lib" / PACKAGE / node
    if not executable.is_file():
        raise SystemExit(f"no executable {node} in {executable.parent}: known nodes are {', '.join(NODES)}")
    return executable


def cmd_run(args: argparse.Namespace) -> int:
    executable = node_executable(args.node)
    # The node replaces this process, so SIGINT/SIGTERM reach it directly.
    os.execv(sys.executable, [sys.executable, str(executable), *args.node_args])
    return 1  # not reached


def cmd_evaluate(args: argparse.Namespace) -> int:
    from glocal_app.commands import evaluate_policy

    scores = evaluate_policy(args.policy, parse_task_list(args.tasks, novel=True), args.episodes, args.seed, args.timeout)
    if args.json:
        print(json.dumps({task: successes for task, successes, _ in scores}))
    else:
        for task, successes, episodes in scores:
            print(f"{task}: {successes}/{episodes}")
    return EXIT_OK


def cmd_launch(args: argparse.Namespace) -> int:
    from glocal_app.launch import launch

    if args.foxglove_host is not None and args.foxglove is None:
        raise ValueError("--foxglove-host needs --foxglove [PORT]")
    foxglove = None if args.foxglove is None else FoxgloveEndpoint(
        args.foxglove, *(() if args.foxglove_host is None else (args.foxglove_host,)))
    how = dict(foxglove=foxglove, remote_pairs=args.remote_pairs,
               tensorboard_dir=None if args.tensorboard is None else args.tensorboard.expanduser().resolve())
    if args.watchdog is not None:
        how["watchdog_sec"] = args.watchdog
    return launch(args.strategy, args.seed, args.out, run_options(args), **how)


def cmd_pair(args: argparse.Namespace) -> int:
    from glocal_app.launch import serve_pair

    return serve_pair(args.out, args.index, args.namespace)


def cmd_foxglove_layout(args: argparse.Namespace) -> int:
    from glocal_app.processes import normalize_namespace, pair_namespaces
    from glocal_ros.foxglove_layout import write_layout

    path = write_layout(args.out, normalize_namespace(args.namespace), pair_namespaces(args.pairs)[0])
    print(f"wrote {path}: import it in Foxglove (Layouts > Import from file...)")
    return EXIT_OK


def cmd_experiment(args: argparse.Namespace) -> int:
    from glocal_app.experiment import experiment

    return experiment(args.strategies, args.seeds, args.out, run_options(args), ray_address=args.ray,
                      ray_cpus_per_run=args.ray_cpus_per_run)


def cmd_adapt(args: argparse.Namespace) -> int:
    from glocal_app.adapt import adapt_run, describe

    print(describe(adapt_run(args.run, args.object, args.name, args.budget, args.seed)))
    return EXIT_OK


def add_graph_commands(commands) -> None:
    """``run``, ``evaluate``, ``launch`` and ``experiment``: the commands that start or call the graph."""
    run = commands.add_parser("run", help="start a node, as `ros2 run glocal_ros NODE` does")
    run.add_argument("node", choices=NODES)
    run.add_argument("node_args", nargs=argparse.REMAINDER, help="passed on, e.g. --ros-args -p num_envs:=2")
    run.set_defaults(func=cmd_run)

    evaluate = commands.add_parser("evaluate", help="score a policy with a running learner (successes per task)")
    evaluate.add_argument("--policy", required=True)
    evaluate.add_argument("--tasks", required=True, help="comma-separated, e.g. A0,B3, or 'all'; NAME@PROXY for a novel object the sim serves")
    evaluate.add_argument("--episodes", type=int, default=100, help="episodes per task (default 100)")
    evaluate.add_argument("--seed", type=int, default=-1, help="seed of the evaluation resets; -1 for none")
    evaluate.add_argument("--timeout", type=float, default=600.0, help="seconds to wait for the answer")
    evaluate.add_argument("--json", action="store_true", help="print one JSON object mapping task to score")
    evaluate.set_defaults(func=cmd_evaluate)


    launch = commands.add_parser("launch", help="run the whole graph as processes on the ROS_DOMAIN_ID you set, "
                                 "else on a free one; the same command resumes an interrupted run")
    launch.add_argument("--strategy", default="glocal", choices=STRATEGY_NAMES)
    launch.add_argument("--preset", default="demo", help="a parameter file of assets/params: smoke, demo, bench, paper, paper-bench (default: demo)")
    launch.add_argument("--seed", type=int, default=0)
    launch.add_argument("--out", type=Path, required=True,
                        help="run directory: gets bag/, policies/, curriculum/, tensorboard/, logs/ and report/")
    launch.add_argument("--tensorboard", type=Path, default=None, metavar="DIR",
                        help="write every Train goal's training curves (TensorBoard events, CSV) in DIR/<goal> "
                             "(default: RUN_DIR/tensorboard)")
    launch.add_argument("--watchdog", type=positive_float, default=None, metavar="SEC",
                        help="stop the graph (resumable) when nothing moves for SEC seconds (default: a minute)")
    add_graph_arguments(launch)
    add_run_arguments(launch)
    launch.add_argument("--foxglove", type=int, nargs="?", const=FOXGLOVE_PORT, default=None, metavar="PORT",
                        help=f"also start foxglove_bridge_node: the graph's topics live over the Foxglove "
                             f"WebSocket protocol on ws://{FOXGLOVE_HOST}:PORT (default port {FOXGLOVE_PORT}); "
                             f"open it in Foxglove with the layout the run directory gets (foxglove-layout.json)")
    launch.add_argument("--foxglove-host", default=None, metavar="HOST",
                        help=f"serve Foxglove on HOST instead of {FOXGLOVE_HOST} (this host only); e.g. 0.0.0.0 "
                             f"lets every host that reaches the port see the graph, with no authentication")
    add_pairs_arguments(launch, remote=True)
    launch.set_defaults(func=cmd_launch, check=check_pairs_arguments)

    pair = commands.add_parser("pair", help="start one sim/learner pair of a `launch --remote-pairs` run on this "
                               "host, on your ROS_DOMAIN_ID, until Ctrl-C")
    pair.add_argument("--out", type=Path, required=True,
                      help="the launch's run directory, mounted here at the same path (its run.json and policies/)")
    pair.add_argument("--index", type=int, required=True, help="which pair: one of the launch's remote pairs")
    pair.add_argument("--namespace", default="", metavar="NS", help="the launch's --namespace")
    pair.set_defaults(func=cmd_pair)

    layout = commands.add_parser("foxglove-layout", help="write the Foxglove layout for a graph under a namespace "
                                 "(what `launch --foxglove` writes to its run directory)")
    layout.add_argument("--namespace", default="", metavar="NS", help="the graph's namespace (default: the root)")
    layout.add_argument("--pairs", type=int, default=1, metavar="K", help="the run's sim/learner pairs: with "
                        "K >= 2 the layout shows pair0 (default 1)")
    layout.add_argument("--out", type=Path, required=True, help="the layout file to write")
    layout.set_defaults(func=cmd_foxglove_layout)

    adapt = commands.add_parser("adapt", help="a novel object: score a finished run's global policies, its last "
                                "and the prior on it, and fine-tune the best until B (glocal_app.adapt)")
    adapt.add_argument("run", type=Path, help="the directory of a finished run with global policies (glocal)")
    adapt.add_argument("--object", type=Path, required=True,
                       help="a mesh file (.obj, .stl, ...), or an object directory of a set (assets generate)")
    adapt.add_argument("--name", required=True, help="the object's name: a letter, then letters, digits, _ or -; "
                       "not a grid task's (A0..G6)")
    adapt.add_argument("--budget", type=int, default=None, help="training steps at most (default: the run "
                       "preset's per-task budget)")
    adapt.add_argument("--seed", type=int, default=None, help="seed of the evaluations and the goal "
                       "(default: the run's)")
    adapt.set_defaults(func=cmd_adapt)

    experiment = commands.add_parser("experiment", help="strategies x seeds as separate runs (resumable), "
                                     "then one report")
    add_experiment_arguments(experiment, preset="smoke")
    experiment.add_argument("--out", type=Path, required=True, help="gets <strategy>-seed<N>/ per run and report/")
    add_graph_arguments(experiment)
    add_run_arguments(experiment)
    add_pairs_arguments(experiment)
    experiment.set_defaults(func=cmd_experiment, check=check_pairs_arguments)


def build_parser() -> argparse.ArgumentParser:
    from glocal_ros.analysis.report import add_report_command

    parser = argparse.ArgumentParser(prog="glocal-ros", description=__doc__.splitlines()[0])
    commands = parser.add_subparsers(dest="command", required=True)
    add_graph_commands(commands)
    add_assets_commands(commands)
    add_bench_commands(commands)
    add_policy_commands(commands)
    add_report_command(commands)
    add_bag_commands(commands)
    return parser


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        check = getattr(args, "check", None)
        if check is not None:
            check(args)
        return args.func(args)
    except ValueError as error:  # bad input (unknown task, ...): a message, not a traceback
        parser.exit(EXIT_USAGE, f"glocal-ros {args.command}: error: {error}\n")


if __name__ == "__main__":
    sys.exit(main())

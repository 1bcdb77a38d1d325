"""``glocal-ros``: the command line of the project.

Subcommands that talk to a running graph import rclpy lazily, so the
ROS-free ones (assets, report, ...) work without a ROS environment.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
from pathlib import Path

from glocal_ros.tasks import parse_task_list

PACKAGE = "glocal_ros"
NODES = ("sim_node", "learner_node", "curriculum_node", "recorder_node")


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
    from node_common.commands import evaluate_policy

    scores = evaluate_policy(args.policy, parse_task_list(args.tasks), args.episodes, args.seed, args.timeout)
    if args.json:
        print(json.dumps({task: successes for task, successes, _ in scores}))
    else:
        for task, successes, episodes in scores:
            print(f"{task}: {successes}/{episodes}")
    return 0


def cmd_launch(args: argparse.Namespace) -> int:
    from node_common.launch import launch

    return launch(args.strategy, args.preset, args.seed, args.out)


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="glocal-ros", description=__doc__.splitlines()[0])
    commands = parser.add_subparsers(dest="command", required=True)

    run = commands.add_parser("run", help="start a node, as `ros2 run glocal_ros NODE` does")
    run.add_argument("node", choices=NODES)
    run.add_argument("node_args", nargs=argparse.REMAINDER, help="passed on, e.g. --ros-args -p num_envs:=2")
    run.set_defaults(func=cmd_run)

    evaluate = commands.add_parser("evaluate", help="score a policy with a running learner (successes per task)")
    evaluate.add_argument("--policy", required=True)
    evaluate.add_argument("--tasks", required=True, help="comma-separated, e.g. A0,B3, or 'all'")
    evaluate.add_argument("--episodes", type=int, default=100, help="episodes per task (default 100)")
    evaluate.add_argument("--seed", type=int, default=-1, help="seed of the evaluation resets; -1 for none")
    evaluate.add_argument("--timeout", type=float, default=600.0, help="seconds to wait for the answer")
    evaluate.add_argument("--json", action="store_true", help="print one JSON object mapping task to score")
    evaluate.set_defaults(func=cmd_evaluate)

    launch = commands.add_parser("launch", help="run the whole graph as processes on an isolated ROS domain")
    launch.add_argument("--strategy", default="glocal")
    launch.add_argument("--preset", default="demo", help="a parameter file of assets/params: smoke, demo, paper")
    launch.add_argument("--seed", type=int, default=0)
    launch.add_argument("--out", type=Path, required=True, help="run directory: gets bag/ and logs/")
    launch.set_defaults(func=cmd_launch)
    return parser


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return args.func(args)
    except ValueError as error:  # bad input (unknown task, ...): a message, not a traceback
        parser.exit(2, f"glocal-ros {args.command}: error: {error}\n")


if __name__ == "__main__":
    sys.exit(main())

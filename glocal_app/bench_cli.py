"""``glocal-ros bench ...``: each bench writes its table, with the command that made it, under bench/results/."""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

from glocal_app.arguments import (
    add_experiment_arguments,
    add_prior_store_argument,
    add_profile_argument,
    add_run_arguments,
    command_line,
    count,
    number_list,
    profile_list,
    run_options,
)
from glocal_app.benches import cost as cost_bench
from glocal_app.benches import fewshot as fewshot_bench
from glocal_app.benches.curriculum import BENCH_PRESET, DEFAULT_OUT, DEFAULT_RESULTS
from glocal_app.benches.transfer import (
    INITIAL_POLICY,
    PROFILE_RECIPE,
    TRANSFER_TASKS,
    TransferSettings,
)
from glocal_app.exit_codes import EXIT_FAILED, EXIT_INTERRUPTED, EXIT_OK
from glocal_ros.sim_contract import DEFAULT_EVAL_ENVS
from glocal_ros.tasks import parse_task_list
from learner_node.profiles import DEFAULT_PROFILE, PROFILES
from learner_node.sac_settings import DEFAULT_NETWORK, FINE_TUNING_RECIPES, NETWORKS


def write_bench_report(report: str, out: Path) -> int:
    """Show a bench's report and write it to ``out`` (with the command that made it, inside)."""
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(report)
    print(report, end="")
    print(f"written to {out}")
    return EXIT_OK


def cmd_bench_sim(args: argparse.Namespace) -> int:
    from glocal_app.benches.sim import run_sim_bench, sim_bench_report

    env_counts = [int(n) for n in args.envs.split(",")]
    rows = run_sim_bench(env_counts, args.batches, args.rounds)
    report = sim_bench_report(rows, command_line(), args.batches, args.rounds)
    return write_bench_report(report, args.out)


def cmd_bench_physics(args: argparse.Namespace) -> int:
    from glocal_app.benches.physics import physics_bench_report, run_physics_bench

    results = run_physics_bench(args.tasks, args.steps, args.rounds)
    return write_bench_report(physics_bench_report(results, command_line(), args.rounds), args.out)


def cmd_bench_learner(args: argparse.Namespace) -> int:
    from glocal_app.benches.learner import learner_bench_report, run_learner_bench

    env_counts = [int(n) for n in args.envs.split(",")]
    rows = run_learner_bench(env_counts, args.steps, args.rounds, learner_node=not args.no_learner_node,
                             profiles=args.profiles, curves=args.curves)
    report = learner_bench_report(rows, command_line(), args.steps, args.rounds)
    return write_bench_report(report, args.out)


def cmd_bench_eval(args: argparse.Namespace) -> int:
    from glocal_app.benches.evaluation import eval_bench_report, run_eval_bench

    row = run_eval_bench(args.envs, args.eval_envs, args.episodes, args.rounds, profile=args.learner_profile)
    return write_bench_report(eval_bench_report(row, command_line(), args.rounds, args.learner_profile), args.out)


def cmd_bench_backends(args: argparse.Namespace) -> int:
    from glocal_app.benches.backends import backends_bench_report, run_backends_bench

    rows = run_backends_bench([int(n) for n in args.envs.split(",")], args.steps, args.rounds, args.network)
    report = backends_bench_report(rows, command_line(), args.steps, args.rounds,
                                   args.network)
    return write_bench_report(report, args.out)


def cmd_bench_foxglove(args: argparse.Namespace) -> int:
    from glocal_app.benches.foxglove import foxglove_bench_report, run_foxglove_bench

    result = run_foxglove_bench(args.envs, args.steps, args.pairs)
    return write_bench_report(foxglove_bench_report(result, command_line()), args.out)


def cmd_bench_graph(args: argparse.Namespace) -> int:
    from glocal_app.benches.graph import graph_bench_report, run_graph_bench

    rows = run_graph_bench(args.goals, args.evaluations, args.steps)
    report = graph_bench_report(rows, command_line())
    write_bench_report(report, args.out)
    return EXIT_OK if all(row.lost == 0 for row in rows) else EXIT_FAILED


def cmd_bench_fewshot(args: argparse.Namespace) -> int:
    from glocal_app.benches.fewshot import (CASES_FILE, fewshot_report, fewshot_selection, held_cases,
                                            run_fewshot_bench)

    settings = TransferSettings(step_budget=args.budget, eval_interval=args.eval_interval,
                                eval_episodes=args.eval_episodes, num_envs=args.envs)
    seeds = [int(seed) for seed in args.seeds.split(",")]
    if args.tabulate:
        runs, objects = fewshot_selection(args.runs, args.objects, seeds, settings, args.per_third)
        held = held_cases(args.work_dir, settings, objects, runs)
        selection = [(run.run_id, novel.name, seed) for run in runs for seed in seeds for novel in objects]
        cases = [held[case] for case in selection if case in held]
        if not cases:
            print(f"bench fewshot --tabulate: no finished case of these runs, objects and seeds in "
                  f"{args.work_dir / CASES_FILE}", file=sys.stderr)
            return EXIT_FAILED
        report = fewshot_report(cases, command_line(), settings, args.objects, args.work_dir, selected=len(selection))
        return write_bench_report(report, args.out)
    try:
        cases = run_fewshot_bench(args.runs, args.objects, seeds, settings, args.per_third, args.work_dir, args.jobs)
    except KeyboardInterrupt:
        print(f"bench fewshot: interrupted; the finished cases are kept in {args.work_dir / CASES_FILE}: the same "
              "command resumes", file=sys.stderr)
        return EXIT_INTERRUPTED
    return write_bench_report(fewshot_report(cases, command_line(), settings, args.objects, args.work_dir, args.jobs),
                              args.out)


def cmd_bench_transfer(args: argparse.Namespace) -> int:
    from glocal_app.benches.transfer import (
        read_transfer_goals,
        run_transfer_bench,
        run_transfer_graph,
        transfer_bench_report,
    )

    settings = TransferSettings(step_budget=args.budget, eval_interval=args.eval_interval,
                                eval_episodes=args.eval_episodes, num_envs=args.envs, objects_dir=args.objects_dir)
    command = command_line()
    if args.tabulate:
        try:
            goals = [goal for source in args.tabulate for goal in read_transfer_goals(source, settings)]
            keys = [(*goal.arm, goal.task, goal.seed) for goal in goals]
            if len(set(keys)) != len(keys):
                repeated = next(key for key in keys if keys.count(key) > 1)
                raise ValueError("the goal (profile, recipe, prior, task, seed) = {} is in the reports more than once"
                                 .format(", ".join(map(str, repeated))))
        except (OSError, ValueError) as error:
            print(f"bench transfer --tabulate: {error}", file=sys.stderr)
            return EXIT_FAILED
        return write_bench_report(transfer_bench_report(goals, command, settings, 0, sources=args.tabulate),
                                  args.out)
    seeds = [int(seed) for seed in args.seeds.split(",")]
    recipes, tasks, priors = args.recipes.split(","), args.tasks.split(","), args.priors.split(",")
    arms = dict(priors=priors, prior_store=args.prior_store, profiles=args.profiles)
    goals = (run_transfer_graph(recipes, tasks, seeds, settings, **arms) if args.graph
             else run_transfer_bench(recipes, tasks, seeds, settings, args.jobs, **arms))
    report = transfer_bench_report(goals, command, settings, args.jobs, args.graph)
    return write_bench_report(report, args.out)


def cmd_bench_cost(args: argparse.Namespace) -> int:
    """A learning-cost map: steps to B per object and seed from the prior (``glocal_app.benches.cost``)."""
    from glocal_app.benches.cost import (
        GOALS_FILE,
        check_against,
        check_cost,
        cost_figure,
        cost_report,
        cost_settings,
        finished_goals,
        read_cost_report,
        run_cost_map,
        select_tasks,
    )

    settings = cost_settings(args.step_budget, args.eval_interval, args.eval_episodes, args.envs,
                             args.objects_dir)
    tasks = select_tasks(args.tasks)
    command = command_line()
    against = None
    if args.against is not None:  # read and checked before any goal runs
        against = read_cost_report(args.against)
        check_against(against, settings, args.learner_profile)
    if args.tabulate:
        check_cost(tasks, args.seeds, settings, args.jobs, args.learner_profile, args.prior_store, args.recipe)
        held = finished_goals(args.work_dir, settings, args.learner_profile, args.prior_store, args.recipe)
        goals = [held[(task, seed)] for task in tasks for seed in args.seeds if (task, seed) in held]
        if not goals:
            print(f"bench cost --tabulate: no finished goal of these tasks and seeds in {args.work_dir / GOALS_FILE}",
                  file=sys.stderr)
            return EXIT_FAILED
    else:
        try:
            goals = run_cost_map(tasks, args.seeds, settings, args.work_dir, args.jobs, args.learner_profile,
                                 prior_store=args.prior_store, recipe=args.recipe)
        except KeyboardInterrupt:
            print(f"bench cost: interrupted; the finished goals are kept in {args.work_dir / GOALS_FILE}: the same "
                  "command resumes", file=sys.stderr)
            return EXIT_INTERRUPTED
    figure = cost_figure(goals, settings, args.out.with_suffix(".png"))
    report = cost_report(goals, command, settings, tasks, args.seeds, args.jobs, figure, args.work_dir,
                         tabulated=args.tabulate, profile=args.learner_profile, recipe=args.recipe, against=against)
    write_bench_report(report, args.out)
    print(f"figure: {figure}")
    return EXIT_OK


def cmd_bench_stones(args: argparse.Namespace) -> int:
    """Steps to B on hard objects from the policy that learned the row above (``glocal_app.benches.stones``)."""
    from glocal_app.benches.cost import GOALS_FILE, cost_settings
    from glocal_app.benches.stones import STONES_FILE, run_stones, stones_report

    settings = cost_settings(args.step_budget, args.eval_interval, args.eval_episodes, args.envs, args.objects_dir)
    try:
        direct, chains = run_stones(parse_task_list(args.targets), args.seeds, settings, args.work_dir, args.jobs,
                                    args.learner_profile, args.prior_store)
    except KeyboardInterrupt:
        print(f"bench stones: interrupted; what finished is kept in {args.work_dir / GOALS_FILE} and "
              f"{args.work_dir / STONES_FILE}: the same command resumes", file=sys.stderr)
        return EXIT_INTERRUPTED
    command = command_line()
    return write_bench_report(stones_report(direct, chains, command, settings, args.work_dir), args.out)


def cmd_bench_curriculum(args: argparse.Namespace) -> int:
    from glocal_app.benches.curriculum import (
        bench_inputs,
        check_bench,
        keep_finished_runs,
        keep_run,
        kept_runs_dir,
        restore_kept_runs,
        tabulate_curriculum_bench,
    )

    command = command_line()
    keep = args.keep or kept_runs_dir(args.results)
    code = 0
    if not args.tabulate:
        check_bench(args.strategies, args.seeds, args.out, run_options(args), keep)
        bench_inputs(args.out, args.merge)  # a --merge that holds no run is refused before the first run
        from glocal_app.experiment import experiment

        def keep_and_restore() -> None:  # once the Ray cluster, if any, is checked too
            keep_finished_runs(args.out, keep)  # runs that finished before this command
            for run_dir in restore_kept_runs(keep, args.out):
                print(f"{run_dir.name}: restored from {keep}")

        code = experiment(args.strategies, args.seeds, args.out, run_options(args), report=False,
                          finished=lambda run_dir: keep_run(run_dir, keep), ray_address=args.ray,
                          ray_cpus_per_run=args.ray_cpus_per_run, prepare=keep_and_restore)
        if code == EXIT_INTERRUPTED:  # the same command resumes
            return code
    report = tabulate_curriculum_bench(bench_inputs(args.out, args.merge, keep), command, args.results)
    write_bench_report(report, args.results)
    return code


def cmd_bench_scale(args: argparse.Namespace) -> int:
    """A scaling model fitted on a recorded run (``glocal_app.benches.scale``)."""
    from glocal_app.benches.scale import check_scale, scale_report

    try:
        check_scale(args.run_dir, args.validate, args.pairs, args.machines)
    except ValueError as error:
        print(f"bench scale: {error}", file=sys.stderr)
        return EXIT_FAILED
    return write_bench_report(scale_report(args.run_dir, args.validate, args.pairs, args.machines, command_line()),
                              args.out)


def _add_rate_arguments(parser: argparse.ArgumentParser, envs: str, steps: int) -> None:
    """The env counts, timed steps and rounds of a bench that times SAC learning (learner, backends)."""
    parser.add_argument("--envs", default=envs, help="comma-separated env counts N")
    parser.add_argument("--steps", type=int, default=steps, help="env steps timed per measurement, after a "
                        "warm-up of batch_size + 64 + N steps")
    parser.add_argument("--rounds", type=int, default=3, help="alternating rounds; the median is reported")


def _add_cost_goal_arguments(command: argparse.ArgumentParser, default_envs: int) -> None:
    """What decides a cost map's goals, and where they are kept: ``bench cost``'s and ``bench stones``'."""
    command.add_argument("--seeds", type=number_list, default=list(cost_bench.DEFAULT_SEEDS),
                         help=f"comma-separated goal seeds (default: {','.join(map(str, cost_bench.DEFAULT_SEEDS))})")
    command.add_argument("--step-budget", type=int, default=cost_bench.DEFAULT_STEP_BUDGET, metavar="STEPS",
                         help=f"the cap: training steps of a goal that does not pass B (default: "
                              f"{cost_bench.DEFAULT_STEP_BUDGET})")
    command.add_argument("--eval-interval", type=int, default=cost_bench.DEFAULT_EVAL_INTERVAL, metavar="STEPS",
                         help=f"training steps between evaluations (default: {cost_bench.DEFAULT_EVAL_INTERVAL})")
    command.add_argument("--eval-episodes", type=int, default=cost_bench.DEFAULT_EVAL_EPISODES,
                         help=f"episodes per evaluation, S-bar; B is 0.75 of them (default: the paper's "
                              f"{cost_bench.DEFAULT_EVAL_EPISODES})")
    command.add_argument("--envs", type=int, default=default_envs, help=f"envs N per goal (default: {default_envs})")
    command.add_argument("--jobs", type=int, default=os.cpu_count() or 1,
                         help="goals run at a time (default: one per core)")
    add_profile_argument(command)
    command.add_argument("--objects-dir", type=Path, default=None, metavar="DIR",
                         help="the object set to map, in the layout `assets generate` writes (default: the "
                              "shipped one)")
    add_prior_store_argument(command)
    command.add_argument("--work-dir", type=Path, default=cost_bench.DEFAULT_WORK_DIR,
                         help="where each goal is kept as it finishes (goals.jsonl), for the same command to "
                              f"skip (default: {cost_bench.DEFAULT_WORK_DIR})")


def add_bench_commands(commands) -> None:
    """``bench sim | graph | learner | backends | fewshot | transfer | cost | stones | curriculum | scale``."""
    bench = commands.add_parser("bench", help="benchmarks; each writes its table with the command that made it")
    bench_commands = bench.add_subparsers(dest="bench_command", required=True)
    bench_sim = bench_commands.add_parser("sim", help="env steps/s in-process vs through sim_node")
    bench_sim.add_argument("--envs", default="1,2,4", help="comma-separated env counts N")
    bench_sim.add_argument("--batches", type=int, default=500, help="lockstep batches per measurement")
    bench_sim.add_argument("--rounds", type=int, default=3, help="alternating rounds; the median is reported")
    bench_sim.add_argument("--out", type=Path, default=Path("bench/results/sim.md"))
    bench_sim.set_defaults(func=cmd_bench_sim)
    bench_physics = bench_commands.add_parser("physics", help="where one control step of the env floor goes: a "
                                              "profile, one physics step, and what would be faster")
    bench_physics.add_argument("--tasks", type=parse_task_list, default=["A0", "D4", "G3"],
                               help="comma-separated tasks, one env each (default A0,D4,G3)")
    bench_physics.add_argument("--steps", type=count(1), default=2000, help="control steps per measurement")
    bench_physics.add_argument("--rounds", type=count(1), default=3, help="alternating rounds; medians reported")
    bench_physics.add_argument("--out", type=Path, default=Path("bench/results/physics.md"))
    bench_physics.set_defaults(func=cmd_bench_physics)
    bench_graph = bench_commands.add_parser("graph", help="lost answers under stress: Train goals, learner/evaluate "
                                            "and sim/step calls, 1 and 4 threads, with and without a CPU burner")
    bench_graph.add_argument("--goals", type=count(1), default=1000, help="short Train goals per row")
    bench_graph.add_argument("--evaluations", type=count(1), default=1000, help="learner/evaluate calls per row")
    bench_graph.add_argument("--steps", type=count(1), default=5000, help="sim/step calls per row")
    bench_graph.add_argument("--out", type=Path, default=Path("bench/results/graph.md"))
    bench_graph.set_defaults(func=cmd_bench_graph)
    bench_foxglove = bench_commands.add_parser(
        "foxglove", help="training env steps/s of sim_node + learner_node with and without an idle "
        "foxglove_bridge_node, alternating (ABBA)")
    bench_foxglove.add_argument("--envs", type=count(1), default=4, help="envs N of the sim (default 4)")
    bench_foxglove.add_argument("--steps", type=count(100), default=2000,
                                help="env steps timed per round, after the warm-up (default 2000)")
    bench_foxglove.add_argument("--pairs", type=count(1), default=4,
                                help="ABBA pairs: each one round with the idle bridge, one without "
                                     "(default 4: two ABBA blocks)")
    bench_foxglove.add_argument("--out", type=Path, default=Path("bench/results/foxglove.md"))
    bench_foxglove.set_defaults(func=cmd_bench_foxglove)
    bench_learner = bench_commands.add_parser("learner", help="SAC env steps/s with updates, in-process vs through "
                                              "sim_node and learner_node")
    _add_rate_arguments(bench_learner, envs="1,2,4", steps=300)
    bench_learner.add_argument("--no-learner-node", action="store_true",
                               help="leave out the learner_node process (its Train action) column")
    bench_learner.add_argument("--curves", action="store_true",
                               help="add the in-process goal writing its training curves (TensorBoard, CSV) at "
                                    "every report: what the curves cost")
    bench_learner.add_argument("--out", type=Path, default=Path("bench/results/learner.md"))
    bench_learner.add_argument("--profiles", type=profile_list, default=list(PROFILES),
                               help="comma-separated learner profiles, each measured on its own prior "
                                    f"(default: all, {','.join(PROFILES)})")
    bench_learner.set_defaults(func=cmd_bench_learner)
    bench_eval = bench_commands.add_parser("eval", help="evaluation env steps/s through learner_node beside the "
                                           "sim's envs stepped alone on all its workers")
    bench_eval.add_argument("--envs", type=count(1), default=4, help="the sim's training envs (default 4)")
    bench_eval.add_argument("--eval-envs", type=count(1), default=DEFAULT_EVAL_ENVS,
                            help=f"the sim's evaluation envs (default {DEFAULT_EVAL_ENVS})")
    bench_eval.add_argument("--episodes", type=count(1), default=25, help="episodes per task (default 25)")
    bench_eval.add_argument("--rounds", type=count(1), default=3, help="alternating rounds; medians reported")
    bench_eval.add_argument("--out", type=Path, default=Path("bench/results/eval.md"))
    add_profile_argument(bench_eval)
    bench_eval.set_defaults(func=cmd_bench_eval)
    bench_backends = bench_commands.add_parser("backends", help="SAC env steps/s of stable-baselines3 (torch) and "
                                               "SBX (JAX), side by side: how the learner's backend was chosen")
    _add_rate_arguments(bench_backends, envs="1,4", steps=2000)
    bench_backends.add_argument("--network", choices=list(NETWORKS), default=DEFAULT_NETWORK)
    bench_backends.add_argument("--out", type=Path, default=Path("bench/results/backends.md"))
    bench_backends.set_defaults(func=cmd_bench_backends)
    transfer_defaults = TransferSettings()
    bench_fewshot = bench_commands.add_parser(
        "fewshot", help="novel objects: steps to B from a run's best global policy, from the prior and from its "
        "last policy")
    bench_fewshot.add_argument("--runs", type=Path, nargs="+", required=True, metavar="RUN_DIR",
                               help="finished GloCAL runs that kept their policies")
    bench_fewshot.add_argument("--objects", type=Path, required=True, metavar="DIR",
                               help="a set `assets generate --seed S` made with a seed the run's set did not use, "
                               "its lifting poses measured")
    bench_fewshot.add_argument("--per-third", type=count(1), default=3,
                               help="objects from each third of the set's lifting-pose shares (default 3)")
    bench_fewshot.add_argument("--seeds", default="0,1", help="comma-separated seeds (default 0,1)")
    bench_fewshot.add_argument("--budget", type=int, default=60_000, help="training steps per goal at most")
    bench_fewshot.add_argument("--eval-interval", type=int, default=2_000)
    bench_fewshot.add_argument("--eval-episodes", type=int, default=20, help="S-bar; B is 75%% of it")
    bench_fewshot.add_argument("--envs", type=int, default=transfer_defaults.num_envs, help="envs N per goal")
    bench_fewshot.add_argument("--jobs", type=count(1), default=1, help="cases at a time, each in a process")
    bench_fewshot.add_argument("--work-dir", type=Path, default=fewshot_bench.DEFAULT_WORK_DIR,
                               help=f"where each finished case is kept ({fewshot_bench.DEFAULT_WORK_DIR}/"
                               f"{fewshot_bench.CASES_FILE}): the same command resumes")
    bench_fewshot.add_argument("--tabulate", action="store_true",
                               help="report the cases the work directory holds; run nothing")
    bench_fewshot.add_argument("--out", type=Path, default=Path("bench/results/fewshot.md"))
    bench_fewshot.set_defaults(func=cmd_bench_fewshot)
    bench_transfer = bench_commands.add_parser(
        "transfer", help="fine-tuning the A0 prior on other objects: steps to B and collapses, recipe by recipe")
    bench_transfer.add_argument("--profiles", type=profile_list, default=[DEFAULT_PROFILE],
                                help=f"comma-separated learner profiles, of {', '.join(PROFILES)}")
    bench_transfer.add_argument("--recipes", default=PROFILE_RECIPE,
                                help=f"comma-separated fine-tuning recipes: {PROFILE_RECIPE} (each profile's own), "
                                     f"or where the profile allows one, {', '.join(FINE_TUNING_RECIPES)}")
    bench_transfer.add_argument("--priors", default=INITIAL_POLICY,
                                help="comma-separated stored policies the goals start from (each recipe from each)")
    add_prior_store_argument(bench_transfer)
    bench_transfer.add_argument("--tasks", default=",".join(TRANSFER_TASKS), help="comma-separated tasks")
    bench_transfer.add_argument("--objects-dir", type=Path, default=None, metavar="DIR",
                                help="the object set the goals grasp, in the layout `assets generate` writes "
                                     "(default: the shipped one)")
    bench_transfer.add_argument("--seeds", default="0,1,2", help="comma-separated goal seeds")
    bench_transfer.add_argument("--budget", type=int, default=transfer_defaults.step_budget,
                                help="training steps of every goal")
    bench_transfer.add_argument("--eval-interval", type=int, default=transfer_defaults.eval_interval,
                                help="training steps between evaluations")
    bench_transfer.add_argument("--eval-episodes", type=int, default=transfer_defaults.eval_episodes,
                                help="episodes per evaluation (S-bar)")
    bench_transfer.add_argument("--envs", type=int, default=transfer_defaults.num_envs, help="envs N per goal")
    bench_transfer.add_argument("--jobs", type=int, default=os.cpu_count() or 1,
                                help="goals run at a time in-process")
    bench_transfer.add_argument("--graph", action="store_true",
                                help="through sim_node + learner_node processes (a pair per arm, all at once)")
    bench_transfer.add_argument("--tabulate", type=Path, nargs="+", default=None, metavar="REPORT",
                                help="run nothing: tabulate together the goals of these earlier reports (made "
                                     "with this --budget and --eval-interval)")
    bench_transfer.add_argument("--out", type=Path, default=Path("bench/results/transfer.md"))
    bench_transfer.set_defaults(func=cmd_bench_transfer)

    bench_cost = bench_commands.add_parser(
        "cost", help="a learning-cost map: steps to B per object from the prior, stopped at B and capped, "
        "row medians, Spearman(letter, steps), a 7x7 heat map (resumable)")
    bench_cost.add_argument("--tasks", default=cost_bench.DEFAULT_TASKS,
                            help=f"all, per-row:K (K objects per row, every column covered), or comma-separated "
                                 f"tasks (default: {cost_bench.DEFAULT_TASKS})")
    _add_cost_goal_arguments(bench_cost, transfer_defaults.num_envs)
    bench_cost.add_argument("--recipe", default=PROFILE_RECIPE,
                            help=f"the goals' fine-tuning recipe: {PROFILE_RECIPE} (the profile's own) or one of "
                                 f"{', '.join(FINE_TUNING_RECIPES)}")
    bench_cost.add_argument("--against", type=Path, default=None, metavar="REPORT",
                            help="another map's report of the same settings (another recipe's): the report "
                                 "adds issue 45's targets and the goals that trained, side by side")
    bench_cost.add_argument("--tabulate", action="store_true",
                            help="run nothing: report the goals of these tasks and seeds that --work-dir holds "
                                 "(same settings)")
    bench_cost.add_argument("--out", type=Path, default=cost_bench.DEFAULT_REPORT,
                            help="the report; the heat map is written beside it as .png")
    bench_cost.set_defaults(func=cmd_bench_cost)
    bench_stones = bench_commands.add_parser(
        "stones", help="steps to B on each target from the policy that learned the object of the row above, "
        "against from the prior, in a cost map's work directory (resumable)")
    bench_stones.add_argument("--targets", default="G0,G1,G2,G3,G4,G5,G6",
                              help="comma-separated objects, none in row A (default: row G)")
    _add_cost_goal_arguments(bench_stones, transfer_defaults.num_envs)
    bench_stones.add_argument("--out", type=Path, default=Path("bench/results/stones.md"), help="the report")
    bench_stones.set_defaults(func=cmd_bench_stones)

    bench_curriculum = bench_commands.add_parser(
        "curriculum", help="the paper's comparison: strategies x seeds at one training budget through the graph "
        "(glocal-ros experiment, resumable), then learned objects per milestone, ratios, t-tests, cost")
    add_experiment_arguments(bench_curriculum, preset=BENCH_PRESET)
    bench_curriculum.add_argument("--out", type=Path, default=DEFAULT_OUT,
                                  help=f"the runs, <strategy>-seed<N>/ each (default: {DEFAULT_OUT})")
    bench_curriculum.add_argument("--merge", type=Path, nargs="+", default=[], metavar="DIR",
                                  help="more runs for the table: run directories, or other benches' --out")
    bench_curriculum.add_argument("--tabulate", action="store_true",
                                  help="run nothing: tabulate the runs of --out, --keep and --merge")
    bench_curriculum.add_argument("--results", type=Path, default=DEFAULT_RESULTS,
                                  help="the table; the report's figures go to a folder of its name beside it")
    bench_curriculum.add_argument("--keep", type=Path, default=None,
                                  help="where each finished run is kept, small enough to commit, and restored from "
                                       "into --out (default: beside --results, curriculum.md -> curriculum-runs)")
    add_run_arguments(bench_curriculum)
    bench_curriculum.set_defaults(func=cmd_bench_curriculum)

    bench_scale = bench_commands.add_parser(
        "scale", help="a scaling model fitted on a recorded sequential run: the wall-clock of the same run with K "
        "pairs (the real scheduler on a virtual clock) and of the paper's grid on M machines")
    bench_scale.add_argument("run_dir", type=Path, metavar="RUN_DIR",
                             help="a finished sequential run (its curriculum/journal.jsonl and bag/)")
    bench_scale.add_argument("--validate", type=Path, nargs="+", default=[], metavar="RUN_DIR",
                             help="runs to predict from their own settings, K and answers, beside their measured "
                                  "wall-clock")
    bench_scale.add_argument("--pairs", type=number_list, default=[1, 2, 4, 8], help="K to predict (default 1,2,4,8)")
    bench_scale.add_argument("--machines", type=number_list, default=[1, 10, 40],
                             help="M for the paper's grid (default 1,10,40)")
    bench_scale.add_argument("--out", type=Path, default=Path("bench/results/scale.md"))
    bench_scale.set_defaults(func=cmd_bench_scale)


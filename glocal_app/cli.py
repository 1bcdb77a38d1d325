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

from glocal_app.bag_cli import add_bag_commands
from glocal_app.benches import cost as cost_bench
from glocal_app.benches.curriculum import BENCH_PRESET, DEFAULT_OUT, DEFAULT_RESULTS
from glocal_app.benches.transfer import INITIAL_POLICY, PROFILE_RECIPE, TRANSFER_TASKS, TransferSettings
from glocal_app.nodes import NODES
from glocal_app.ray_runs import DEFAULT_CPUS_PER_RUN
from glocal_ros.curriculum.codes import STRATEGY_NAMES
from glocal_ros.curriculum.learner import paper_threshold, passes_threshold
from glocal_ros.paths import assets_dir, object_urdf, objects_dir
from glocal_ros.tasks import parse_task_list, sorted_tasks
from learner_node.prior import PriorConfig
from learner_node.profiles import DEFAULT_PROFILE, PROFILES, learner_profile
from learner_node.sac_settings import (DEFAULT_NETWORK, DEFAULT_RECIPE, EXPERIENCE_TRANSITIONS, FINE_TUNING_RECIPES,
                                       NETWORKS)

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

    scores = evaluate_policy(args.policy, parse_task_list(args.tasks), args.episodes, args.seed, args.timeout)
    if args.json:
        print(json.dumps({task: successes for task, successes, _ in scores}))
    else:
        for task, successes, episodes in scores:
            print(f"{task}: {successes}/{episodes}")
    return 0


def cmd_launch(args: argparse.Namespace) -> int:
    from glocal_app.launch import launch

    graph = dict(namespace=args.namespace, use_sim_time=args.use_sim_time, learner_profile=args.profile)
    if args.watchdog is None:
        return launch(args.strategy, args.preset, args.seed, args.out, **graph)
    if args.watchdog <= 0:
        raise ValueError(f"--watchdog must be positive, got {args.watchdog}")
    return launch(args.strategy, args.preset, args.seed, args.out, watchdog_sec=args.watchdog, **graph)


def cmd_experiment(args: argparse.Namespace) -> int:
    from glocal_app.launch import experiment

    return experiment(args.strategies, args.seeds, args.preset, args.out, namespace=args.namespace,
                      use_sim_time=args.use_sim_time, step_budget=args.budget, learner_profile=args.profile,
                      ray_address=args.ray, ray_cpus_per_run=args.ray_cpus_per_run)


def _name_list(text: str) -> list[str]:
    """An argparse type: comma-separated names (checked by whoever takes them)."""
    return [name.strip() for name in text.split(",") if name.strip()]


def _seed_list(text: str) -> list[int]:
    """An argparse type: comma-separated non-negative integer seeds."""
    items = [item.strip() for item in text.split(",")]
    if not all(item.isdigit() for item in items):
        raise argparse.ArgumentTypeError(f"{text!r}: expected comma-separated non-negative integers, e.g. 0,1,2")
    return [int(item) for item in items]


def add_experiment_arguments(parser: argparse.ArgumentParser, preset: str) -> None:
    """What ``experiment`` and ``bench curriculum`` share: which runs, at which preset and budget."""
    parser.add_argument("--strategies", type=_name_list, default=list(STRATEGY_NAMES),
                        help=f"comma-separated, of {', '.join(STRATEGY_NAMES)} (default: all)")
    parser.add_argument("--seeds", type=_seed_list, default=[0, 1, 2], help="comma-separated (default: 0,1,2)")
    parser.add_argument("--preset", default=preset, help=f"a parameter file of assets/params (default: {preset})")
    parser.add_argument("--budget", type=_count(1), default=None, metavar="STEPS",
                        help="training steps of every run, instead of the preset's step_budget")
    parser.add_argument("--ray", default=None, metavar="ADDRESS",
                        help="run the runs as tasks of the Ray cluster at ADDRESS (HOST:PORT of its head, e.g. "
                             "10.0.0.5:6379), or of a Ray instance started on this machine (local); the run "
                             "directories come back to --out (default: one after another, here)")
    parser.add_argument("--ray-cpus-per-run", type=_count(1), default=DEFAULT_CPUS_PER_RUN, metavar="N",
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
    add_profile_argument(parser, default=None)


def add_profile_argument(parser: argparse.ArgumentParser, default: str | None = DEFAULT_PROFILE) -> None:
    """``--profile``: the learner profile; a default of None leaves it to the preset."""
    parser.add_argument("--profile", default=default, choices=list(PROFILES),
                        help="the learner profile: how policies learn and are scored (learner_node/profiles.py)"
                             + ("; default: the preset's" if default is None else ""))


def _count(minimum: int):
    """An argparse type: an integer of at least ``minimum``."""
    def parse(text: str) -> int:
        value = int(text)
        if value < minimum:
            raise argparse.ArgumentTypeError(f"{value} is below {minimum}")
        return value
    parse.__name__ = "int"  # argparse names the type in its message: "invalid int value"
    return parse


def _progress(stage: str, done: int, total: int) -> None:
    if done == total or done % max(1, total // 20) == 0:
        print(f"{stage}: {done}/{total}", flush=True)


def cmd_assets_generate(args: argparse.Namespace) -> int:
    from functools import partial

    from glocal_ros.objects import GeneratorConfig, MeasuredGrid, generate_object_set
    from sim_node.scripted_grasp import grasp_trial

    shortlist = {} if args.per_column is None else {"per_column": args.per_column}
    lifting_poses = _lifting_pose_check(args)
    measured = None
    if args.grid == "measured":
        measured = MeasuredGrid(partial(grasp_trial, perturbed_episodes=args.perturbed_episodes), **shortlist)
    elif args.grid == "lifting-poses":
        measured = MeasuredGrid(lifting_poses.trial, letter_by="lifting poses", **shortlist)
    generate_object_set(args.out, seed=args.seed, candidates=args.candidates, workers=args.workers,
                        progress=_progress, measured=measured, lifting_poses=lifting_poses,
                        config=GeneratorConfig(envelope=args.envelope))
    print(f"wrote {args.out}")
    return cmd_assets_check(args) if args.check_episodes else 0


def cmd_assets_import_egad(args: argparse.Namespace) -> int:
    from glocal_ros.objects import BadMeshError, MissingEgadFilesError, UnliftableObjectError, import_egad

    try:
        import_egad(args.egad_dir, args.out, require_all=not args.partial, progress=_progress,
                    lifting_poses=_lifting_pose_check(args))
    except (BadMeshError, MissingEgadFilesError, UnliftableObjectError) as error:
        print(f"assets import-egad: {error}; {args.out} is unchanged", file=sys.stderr)
        return 1
    print(f"wrote {args.out}")
    return cmd_assets_check(args) if args.check_episodes else 0


def cmd_assets_check(args: argparse.Namespace) -> int:
    """The scripted grasp and the perturbed grasp on every object; rates stored in objects.json. Exit 1 when an
    object is never grasped by the scripted grasp and no best pose of at least ``MIN_BEST_POSE_SUCCESS`` is on
    record for it: a slab the centred descent never lifts is learnable when another top-down pose lifts it."""
    from glocal_ros.objects import MIN_BEST_POSE_SUCCESS, ObjectSetMetadata, never_grasped, record_grasp_success
    from sim_node.scripted_grasp import GraspErrors, graspability

    objects = ObjectSetMetadata.load(args.out).objects
    tasks = sorted_tasks(objects)
    scripted = graspability(args.out, tasks, args.check_episodes, seed=args.seed,
                            progress=lambda task, rate: print(f"{task}: scripted grasp {rate:.0%}", flush=True))
    perturbed = graspability(args.out, tasks, args.perturbed_episodes, seed=args.seed, errors=GraspErrors(),
                             progress=lambda task, rate: print(f"{task}: perturbed grasp {rate:.0%}", flush=True))
    record_grasp_success(args.out, scripted, perturbed)
    best_poses = {task: objects[task].best_pose_success for task in tasks}
    never, unlearnable = never_grasped(scripted, best_poses)
    never_text = ", ".join(f"{task} (best pose: " + ("not measured" if best_poses[task] is None
                                                     else f"{best_poses[task]:.0%}") + ")" for task in never)
    print(f"scripted grasp: mean {sum(scripted.values()) / len(scripted):.0%}, lowest "
          f"{min(scripted.values()):.0%}; never grasped: {never_text or 'none'}")
    print(f"perturbed grasp: mean {sum(perturbed.values()) / len(perturbed):.0%}, lowest "
          f"{min(perturbed.values()):.0%}, highest {max(perturbed.values()):.0%}")
    if unlearnable:
        print(f"not learnable: {', '.join(unlearnable)} (never grasped, and no best pose of at least "
              f"{MIN_BEST_POSE_SUCCESS:.0%} on record: glocal-ros assets lifting-poses)", file=sys.stderr)
    return 1 if unlearnable else 0


def _lifting_pose_check(args: argparse.Namespace):
    """The asset commands' share of lifting poses, and their rule that every object stays learnable."""
    from functools import partial

    from glocal_ros.objects import LiftingPoseCheck
    from sim_node.lifting_poses import LiftingPoseSettings, lifting_pose_trial

    settings = LiftingPoseSettings()
    return LiftingPoseCheck(partial(lifting_pose_trial, settings=settings), seed=args.seed,
                            workers=getattr(args, "workers", 1), settings=settings.to_dict())


def cmd_assets_lifting_poses(args: argparse.Namespace) -> int:
    """The share of top-down poses that lift each object and its best pose's success, into objects.json."""
    from glocal_ros.objects import ObjectSetMetadata, measure_lifting_poses, record_lifting_poses, unliftable

    check = _lifting_pose_check(args)
    tasks = sorted_tasks(ObjectSetMetadata.load(args.out).objects)
    results = measure_lifting_poses(args.out, tasks, check.trial, check.seed, check.workers, _progress)
    record_lifting_poses(args.out, results, check.record())
    for task, (share, best) in results.items():
        print(f"{task}: lifting poses {share:.0%}, best pose {best:.0%}")
    failing = unliftable(results, check.min_best_pose_success)
    print(f"recorded in {args.out / 'objects.json'}; best pose below {check.min_best_pose_success:.0%}: "
          f"{', '.join(failing) or 'none'}")
    return 1 if failing else 0


def cmd_assets_show(args: argparse.Namespace) -> int:
    from glocal_ros.objects import ObjectSetMetadata

    def rate(value: float | None) -> str:
        return "-" if value is None else f"{value:.0%}"

    metadata = ObjectSetMetadata.load(args.out)
    print(f"{'task':4} {'complexity':>10} {'difficulty':>10} {'extents (cm)':>18} {'mass (g)':>8} {'hulls':>5} "
          f"{'scripted':>8} {'perturbed':>9}")
    for task in sorted_tasks(metadata.objects):
        obj = metadata.objects[task]
        extents = "x".join(f"{100 * e:.1f}" for e in obj.extents)
        print(f"{task:4} {obj.complexity:10.2f} {obj.difficulty:10.3f} {extents:>18} {1000 * obj.mass:8.0f} "
              f"{obj.hull_count:5d} {rate(obj.scripted_grasp_success):>8} {rate(obj.perturbed_grasp_success):>9}")
    return 0


def cmd_assets_validate(args: argparse.Namespace) -> int:
    """The letter against perturbed and scripted grasp success, the prior's score and steps to B."""
    from glocal_app.benches.assets import prior_scores, steps_to_b, validation_figure, validation_report
    from glocal_app.benches.cost import held_cost_map
    from glocal_app.benches.transfer import read_transfer_goals
    from glocal_ros.objects import ObjectSetMetadata

    metadata = ObjectSetMetadata.load(args.out)
    goals, cost = [], ""
    try:
        if args.cost:
            settings, goals = held_cost_map(args.cost, args.out, args.prior_store)
            cost = (f"the cost map in `{args.cost}` ({len(goals)} goals from the prior, stopped at B, capped at "
                    f"{settings.step_budget} steps, scored every {settings.eval_interval} over "
                    f"{settings.eval_episodes} episodes)")
        elif args.transfer:
            goals = [goal for path in args.transfer for goal in read_transfer_goals(path, TransferSettings())
                     if goal.recipe == args.recipe and goal.prior == INITIAL_POLICY]
            cost = f"goals of {', '.join(map(str, args.transfer))} ({args.recipe})"
    except (OSError, ValueError) as error:
        print(f"assets validate: {error}", file=sys.stderr)
        return 1
    tasks = sorted_tasks(metadata.objects)
    measures = {
        "perturbed": {t: o.perturbed_grasp_success for t, o in metadata.objects.items()
                      if o.perturbed_grasp_success is not None},
        "scripted": {t: o.scripted_grasp_success for t, o in metadata.objects.items()
                     if o.scripted_grasp_success is not None},
        "lifting_poses": {t: o.lifting_pose_share for t, o in metadata.objects.items()
                          if o.lifting_pose_share is not None},
        "best_pose": {t: o.best_pose_success for t, o in metadata.objects.items()
                      if o.best_pose_success is not None},
        "prior": (prior_scores(args.out, tasks, args.episodes, seed=args.seed, prior_store=args.prior_store)
                  if args.episodes else {}),
        "steps_to_b": steps_to_b(goals),
    }
    figure = validation_figure(measures, args.report.with_suffix(".png"))
    command = "glocal-ros " + " ".join(sys.argv[1:])
    preamble = (f"Objects: `{args.out}` (generator {metadata.generator_version}, {metadata.source}). (a) and (b) "
                f"from its `objects.json` (`glocal-ros assets check`), as are lifting poses and the best pose "
                f"(`glocal-ros assets lifting-poses`); (c) {args.episodes} deterministic "
                f"episodes of the prior ({args.prior_store or 'shipped'}) per object (seed {args.seed}), task "
                f"bits it never trained on as the mean of the trained one; (d) steps to B from "
                f"{cost or 'no goals'}. Figure: `{figure.name}`.")
    return write_bench_report(validation_report(measures, command, preamble), args.report)


def cmd_bench_stones(args: argparse.Namespace) -> int:
    """Steps to B on hard objects from the policy that learned the row above (``glocal_app.benches.stones``)."""
    from glocal_app.benches.cost import GOALS_FILE, cost_settings
    from glocal_app.benches.stones import STONES_FILE, run_stones, stones_report

    settings = cost_settings(args.step_budget, args.eval_interval, args.eval_episodes, args.envs, args.objects_dir)
    try:
        direct, chains = run_stones(parse_task_list(args.targets), args.seeds, settings, args.work_dir, args.jobs,
                                    args.profile, args.prior_store)
    except KeyboardInterrupt:
        print(f"bench stones: interrupted; what finished is kept in {args.work_dir / GOALS_FILE} and "
              f"{args.work_dir / STONES_FILE}: the same command resumes", file=sys.stderr)
        return 130
    command = "glocal-ros " + " ".join(sys.argv[1:])
    return write_bench_report(stones_report(direct, chains, command, settings, args.work_dir), args.out)


def write_bench_report(report: str, out: Path) -> int:
    """Show a bench's report and write it to ``out`` (with the command that made it, inside)."""
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(report)
    print(report, end="")
    print(f"written to {out}")
    return 0


def cmd_bench_sim(args: argparse.Namespace) -> int:
    from glocal_app.benches.sim import run_sim_bench, sim_bench_report

    env_counts = [int(n) for n in args.envs.split(",")]
    rows = run_sim_bench(env_counts, args.batches, args.rounds)
    report = sim_bench_report(rows, "glocal-ros " + " ".join(sys.argv[1:]), args.batches, args.rounds)
    return write_bench_report(report, args.out)


def cmd_bench_learner(args: argparse.Namespace) -> int:
    from glocal_app.benches.learner import learner_bench_report, run_learner_bench

    env_counts = [int(n) for n in args.envs.split(",")]
    rows = run_learner_bench(env_counts, args.steps, args.rounds, learner_node=not args.no_learner_node,
                             profile=args.profile)
    report = learner_bench_report(rows, "glocal-ros " + " ".join(sys.argv[1:]), args.steps, args.rounds)
    return write_bench_report(report, args.out)


def cmd_bench_backends(args: argparse.Namespace) -> int:
    from glocal_app.benches.backends import backends_bench_report, run_backends_bench

    rows = run_backends_bench([int(n) for n in args.envs.split(",")], args.steps, args.rounds, args.network)
    report = backends_bench_report(rows, "glocal-ros " + " ".join(sys.argv[1:]), args.steps, args.rounds,
                                   args.network)
    return write_bench_report(report, args.out)


def cmd_bench_graph(args: argparse.Namespace) -> int:
    from glocal_app.benches.graph import graph_bench_report, run_graph_bench

    if min(args.goals, args.evaluations, args.steps) < 1:
        raise ValueError("--goals, --evaluations and --steps must be at least 1")
    rows = run_graph_bench(args.goals, args.evaluations, args.steps)
    report = graph_bench_report(rows, "glocal-ros " + " ".join(sys.argv[1:]))
    write_bench_report(report, args.out)
    return 0 if all(row.lost == 0 for row in rows) else 1


def cmd_bench_transfer(args: argparse.Namespace) -> int:
    from glocal_app.benches.transfer import (read_transfer_goals, run_transfer_bench, run_transfer_graph,
                                             transfer_bench_report)

    settings = TransferSettings(step_budget=args.budget, eval_interval=args.eval_interval,
                                eval_episodes=args.eval_episodes, num_envs=args.envs, objects_dir=args.objects_dir)
    command = "glocal-ros " + " ".join(sys.argv[1:])
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
            return 1
        return write_bench_report(transfer_bench_report(goals, command, settings, 0, sources=args.tabulate),
                                  args.out)
    seeds = [int(seed) for seed in args.seeds.split(",")]
    recipes, tasks, priors = args.recipes.split(","), args.tasks.split(","), args.priors.split(",")
    arms = dict(priors=priors, prior_store=args.prior_store, profiles=args.profiles.split(","))
    goals = (run_transfer_graph(recipes, tasks, seeds, settings, **arms) if args.graph
             else run_transfer_bench(recipes, tasks, seeds, settings, args.jobs, **arms))
    report = transfer_bench_report(goals, command, settings, args.jobs, args.graph)
    return write_bench_report(report, args.out)


def cmd_bench_cost(args: argparse.Namespace) -> int:
    """A learning-cost map: steps to B per object and seed from the prior (``glocal_app.benches.cost``)."""
    from glocal_app.benches.cost import (GOALS_FILE, check_cost, cost_figure, cost_report, cost_settings,
                                         finished_goals, run_cost_map, select_tasks)

    settings = cost_settings(args.step_budget, args.eval_interval, args.eval_episodes, args.envs,
                             args.objects_dir)
    tasks = select_tasks(args.tasks)
    command = "glocal-ros " + " ".join(sys.argv[1:])
    if args.tabulate:
        check_cost(tasks, args.seeds, settings, args.jobs, args.profile, args.prior_store)
        held = finished_goals(args.work_dir, settings, args.profile, args.prior_store)
        goals = [held[(task, seed)] for task in tasks for seed in args.seeds if (task, seed) in held]
        if not goals:
            print(f"bench cost --tabulate: no finished goal of these tasks and seeds in {args.work_dir / GOALS_FILE}",
                  file=sys.stderr)
            return 1
    else:
        try:
            goals = run_cost_map(tasks, args.seeds, settings, args.work_dir, args.jobs, args.profile,
                                 prior_store=args.prior_store)
        except KeyboardInterrupt:
            print(f"bench cost: interrupted; the finished goals are kept in {args.work_dir / GOALS_FILE}: the same "
                  "command resumes", file=sys.stderr)
            return 130
    figure = cost_figure(goals, settings, args.out.with_suffix(".png"))
    report = cost_report(goals, command, settings, tasks, args.seeds, args.jobs, figure, args.work_dir,
                         tabulated=args.tabulate, profile=args.profile)
    write_bench_report(report, args.out)
    print(f"figure: {figure}")
    return 0


def cmd_bench_curriculum(args: argparse.Namespace) -> int:
    from glocal_app.benches.curriculum import (bench_inputs, check_bench, keep_finished_runs, keep_run,
                                               kept_runs_dir, restore_kept_runs, tabulate_curriculum_bench)

    command = "glocal-ros " + " ".join(sys.argv[1:])
    keep = args.keep or kept_runs_dir(args.results)
    code = 0
    if not args.tabulate:
        check_bench(args.strategies, args.seeds, args.preset, args.out, args.budget, args.profile, keep)
        bench_inputs(args.out, args.merge)  # a --merge that holds no run is refused before the first run
        from glocal_app.launch import experiment

        def keep_and_restore() -> None:  # once the Ray cluster, if any, is checked too
            keep_finished_runs(args.out, keep)  # runs that finished before this command
            for run_dir in restore_kept_runs(keep, args.out):
                print(f"{run_dir.name}: restored from {keep}")

        code = experiment(args.strategies, args.seeds, args.preset, args.out, step_budget=args.budget, report=False,
                          learner_profile=args.profile, finished=lambda run_dir: keep_run(run_dir, keep),
                          ray_address=args.ray, ray_cpus_per_run=args.ray_cpus_per_run, prepare=keep_and_restore)
        if code == 130:  # interrupted: the same command resumes
            return code
    report = tabulate_curriculum_bench(bench_inputs(args.out, args.merge, keep), command, args.results)
    write_bench_report(report, args.results)
    return code


def cmd_train_prior(args: argparse.Namespace) -> int:
    """Train the A0 prior in-process, evaluate it, store it (as `prior` in assets/priors by default)."""
    from tqdm import tqdm

    from learner_node.evaluation import evaluate
    from learner_node.policy_store import PolicyRecord, PolicyStore, check_name
    from learner_node.prior import train_prior
    from learner_node.replay_buffer import recent_experience
    from learner_node.sac_settings import EXPERIENCE_TRANSITIONS
    from sim_node.batch import BatchedEnvs
    from sim_node.grasp_env import GraspEnv
    from sim_node.scripted_grasp import ScriptedGraspPolicy

    check_name(args.name)
    config = PriorConfig(max_steps=args.steps, min_steps=args.min_steps, seed=args.seed, network=args.network,
                         profile=args.profile)
    profile = learner_profile(config.profile)
    work_dir = args.work_dir or Path("build") / f"prior-{config.profile}"
    bar = tqdm(total=config.max_steps, unit="step", desc="A0 prior")

    def progress(steps: int, success_rate: float) -> None:
        bar.n = steps
        if steps % 250 == 0:
            bar.set_postfix(success=f"{success_rate:.0%}")
            bar.refresh()

    model = train_prior(lambda: GraspEnv(config.task, args.objects_dir), ScriptedGraspPolicy().act, work_dir, config,
                        progress)
    bar.close()
    batch = BatchedEnvs(lambda i: GraspEnv(config.task, args.objects_dir), 2, config.task)
    try:
        (score,) = evaluate(batch, lambda obs: model.predict(obs, deterministic=True)[0], [config.task],
                            args.eval_episodes, policy_name=args.name, seed=args.seed + 1)
    finally:
        batch.close()
    print(f"{args.name}: {score.successes}/{score.episodes} on {config.task} after {model.num_timesteps} steps")
    record = PolicyRecord(name=args.name, task=config.task, steps_trained=model.num_timesteps,
                          last_score=float(score.successes), last_score_task=config.task,
                          profile=config.profile,
                          extra={"eval_episodes": score.episodes, "demo_episodes": config.demo_episodes,
                                 "seed": config.seed, "network": config.network or profile.network,
                                 **({"objects_dir": str(args.objects_dir)} if args.objects_dir else {})})
    PolicyStore(args.out).save(model, record, recent_experience(model.replay_buffer, EXPERIENCE_TRANSITIONS))
    print(f"stored in {args.out}/{args.name}")
    threshold = paper_threshold(score.episodes) if args.threshold is None else args.threshold
    return 0 if passes_threshold(score.successes, threshold) else 1


def cmd_collect_experience(args: argparse.Namespace) -> int:
    """Give a stored policy experience: it acts on its task as SAC acts in training; the model is unchanged."""
    from learner_node.policy_store import PolicyStore
    from learner_node.prior import collect_experience
    from sim_node.grasp_env import GraspEnv

    if args.transitions < 1:
        raise ValueError(f"--transitions must be at least 1, got {args.transitions}")
    source = PolicyStore(args.store)
    if args.name not in source:
        raise ValueError(f"no policy {args.name!r} in {source.root}")
    record = source.record(args.name)
    out = PolicyStore(args.out or args.store)
    if out.root.resolve() != source.root.resolve():
        out.add_copy(source, args.name, args.name)
    env = GraspEnv(record.task)
    try:
        experience = collect_experience(source.load(args.name), env, args.transitions, args.seed)
    finally:
        env.close()
    out.keep_experience(args.name, experience)
    successes = int((experience["dones"] - experience["timeouts"]).sum())  # episodes that ended by a lift
    print(f"{args.name}: {len(experience['dones'])} transitions on {record.task}, {successes} successful "
          f"episodes, kept in {out.root}/{args.name}")
    return 0


def cmd_policy_import(args: argparse.Namespace) -> int:
    """Convert a policy of stable-baselines3's zip (the format before arrays and JSON) into a store: loading the
    zip unpickles it, which runs whatever code it holds, so only with ``--trust``.

    A zip that is the model of a store's policy (its folder's policy.json names it) keeps that record (task,
    steps, scores, profile, layout, extra) and experience; a bare zip becomes a policy of ``--profile`` on the
    sim's observation layout, named ``--name``.
    """
    from learner_node.model_files import load_pickled_model
    from learner_node.policy_store import PolicyRecord, PolicyStore, check_name
    from learner_node.replay_buffer import load_experience

    if not args.trust:
        raise ValueError(f"importing {args.zip} unpickles it, which runs any code it holds: pass --trust only for "
                         "a file you made or whose maker you trust")
    record, experience = _record_beside(args.zip)
    if record is None:
        if not args.name:
            raise ValueError(f"no policy.json beside {args.zip} names it: name the policy with --name")
        record = PolicyRecord(name=args.name, profile=args.profile or DEFAULT_PROFILE)
    elif args.profile and args.profile != record.profile:
        raise ValueError(f"{args.zip} is a policy of profile {record.profile!r} (its policy.json), not "
                         f"{args.profile!r}")
    source_folder = args.zip.resolve().parent
    record.name = check_name(args.name or record.name)
    store = PolicyStore(args.store)
    if record.name in store and (store.root / record.name).resolve() != source_folder:
        raise ValueError(f"policy {record.name!r} exists in {store.root} already: choose another --name")
    print(f"{args.zip}: loading it runs the code it holds (--trust)", flush=True)
    model = load_pickled_model(args.zip)
    if experience is not None:
        experience = load_experience(experience)
    stored = store.save(model, record, experience)
    kept = f" and {stored.experience_file}" if stored.experience_file else ""
    print(f"{stored.name}: stored in {store.root} as {stored.model_file}{kept} (arrays and JSON)")
    return 0


def _record_beside(zip_path: Path):
    """(the record of the store policy whose model ``zip_path`` is, its experience file or None), or (None, None)."""
    from learner_node.policy_store import METADATA_FILE, PolicyStore

    folder = zip_path.resolve().parent
    if not (folder / METADATA_FILE).is_file():
        return None, None
    record = PolicyStore(folder.parent).record(folder.name)
    if record.model_file != zip_path.name:
        return None, None
    return record, (folder / record.experience_file if record.experience_file else None)


def _add_rate_arguments(parser: argparse.ArgumentParser, envs: str, steps: int) -> None:
    """The env counts, timed steps and rounds of a bench that times SAC learning (learner, backends)."""
    parser.add_argument("--envs", default=envs, help="comma-separated env counts N")
    parser.add_argument("--steps", type=int, default=steps, help="env steps timed per measurement, after a "
                        "warm-up of batch_size + 64 + N steps")
    parser.add_argument("--rounds", type=int, default=3, help="alternating rounds; the median is reported")


def _add_prior_store_argument(command: argparse.ArgumentParser) -> None:
    command.add_argument("--prior-store", type=Path, default=None, metavar="DIR",
                         help="a policy store searched for the prior before the profile's shipped one "
                              "(train-prior --out; for a set of another A0)")


def _add_cost_goal_arguments(command: argparse.ArgumentParser, default_envs: int) -> None:
    """What decides a cost map's goals, and where they are kept: ``bench cost``'s and ``bench stones``'."""
    command.add_argument("--seeds", type=_seed_list, default=list(cost_bench.DEFAULT_SEEDS),
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
    _add_prior_store_argument(command)
    command.add_argument("--work-dir", type=Path, default=cost_bench.DEFAULT_WORK_DIR,
                         help="where each goal is kept as it finishes (goals.jsonl), for the same command to "
                              f"skip (default: {cost_bench.DEFAULT_WORK_DIR})")


def build_parser() -> argparse.ArgumentParser:
    from glocal_ros.analysis.report import add_report_command

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

    assets = commands.add_parser("assets", help="the object set: generate, import EGAD, check, lifting poses, "
                                     "show, validate")
    asset_commands = assets.add_subparsers(dest="assets_command", required=True)
    generate = asset_commands.add_parser("generate", help="generate the 49 objects (seeded, about 25 minutes)")
    generate.add_argument("--seed", type=int, default=0)
    generate.add_argument("--candidates", type=int, default=1500, help="candidate shapes to bin into the grid")
    generate.add_argument("--workers", type=int, default=2)
    generate.add_argument("--grid", choices=("measured", "lifting-poses", "geometric"), default="lifting-poses",
                          help="letters from the share of top-down poses that lift each candidate (lifting-poses, "
                               "the committed set's), from the perturbed grasp in the simulator (measured, "
                               "faster), or from the geometric difficulty alone")
    generate.add_argument("--per-column", type=_count(7), default=None,
                          help="candidates of each complexity digit tried in the simulator (--grid measured or "
                               "lifting-poses; default: glocal_ros.objects.MeasuredGrid's)")
    # glocal_ros.objects.cppn.ENVELOPES, named here: the object package takes a second to import.
    generate.add_argument("--envelope", choices=("blob", "wide"), default="wide",
                          help="base solids: wide (blobs, slabs and rods, tapered: the committed set's), or "
                               "EGAD-like blobs (glocal_ros/objects/cppn.py)")
    generate.set_defaults(func=cmd_assets_generate)
    egad = asset_commands.add_parser("import-egad", help="the same layout from EGAD's A0.obj .. G6.obj")
    egad.add_argument("egad_dir", type=Path)
    egad.add_argument("--partial", action="store_true", help="import whichever of the 49 files exist")
    egad.add_argument("--seed", type=int, default=0, help="seed of the scripted grasp check")
    egad.set_defaults(func=cmd_assets_import_egad)
    check = asset_commands.add_parser("check", help="scripted and perturbed grasp success of every object, into "
                                      "objects.json")
    check.add_argument("--seed", type=int, default=0)
    check.set_defaults(func=cmd_assets_check)
    poses = asset_commands.add_parser(
        "lifting-poses", help="the share of top-down poses that lift each object and its best pose's success, "
        "into objects.json (exit 1 if a best pose lifts its object less than 80%% of the time)")
    poses.add_argument("--seed", type=int, default=0)
    poses.add_argument("--workers", type=_count(1), default=2, help="processes, one object each (default 2)")
    poses.set_defaults(func=cmd_assets_lifting_poses)
    show = asset_commands.add_parser("show", help="every object's metrics")
    show.set_defaults(func=cmd_assets_show)
    validate = asset_commands.add_parser(
        "validate", help="Spearman between the letter and grasp success, the prior's score and steps to B")
    validate.add_argument("--episodes", type=_count(0), default=100,
                          help="episodes of the prior per object (0: none)")
    validate.add_argument("--seed", type=int, default=0)
    steps_source = validate.add_mutually_exclusive_group()
    steps_source.add_argument("--cost", type=Path, default=None, metavar="WORK_DIR",
                              help="a bench cost work directory (of this set) whose goals give steps to B")
    steps_source.add_argument("--transfer", type=Path, nargs="*", help="bench transfer reports (default budget) "
                              "whose goals give steps to B")
    validate.add_argument("--recipe", default=DEFAULT_RECIPE, help="the transfer reports' recipe to use")
    _add_prior_store_argument(validate)
    validate.add_argument("--report", type=Path, default=Path("bench/results/assets-validate.md"),
                          help="the report; the figure is written beside it as .png")
    validate.set_defaults(func=cmd_assets_validate)
    for command in (generate, egad, check, poses, show, validate):
        command.add_argument("--out", type=Path, default=None, help="objects directory (default: the package's)")
    for command in (generate, egad, check):
        command.add_argument("--check-episodes", type=_count(0), default=30,
                             help="scripted grasp episodes per object (0: no check)")
        command.add_argument("--perturbed-episodes", type=_count(1), default=40,
                             help="perturbed grasp episodes per object (and per candidate tried)")

    bench = commands.add_parser("bench", help="benchmarks; each writes its table with the command that made it")
    bench_commands = bench.add_subparsers(dest="bench_command", required=True)
    bench_sim = bench_commands.add_parser("sim", help="env steps/s in-process vs through sim_node")
    bench_sim.add_argument("--envs", default="1,2,4", help="comma-separated env counts N")
    bench_sim.add_argument("--batches", type=int, default=500, help="lockstep batches per measurement")
    bench_sim.add_argument("--rounds", type=int, default=3, help="alternating rounds; the median is reported")
    bench_sim.add_argument("--out", type=Path, default=Path("bench/results/sim.md"))
    bench_sim.set_defaults(func=cmd_bench_sim)
    bench_graph = bench_commands.add_parser("graph", help="lost answers under stress: Train goals, learner/evaluate "
                                            "and sim/step calls, 1 and 4 threads, with and without a CPU burner")
    bench_graph.add_argument("--goals", type=int, default=1000, help="short Train goals per row")
    bench_graph.add_argument("--evaluations", type=int, default=1000, help="learner/evaluate calls per row")
    bench_graph.add_argument("--steps", type=int, default=5000, help="sim/step calls per row")
    bench_graph.add_argument("--out", type=Path, default=Path("bench/results/graph.md"))
    bench_graph.set_defaults(func=cmd_bench_graph)
    bench_learner = bench_commands.add_parser("learner", help="SAC env steps/s with updates, in-process vs through "
                                              "sim_node and learner_node")
    _add_rate_arguments(bench_learner, envs="1,2,4", steps=300)
    bench_learner.add_argument("--no-learner-node", action="store_true",
                               help="leave out the learner_node process (its Train action) column")
    bench_learner.add_argument("--out", type=Path, default=Path("bench/results/learner.md"))
    add_profile_argument(bench_learner)
    bench_learner.set_defaults(func=cmd_bench_learner)
    bench_backends = bench_commands.add_parser("backends", help="SAC env steps/s of stable-baselines3 (torch) and "
                                               "SBX (JAX), side by side: how the learner's backend was chosen")
    _add_rate_arguments(bench_backends, envs="1,4", steps=2000)
    bench_backends.add_argument("--network", choices=list(NETWORKS), default=DEFAULT_NETWORK)
    bench_backends.add_argument("--out", type=Path, default=Path("bench/results/backends.md"))
    bench_backends.set_defaults(func=cmd_bench_backends)
    transfer_defaults = TransferSettings()
    bench_transfer = bench_commands.add_parser(
        "transfer", help="fine-tuning the A0 prior on other objects: steps to B and collapses, recipe by recipe")
    bench_transfer.add_argument("--profiles", default=DEFAULT_PROFILE,
                                help=f"comma-separated learner profiles, of {', '.join(PROFILES)}")
    bench_transfer.add_argument("--recipes", default=PROFILE_RECIPE,
                                help=f"comma-separated fine-tuning recipes: {PROFILE_RECIPE} (each profile's own), "
                                     f"or where the profile allows one, {', '.join(FINE_TUNING_RECIPES)}")
    bench_transfer.add_argument("--priors", default=INITIAL_POLICY,
                                help="comma-separated stored policies the goals start from (each recipe from each)")
    _add_prior_store_argument(bench_transfer)
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
    add_profile_argument(bench_curriculum, default=None)
    bench_curriculum.set_defaults(func=cmd_bench_curriculum)

    prior = commands.add_parser("train-prior", help="train a learner profile's A0 prior (resumable) and store it "
                                "with the profile's shipped priors")
    prior.add_argument("--steps", type=int, default=PriorConfig.max_steps, help="most SAC env steps")
    prior.add_argument("--min-steps", type=int, default=PriorConfig.min_steps,
                       help="SAC env steps before the training success rate may stop it")
    prior.add_argument("--seed", type=int, default=0)
    prior.add_argument("--eval-episodes", type=int, default=100)
    prior.add_argument("--threshold", type=float, default=None,
                       help="B: the prior must score above it (default: 0.75 x --eval-episodes, the paper's)")
    prior.add_argument("--work-dir", type=Path, default=None,
                       help="checkpoints, for resuming (default: build/prior-PROFILE)")
    prior.add_argument("--out", type=Path, default=None,
                       help="policy store (default: the profile's shipped priors, assets/priors for glocal_ros)")
    prior.add_argument("--name", default="prior", help="the policy's name in the store")
    add_profile_argument(prior)
    prior.add_argument("--objects-dir", type=Path, default=None, metavar="DIR",
                       help="the object set whose A0 it trains on (default: the shipped one)")
    prior.add_argument("--network", default="", choices=list(NETWORKS),
                       help="hidden layers and batch of the new model (learner_node/sac_settings.py), where the "
                            "profile allows a choice (default: the profile's)")
    prior.set_defaults(func=cmd_train_prior)

    experience = commands.add_parser(
        "collect-experience", help="give a stored policy experience (for the parent-experience recipe): "
        "transitions of it acting on its task")
    experience.add_argument("name", help="the stored policy")
    experience.add_argument("--store", type=Path, default=None, help="its policy store (default: assets/priors)")
    experience.add_argument("--out", type=Path, default=None, help="the store to write it to (default: --store)")
    experience.add_argument("--transitions", type=int, default=EXPERIENCE_TRANSITIONS)
    experience.add_argument("--seed", type=int, default=0, help="of the first episode; episode k: seed + k")
    experience.set_defaults(func=cmd_collect_experience)

    policy = commands.add_parser("policy", help="stored policies: import one of the format before")
    policy_commands = policy.add_subparsers(dest="policy_command", required=True)
    policy_import = policy_commands.add_parser(
        "import", help="convert a stable-baselines3 zip (the pickled format before) into a policy store; "
        "LOADING THE ZIP RUNS THE CODE IT HOLDS")
    policy_import.add_argument("zip", type=Path, metavar="ZIP", help="the zip, e.g. <store>/<name>/model-1.zip")
    policy_import.add_argument("--trust", action="store_true",
                               help="you trust the file: it is unpickled, which runs any code in it (required)")
    policy_import.add_argument("--store", type=Path, default=None, metavar="DIR",
                               help="the policy store to write (default: the learner's, $ROS_HOME/glocal_ros/"
                                    "policies); the zip's own store converts it in place")
    policy_import.add_argument("--name", default="",
                               help="the policy's name (default: the one of the policy.json naming the zip)")
    policy_import.add_argument("--profile", default=None, choices=list(PROFILES),
                               help="the learner profile of a zip no policy.json names (default: "
                                    f"{DEFAULT_PROFILE}); a zip of a store keeps its record's")
    policy_import.set_defaults(func=cmd_policy_import)

    launch = commands.add_parser("launch", help="run the whole graph as processes on the ROS_DOMAIN_ID you set, "
                                 "else on a free one; the same command resumes an interrupted run")
    launch.add_argument("--strategy", default="glocal", choices=STRATEGY_NAMES)
    launch.add_argument("--preset", default="demo", help="a parameter file of assets/params: smoke, demo, paper")
    launch.add_argument("--seed", type=int, default=0)
    launch.add_argument("--out", type=Path, required=True,
                        help="run directory: gets bag/, policies/, curriculum/, logs/ and report/")
    launch.add_argument("--watchdog", type=float, default=None, metavar="SEC",
                        help="stop the graph (resumable) when nothing moves for SEC seconds (default: a minute)")
    add_graph_arguments(launch)
    launch.set_defaults(func=cmd_launch)

    experiment = commands.add_parser("experiment", help="strategies x seeds as separate runs (resumable), "
                                     "then one report")
    add_experiment_arguments(experiment, preset="smoke")
    experiment.add_argument("--out", type=Path, required=True, help="gets <strategy>-seed<N>/ per run and report/")
    add_graph_arguments(experiment)
    experiment.set_defaults(func=cmd_experiment)
    add_report_command(commands)
    add_bag_commands(commands)
    return parser


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if args.command == "assets" and args.out is None:
        args.out = objects_dir()
    if args.command == "train-prior" and args.out is None:
        args.out = learner_profile(args.profile).shipped_priors()
    if args.command == "assets" and args.assets_command == "check" and args.check_episodes < 1:
        parser.error("assets check: --check-episodes must be at least 1")
    if args.command == "train-prior" and not 0 <= args.min_steps <= args.steps:
        parser.error(f"train-prior: --min-steps {args.min_steps} must lie between 0 and --steps {args.steps}")
    if args.command == "train-prior" and args.objects_dir and not object_urdf(args.objects_dir, "A0").is_file():
        parser.error(f"train-prior: {args.objects_dir} holds no A0/model.urdf (the layout `assets generate` writes)")
    if args.command == "collect-experience" and args.store is None:
        args.store = assets_dir() / "priors"
    if args.command == "policy" and args.store is None:
        from learner_node.policy_store import default_policy_dir

        args.store = default_policy_dir()
    try:
        return args.func(args)
    except ValueError as error:  # bad input (unknown task, ...): a message, not a traceback
        parser.exit(2, f"glocal-ros {args.command}: error: {error}\n")


if __name__ == "__main__":
    sys.exit(main())

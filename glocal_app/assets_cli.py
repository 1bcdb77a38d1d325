"""``glocal-ros assets ...``: generate, import, check, measure and validate the object set."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from glocal_app.arguments import (
    add_prior_store_argument,
    add_profile_argument,
    command_line,
    count,
    print_progress,
)
from glocal_app.bench_cli import write_bench_report
from glocal_app.benches.transfer import INITIAL_POLICY, TransferSettings
from glocal_app.exit_codes import EXIT_FAILED, EXIT_OK
from glocal_ros.paths import objects_dir
from glocal_ros.tasks import sorted_tasks
from learner_node.profiles import learner_profile
from learner_node.sac_settings import DEFAULT_RECIPE


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
                        progress=print_progress, measured=measured, lifting_poses=lifting_poses,
                        config=GeneratorConfig(envelope=args.envelope))
    print(f"wrote {args.out}")
    return cmd_assets_check(args) if args.check_episodes else 0


def cmd_assets_import_egad(args: argparse.Namespace) -> int:
    """Import EGAD's meshes (repairing those with a few non-manifold edges), measure the lifting poses, then
    ``assets check``. A best pose below the rule is a warning for an imported set (exit 0), a refusal with
    ``--strict`` (exit 1, the measurements kept beside the output)."""
    from glocal_ros.objects import (
        BadMeshError,
        MissingEgadFilesError,
        UnliftableObjectError,
        import_egad,
    )

    try:
        metadata = import_egad(args.egad_dir, args.out, require_all=not args.partial, progress=print_progress,
                               lifting_poses=_lifting_pose_check(args), refuse_unliftable=args.strict)
    except UnliftableObjectError as error:
        print(f"assets import-egad: {error}", file=sys.stderr)
        return EXIT_FAILED
    except (BadMeshError, MissingEgadFilesError) as error:
        print(f"assets import-egad: {error}; {args.out} is unchanged", file=sys.stderr)
        return EXIT_FAILED
    for task in sorted_tasks(metadata.objects):
        obj = metadata.objects[task]
        if obj.repair:
            print(f"{task}: repaired ({obj.source_file}): {_repair_summary(obj.repair)}")
        print(f"{task}: lifting poses {obj.lifting_pose_share:.0%}, best pose {obj.best_pose_success:.0%}")
    for warning in metadata.warnings or []:
        print(f"assets import-egad: warning: {warning}", file=sys.stderr)
    print(f"wrote {args.out}")
    return cmd_assets_check(args) if args.check_episodes else 0


def _repair_summary(repair: dict) -> str:
    """One line of an object's recorded repair (``MeshRepair.to_dict``)."""
    return (f"{repair['non_manifold_edges']} non-manifold edge(s) closed by {repair['method']}; volume "
            f"{repair['volume_change']:+.2%}, extents " + ", ".join(f"{c:+.2%}" for c in repair["extent_changes"]))


def cmd_assets_check(args: argparse.Namespace) -> int:
    """The scripted grasp and the perturbed grasp on every object; rates stored in objects.json. Exit 1 when an
    object is never grasped by the scripted grasp and no best pose of at least ``MIN_BEST_POSE_SUCCESS`` is on
    record for it: a slab the centred descent never lifts is learnable when another top-down pose lifts it."""
    from glocal_ros.objects import (
        MIN_BEST_POSE_SUCCESS,
        ObjectSetMetadata,
        never_grasped,
        record_grasp_success,
    )
    from sim_node.scripted_grasp import GraspErrors, graspability

    metadata = ObjectSetMetadata.load(args.out)
    objects, imported = metadata.objects, metadata.source == "egad"
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
        print(f"{'warning: ' if imported else ''}not learnable: {', '.join(unlearnable)} (never grasped, and no "
              f"best pose of at least {MIN_BEST_POSE_SUCCESS:.0%} on record: glocal-ros assets lifting-poses)"
              + ("; kept: an imported set is EGAD's" if imported else ""), file=sys.stderr)
    return EXIT_FAILED if unlearnable and not imported else EXIT_OK


def _lifting_pose_check(args: argparse.Namespace):
    """The asset commands' share of lifting poses, and their rule that every object stays learnable."""
    from functools import partial

    from glocal_ros.objects import LiftingPoseCheck
    from sim_node.lifting_poses import LiftingPoseSettings, lifting_pose_trial

    settings = LiftingPoseSettings()
    return LiftingPoseCheck(partial(lifting_pose_trial, settings=settings), seed=args.seed,
                            workers=getattr(args, "workers", 1), settings=settings.to_dict())


def cmd_assets_lifting_poses(args: argparse.Namespace) -> int:
    """The share of top-down poses that lift each object and its best pose's success, into objects.json. Exit 1
    when a best pose is below the rule, but for an imported (EGAD) set, where that is a warning."""
    from glocal_ros.objects import (
        ObjectSetMetadata,
        measure_lifting_poses,
        record_lifting_poses,
        unliftable,
    )

    check = _lifting_pose_check(args)
    metadata = ObjectSetMetadata.load(args.out)
    tasks = sorted_tasks(metadata.objects)
    results = measure_lifting_poses(args.out, tasks, check.trial, check.seed, check.workers, print_progress)
    record_lifting_poses(args.out, results, check.record())
    for task, (share, best) in results.items():
        print(f"{task}: lifting poses {share:.0%}, best pose {best:.0%}")
    failing = unliftable(results, check.min_best_pose_success)
    print(f"recorded in {args.out / 'objects.json'}; best pose below {check.min_best_pose_success:.0%}: "
          f"{', '.join(failing) or 'none'}")
    if failing and metadata.source == "egad":
        print(f"assets lifting-poses: warning: best pose below {check.min_best_pose_success:.0%}: "
              f"{', '.join(failing)}; kept: an imported set is EGAD's", file=sys.stderr)
        return EXIT_OK
    return EXIT_FAILED if failing else EXIT_OK


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
    return EXIT_OK


def cmd_assets_validate(args: argparse.Namespace) -> int:
    """The letter against perturbed and scripted grasp success, the prior's score and steps to B."""
    from glocal_app.benches.assets import (
        prior_scores,
        steps_to_b,
        validation_figure,
        validation_report,
    )
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
        return EXIT_FAILED
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
        "prior": (prior_scores(args.out, tasks, args.episodes, seed=args.seed, profile=args.learner_profile,
                               prior_store=args.prior_store) if args.episodes else {}),
        "steps_to_b": steps_to_b(goals),
    }
    figure = validation_figure(measures, args.report.with_suffix(".png"))
    command = command_line()
    preamble = (f"Objects: `{args.out}` (generator {metadata.generator_version}, {metadata.source}). (a) and (b) "
                f"from its `objects.json` (`glocal-ros assets check`), as are lifting poses and the best pose "
                f"(`glocal-ros assets lifting-poses`); (c) {args.episodes} deterministic "
                f"episodes of the `{args.learner_profile}` profile's prior ({args.prior_store or 'shipped'}) per "
                f"object (seed {args.seed}), its task bits as the profile starts a goal's "
                f"(`{learner_profile(args.learner_profile).fine_tuning.new_task_inputs}`); (d) steps to B from "
                f"{cost or 'no goals'}. Figure: `{figure.name}`.")
    return write_bench_report(validation_report(measures, command, preamble), args.report)


def check_assets_arguments(args: argparse.Namespace) -> None:
    """The objects directory defaults to the package's; a check needs at least one scripted episode."""
    if args.out is None:
        args.out = objects_dir()
    if args.assets_command == "check" and args.check_episodes < 1:
        raise ValueError("--check-episodes must be at least 1")


def add_assets_commands(commands) -> None:
    """``assets generate | import-egad | check | lifting-poses | show | validate``."""
    assets = commands.add_parser("assets", help="the object set: generate, import EGAD, check, lifting poses, "
                                     "show, validate")
    assets.set_defaults(check=check_assets_arguments)
    asset_commands = assets.add_subparsers(dest="assets_command", required=True)
    generate = asset_commands.add_parser("generate", help="generate the 49 objects (seeded, about 25 minutes)")
    generate.add_argument("--seed", type=int, default=0)
    generate.add_argument("--candidates", type=int, default=1500, help="candidate shapes to bin into the grid")
    generate.add_argument("--workers", type=int, default=2)
    generate.add_argument("--grid", choices=("measured", "lifting-poses", "geometric"), default="lifting-poses",
                          help="letters from the share of top-down poses that lift each candidate (lifting-poses, "
                               "the committed set's), from the perturbed grasp in the simulator (measured, "
                               "faster), or from the geometric difficulty alone")
    generate.add_argument("--per-column", type=count(7), default=None,
                          help="candidates of each complexity digit tried in the simulator (--grid measured or "
                               "lifting-poses; default: glocal_ros.objects.MeasuredGrid's)")
    # glocal_ros.objects.cppn.ENVELOPES, named here: the object package takes a second to import.
    generate.add_argument("--envelope", choices=("blob", "wide"), default="wide",
                          help="base solids: wide (blobs, slabs and rods, tapered: the committed set's), or "
                               "EGAD-like blobs (glocal_ros/objects/cppn.py)")
    generate.set_defaults(func=cmd_assets_generate)
    egad = asset_commands.add_parser("import-egad", help="the same layout from EGAD's A0.obj .. G6.obj (a mesh "
                                     "with a few non-manifold edges is repaired and the repair reported)")
    egad.add_argument("egad_dir", type=Path)
    egad.add_argument("--partial", action="store_true", help="import whichever of the 49 files exist")
    egad.add_argument("--seed", type=int, default=0, help="seed of the lifting poses and the scripted grasp check")
    egad.add_argument("--workers", type=count(1), default=1,
                      help="processes measuring the lifting poses, one object each (default 1; the results do "
                           "not depend on it)")
    egad.add_argument("--strict", action="store_true",
                      help="refuse the set (exit 1) if an object's best pose lifts it less than 80%% of the time, "
                           "keeping the measurements in OUT.refused.json; by default that is a warning: the set "
                           "is EGAD's")
    egad.set_defaults(func=cmd_assets_import_egad)
    check = asset_commands.add_parser("check", help="scripted and perturbed grasp success of every object, into "
                                      "objects.json")
    check.add_argument("--seed", type=int, default=0)
    check.set_defaults(func=cmd_assets_check)
    poses = asset_commands.add_parser(
        "lifting-poses", help="the share of top-down poses that lift each object and its best pose's success, "
        "into objects.json (exit 1 if a best pose lifts its object less than 80%% of the time)")
    poses.add_argument("--seed", type=int, default=0)
    poses.add_argument("--workers", type=count(1), default=2, help="processes, one object each (default 2)")
    poses.set_defaults(func=cmd_assets_lifting_poses)
    show = asset_commands.add_parser("show", help="every object's metrics")
    show.set_defaults(func=cmd_assets_show)
    validate = asset_commands.add_parser(
        "validate", help="Spearman between the letter and grasp success, the prior's score and steps to B")
    validate.add_argument("--episodes", type=count(0), default=100,
                          help="episodes of the prior per object (0: none)")
    validate.add_argument("--seed", type=int, default=0)
    steps_source = validate.add_mutually_exclusive_group()
    steps_source.add_argument("--cost", type=Path, default=None, metavar="WORK_DIR",
                              help="a bench cost work directory (of this set) whose goals give steps to B")
    steps_source.add_argument("--transfer", type=Path, nargs="*", help="bench transfer reports (default budget) "
                              "whose goals give steps to B")
    validate.add_argument("--recipe", default=DEFAULT_RECIPE, help="the transfer reports' recipe to use")
    add_prior_store_argument(validate)
    add_profile_argument(validate)
    validate.add_argument("--report", type=Path, default=Path("bench/results/assets-validate.md"),
                          help="the report; the figure is written beside it as .png")
    validate.set_defaults(func=cmd_assets_validate)
    for command in (generate, egad, check, poses, show, validate):
        command.add_argument("--out", type=Path, default=None, help="objects directory (default: the package's)")
    for command in (generate, egad, check):
        command.add_argument("--check-episodes", type=count(0), default=30,
                             help="scripted grasp episodes per object (0: no check)")
        command.add_argument("--perturbed-episodes", type=count(1), default=40,
                             help="perturbed grasp episodes per object (and per candidate tried)")


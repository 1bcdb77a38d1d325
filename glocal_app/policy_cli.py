"""``glocal-ros train-prior``, ``collect-experience`` and ``policy import``: making and converting stored policies."""

from __future__ import annotations

import argparse
from pathlib import Path

from glocal_app.arguments import add_profile_argument, count
from glocal_app.exit_codes import EXIT_FAILED, EXIT_OK
from glocal_ros.curriculum.learner import paper_threshold, passes_threshold
from glocal_ros.paths import assets_dir, object_urdf
from glocal_ros.tasks import split_novel_task
from learner_node.prior import PriorConfig
from learner_node.profiles import DEFAULT_PROFILE, PROFILES, learner_profile
from learner_node.sac_settings import EXPERIENCE_TRANSITIONS, NETWORKS


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
                         profile=args.learner_profile)
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
    return EXIT_OK if passes_threshold(score.successes, threshold) else EXIT_FAILED


def cmd_collect_experience(args: argparse.Namespace) -> int:
    """Give a stored policy experience: it acts on its task as SAC acts in training; the model is unchanged."""
    from learner_node.policy_store import PolicyStore
    from learner_node.prior import collect_experience
    from sim_node.grasp_env import GraspEnv

    source = PolicyStore(args.store)
    if args.name not in source:
        raise ValueError(f"no policy {args.name!r} in {source.root}")
    record = source.record(args.name)
    if split_novel_task(record.task) and args.objects is None:
        raise ValueError(f"{args.name} was trained on the novel object of {record.task}: give its objects "
                         f"directory with --objects (adapt's RUN_DIR/adapt/NAME/objects)")
    out = PolicyStore(args.out or args.store)
    if out.root.resolve() != source.root.resolve():
        out.add_copy(source, args.name, args.name)
    env = GraspEnv(record.task, args.objects)
    try:
        experience = collect_experience(source.load(args.name), env, args.transitions, args.seed)
    finally:
        env.close()
    out.keep_experience(args.name, experience)
    successes = int((experience["dones"] - experience["timeouts"]).sum())  # episodes that ended by a lift
    print(f"{args.name}: {len(experience['dones'])} transitions on {record.task}, {successes} successful "
          f"episodes, kept in {out.root}/{args.name}")
    return EXIT_OK


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
        record = PolicyRecord(name=args.name, profile=args.learner_profile or DEFAULT_PROFILE)
    elif args.learner_profile and args.learner_profile != record.profile:
        raise ValueError(f"{args.zip} is a policy of profile {record.profile!r} (its policy.json), not "
                         f"{args.learner_profile!r}")
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
    return EXIT_OK


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


def check_train_prior_arguments(args: argparse.Namespace) -> None:
    """The store defaults to the profile's shipped priors; --min-steps within --steps; an A0 in --objects-dir."""
    if args.out is None:
        args.out = learner_profile(args.learner_profile).shipped_priors()
    if not 0 <= args.min_steps <= args.steps:
        raise ValueError(f"--min-steps {args.min_steps} must lie between 0 and --steps {args.steps}")
    if args.objects_dir and not object_urdf(args.objects_dir, "A0").is_file():
        raise ValueError(f"{args.objects_dir} holds no A0/model.urdf (the layout `assets generate` writes)")


def check_experience_arguments(args: argparse.Namespace) -> None:
    """The store defaults to the shipped priors'."""
    if args.store is None:
        args.store = assets_dir() / "priors"


def check_policy_arguments(args: argparse.Namespace) -> None:
    """The store defaults to the learner's."""
    if args.store is None:
        from learner_node.policy_store import default_policy_dir

        args.store = default_policy_dir()


def add_policy_commands(commands) -> None:
    """``train-prior``, ``collect-experience`` and ``policy import``."""
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
    prior.set_defaults(func=cmd_train_prior, check=check_train_prior_arguments)

    experience = commands.add_parser(
        "collect-experience", help="give a stored policy experience (for the parent-experience recipe): "
        "transitions of it acting on its task")
    experience.add_argument("name", help="the stored policy")
    experience.add_argument("--store", type=Path, default=None, help="its policy store (default: assets/priors)")
    experience.add_argument("--out", type=Path, default=None, help="the store to write it to (default: --store)")
    experience.add_argument("--transitions", type=count(1), default=EXPERIENCE_TRANSITIONS)
    experience.add_argument("--seed", type=int, default=0, help="of the first episode; episode k: seed + k")
    experience.add_argument("--objects", type=Path, default=None,
                            help="the objects directory of its task (default: the package's set; needed for a "
                                 "novel object's task)")
    experience.set_defaults(func=cmd_collect_experience, check=check_experience_arguments)

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
    policy_import.add_argument("--learner-profile", "--profile", default=None, choices=list(PROFILES),
                               help="the learner profile of a zip no policy.json names (default: "
                                    f"{DEFAULT_PROFILE}); a zip of a store keeps its record's")
    policy_import.set_defaults(func=cmd_policy_import, check=check_policy_arguments)


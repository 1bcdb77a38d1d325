"""``glocal-ros bench transfer``: how Train goals fine-tune the A0 prior on other objects.

For each learner profile (``learner_node.profiles``), fine-tuning recipe
(``learner_node.sac_settings.FINE_TUNING_RECIPES``, or ``default``: the
profile's own; a profile refuses recipes it does not allow), prior, task and
seed, one seeded Train goal from the prior with the same
step budget, scored every ``eval_interval`` training steps on
``eval_episodes`` deterministic episodes (the paper's score), and never
stopped when learned, so that the whole curve is seen (``bench cost``,
``glocal_app.benches.cost``, runs the same goals with the settings'
``stop_at_threshold``: stopped at the first score above B, as a curriculum
stops them). Per goal it records:

- the curve: the score at step 0 (the prior as the goal starts it, on the
  episodes the goal's own step-0 evaluation would use) and at every interval;
- steps-to-B: the first step whose score passes B (``passes_threshold``),
  none when no evaluation did;
- the drop: how far the lowest score from ``COLLAPSE_AFTER`` steps on fell
  below the start, in points of 100; a drop of ``COLLAPSE_POINTS`` or more
  is a collapse (the score was there before training and training lost it);
- wall-clock of the goal (its evaluations included).

The priors are stored policies: the shipped ``prior`` by default, and for
comparing networks (``learner_node.sac_settings.NETWORKS``) others that
``glocal-ros train-prior --network ... --name ... --out DIR`` made, read from
``prior_store`` DIR before the profile's shipped store. Each (profile,
recipe, prior) is an arm. Goals with the same task and seed run the same episodes in every
arm (the goal's seed derives every stream, ``learner_node.training``), so
the arms are compared pairwise on equal footing. The goals run in-process
(the ``Trainer`` on a ``BatchedEnvs``, no ROS), ``jobs`` at a time in worker
processes, interleaved by arm so that load on the shared machine hits all
arms alike.

``--graph`` runs the same goals through the graph: per arm a sim_node and
a learner_node process (its ``fine_tuning`` parameter set to the recipe, the
prior copied into its store), in a namespace of their own, sent the goals by
the curriculum's ``RosLearner``; the arms' pairs run at once. The start is the prior scored by
``learner/evaluate`` on the same episodes (the sim holds as many evaluation
envs as training envs), the curve the goal's evaluations on ``glocal/evaluations`` (the k-th one at k intervals: the settings make
every evaluation fall exactly on its step).

``read_transfer_goals`` reads the goals back from a report's per-goal table,
so that arms that ran on different days (same tasks, seeds and settings, hence
the same episodes) are tabulated side by side without running them again.
"""

from __future__ import annotations

import math
import os
import shutil
import statistics
import sys
import tempfile
import time
from concurrent.futures import ProcessPoolExecutor, ThreadPoolExecutor
from dataclasses import dataclass, replace
from multiprocessing import get_context
from pathlib import Path
from typing import Callable, Sequence

from glocal_ros.curriculum.learner import PAPER_THRESHOLD_FRACTION, passes_threshold
from learner_node.profiles import DEFAULT_PROFILE, learner_profile, profile_departures
from glocal_ros.paths import object_urdf
from glocal_ros.seeds import MAX_SEED
from glocal_ros.tasks import validate_tasks

#: Eight cells over the grid: every row letter and every column digit at least once.
TRANSFER_TASKS = ("A6", "B1", "C4", "D3", "E0", "E5", "F2", "G6")
INITIAL_POLICY = "prior"
#: The recipe name that stands for a learner profile's own fine-tuning (``LearnerProfile.fine_tuning``).
PROFILE_RECIPE = "default"
#: A collapse: from this many training steps on, a score this many points of 100 below the start.
COLLAPSE_AFTER = 1_000
COLLAPSE_POINTS = 25.0


@dataclass(frozen=True)
class TransferSettings:
    """What every goal of one bench run shares."""

    step_budget: int = 3_000
    eval_interval: int = 500
    eval_episodes: int = 20
    threshold_fraction: float = PAPER_THRESHOLD_FRACTION  # B as a share of eval_episodes: the paper's 75 of 100
    num_envs: int = 4
    #: Stop each goal at its first score above B, as a curriculum's goal stops (``TrainGoal.stop_when_learned``):
    #: the goal's own check before its first step is then the curve's step 0, and the curve ends where it passed.
    stop_at_threshold: bool = False
    #: Where the goals' envs load the objects from; None: the shipped set (``sim_node.grasp_env``).
    objects_dir: Path | None = None

    @property
    def threshold(self) -> float:
        return self.threshold_fraction * self.eval_episodes

    def check(self) -> None:
        """Raise ``ValueError`` before anything runs, with what to change."""
        if min(self.step_budget, self.eval_interval, self.eval_episodes, self.num_envs) < 1:
            raise ValueError("the budget, evaluation interval, evaluation episodes and envs must be at least 1")
        if self.step_budget < self.eval_interval:
            raise ValueError(f"the budget ({self.step_budget}) is below one evaluation interval "
                             f"({self.eval_interval}): no goal would be scored before its end")
        if self.eval_interval % self.num_envs or self.step_budget % self.eval_interval:
            raise ValueError(f"the evaluation interval ({self.eval_interval}) must be a multiple of the envs "
                             f"({self.num_envs}) and divide the budget ({self.step_budget}): every evaluation "
                             "then falls exactly on its step")
        if not 0 <= self.threshold_fraction < 1:
            raise ValueError(f"the threshold fraction must lie in [0, 1), got {self.threshold_fraction}")


@dataclass(frozen=True)
class TransferGoal:
    recipe: str
    task: str
    seed: int
    curve: tuple[tuple[int, int], ...]  # (training steps, successes), from step 0
    eval_episodes: int
    threshold: float
    wall_s: float
    prior: str = INITIAL_POLICY
    profile: str = DEFAULT_PROFILE
    #: (training steps, instrument -> value) at each of the goal's own evaluations (``learner_node.instruments``);
    #: () where they were not heard (through the graph, or a report made before them).
    instruments: tuple[tuple[int, dict[str, float]], ...] = ()

    @property
    def arm(self) -> tuple[str, str, str]:
        return self.profile, self.recipe, self.prior

    @property
    def start(self) -> int:
        return self.curve[0][1]

    @property
    def final(self) -> int:
        return self.curve[-1][1]

    @property
    def steps_to_b(self) -> int | None:
        return next((steps for steps, score in self.curve if passes_threshold(score, self.threshold)), None)

    @property
    def drop_points(self) -> float:
        """How far the lowest score from ``COLLAPSE_AFTER`` steps on lies below the start, in points of 100."""
        later = [score for steps, score in self.curve if steps >= COLLAPSE_AFTER]
        return max(0.0, 100.0 * (self.start - min(later)) / self.eval_episodes) if later else 0.0

    @property
    def collapsed(self) -> bool:
        return self.drop_points >= COLLAPSE_POINTS


def prior_stores(prior_store: Path | None, profile: str = DEFAULT_PROFILE) -> list:
    """The read-only stores the priors come from: ``prior_store`` (when given), then the profile's shipped one."""
    from learner_node.policy_store import PolicyStore

    return [PolicyStore(root) for root in ([prior_store] if prior_store else [])
            + [learner_profile(profile).shipped_priors()]]


def fine_tuning_of(profile: str, recipe: str):
    """The fine-tuning of arm (``profile``, ``recipe``); ``ValueError`` where the profile does not allow it."""
    return learner_profile(profile).with_recipe("" if recipe == PROFILE_RECIPE else recipe)


def run_goal(recipe: str, prior: str, task: str, seed: int, settings: TransferSettings,
             prior_store: Path | None = None, profile: str = DEFAULT_PROFILE) -> TransferGoal:
    """One seeded goal from ``prior`` in this process, on envs of its own; its curve and wall-clock.

    Its curve starts with the prior's score at step 0 on the episodes of the goal's own check before its first
    step: with ``settings.stop_at_threshold`` that check itself (the goal runs it), else scored here.
    """
    (goal,) = run_chain(recipe, prior, [task], seed, settings, prior_store, profile)
    return goal


def run_chain(recipe: str, prior: str, tasks: Sequence[str], seed: int, settings: TransferSettings,
              prior_store: Path | None = None, profile: str = DEFAULT_PROFILE) -> list[TransferGoal]:
    """Goals on ``tasks`` in turn, in this process, the first from ``prior`` and each later one from the
    policy the goal before it stored, as ``run_goal`` runs one; the chain ends early after a goal whose
    last score is not above B (a policy that did not learn its object leads nowhere). Every goal has the
    same ``seed``, so a goal on a task sees the episodes of ``run_goal`` on it from any start.
    """
    from glocal_ros.seeds import derived_seed
    from learner_node.evaluation import evaluate
    from learner_node.policies import PolicyRegistry
    from learner_node.policy_store import PolicyStore
    from glocal_ros.curriculum.learner import TrainGoal
    from learner_node.training import EVALUATION_STREAM, Trainer
    from sim_node.batch import BatchedEnvs
    from sim_node.grasp_env import GraspEnv

    work = Path(tempfile.mkdtemp(prefix="glocal-bench-transfer-"))
    envs = BatchedEnvs(lambda i: GraspEnv(tasks[0], settings.objects_dir), settings.num_envs, tasks[0])
    goals: list[TransferGoal] = []
    try:
        policies = PolicyRegistry(PolicyStore(work / "policies"), prior_stores(prior_store, profile), seed=seed)
        trainer = Trainer(envs, policies, work / "checkpoints", seed, checkpoint_interval=10**12,
                          profile=learner_profile(profile), fine_tuning=fine_tuning_of(profile, recipe))
        start_policy = prior
        for number, task in enumerate(tasks):
            started = time.perf_counter()
            curve = []
            if not settings.stop_at_threshold:
                # The start as the goal meets it, on the episodes the goal's own step-0 evaluation would score.
                (start,) = evaluate(envs, trainer.evaluation_policy(start_policy, [task]), [task],
                                    settings.eval_episodes, seed=derived_seed(seed, EVALUATION_STREAM, 0))
                curve.append((0, start.successes))
            output = f"transfer-{number}"
            heard: dict[int, dict[str, float]] = {}  # the progress report after each evaluation carries its instruments
            trainer.train(TrainGoal(task=task, initial_policy=start_policy, output_policy=output,
                                    step_budget=settings.step_budget, threshold=settings.threshold,
                                    eval_episodes=settings.eval_episodes, eval_interval=settings.eval_interval,
                                    stop_when_learned=settings.stop_at_threshold, seed=seed),
                          on_evaluation=lambda score, steps: curve.append((steps, score.successes)),
                          on_progress=lambda progress: heard.update({progress.steps: instrument_values(progress)}))
            goals.append(TransferGoal(recipe, task, seed, tuple(curve), settings.eval_episodes, settings.threshold,
                                      time.perf_counter() - started, start_policy, profile,
                                      tuple((steps, heard[steps]) for steps, _ in curve if steps in heard)))
            if not passes_threshold(curve[-1][1], settings.threshold):
                break
            start_policy = output
        return goals
    finally:
        envs.close()
        shutil.rmtree(work, ignore_errors=True)


#: What the report shows of a goal's instruments at each evaluation: name -> (what, from a TrainProgress).
INSTRUMENTS: dict[str, tuple[str, Callable]] = {
    "action distance": ("the mean distance of the deterministic action from the parent's",
                        lambda i: i.action_distance),
    "Q gap": ("Q(s, current action) - Q(s, parent's action), the critics' min",
              lambda i: i.q_current_action - i.q_parent_action),
    "entropy": ("the policy's entropy (one draw per state)", lambda i: i.policy_entropy),
}


def instrument_values(progress) -> dict[str, float]:
    """The report's instruments of a ``TrainProgress``."""
    return {name: float(value(progress.instruments)) for name, (_, value) in INSTRUMENTS.items()}


def _run_goal(job: tuple[str, str, str, int, TransferSettings, Path | None, str]) -> TransferGoal:
    return run_goal(*job)


def run_transfer_bench(recipes: Sequence[str], tasks: Sequence[str], seeds: Sequence[int],
                       settings: TransferSettings, jobs: int = 1, log: Callable[[str], None] = print,
                       priors: Sequence[str] = (INITIAL_POLICY,), prior_store: Path | None = None,
                       profiles: Sequence[str] = (DEFAULT_PROFILE,)) -> list[TransferGoal]:
    """Every (profile, recipe, prior, task, seed) goal, ``jobs`` at a time; in the order task, seed, profile,
    prior, recipe."""
    check_goals(recipes, priors, prior_store, tasks, seeds, settings, jobs, profiles)
    work = [(recipe, prior, task, seed, settings, prior_store, profile)
            for task in tasks for seed in seeds for profile in profiles for prior in priors for recipe in recipes]
    goals = []
    # Spawned workers: pybullet, torch and JAX do not survive a fork of a process that uses them.
    with ProcessPoolExecutor(max_workers=jobs, mp_context=get_context("spawn")) as pool:
        for goal in pool.map(_run_goal, work):
            log(_goal_line(goal))
            goals.append(goal)
    return goals


def check_goals(recipes: Sequence[str], priors: Sequence[str], prior_store: Path | None, tasks: Sequence[str],
           seeds: Sequence[int], settings: TransferSettings, jobs: int,
           profiles: Sequence[str] = (DEFAULT_PROFILE,)) -> None:
    """Raise ``ValueError`` for anything that would fail later, before any goal runs."""
    from learner_node.policy_store import check_name

    for profile in profiles:
        for recipe in recipes:
            fine_tuning_of(profile, recipe)
    if prior_store is not None and not prior_store.is_dir():
        raise ValueError(f"the prior store {prior_store} is not a directory")
    for profile in profiles:
        stores = prior_stores(prior_store, profile)
        for prior in priors:
            store = next((store for store in stores if check_name(prior) in store), None)
            if store is None:
                raise ValueError(f"no prior {prior!r} in {' or '.join(str(store.root) for store in stores)}")
            if not learner_profile(profile).trains_policies_of(store.record(prior).profile):
                raise ValueError(f"prior {prior!r} of {store.root} was trained under learner profile "
                                 f"{store.record(prior).profile!r}, not {profile!r}")
    validate_tasks(list(tasks))
    settings.check()
    if settings.objects_dir is not None:
        missing = [task for task in tasks if not object_urdf(settings.objects_dir, task).is_file()]
        if missing:
            raise ValueError(f"{settings.objects_dir} holds no model.urdf for {', '.join(missing)} (the layout "
                             "`assets generate` writes: <TASK>/model.urdf)")
    if not recipes or not priors or not tasks or not seeds or not profiles or jobs < 1:
        raise ValueError("the goals need a profile, a recipe, a prior, a task, a seed and at least one job")
    if any(len(set(values)) != len(values) for values in (recipes, priors, tasks, seeds, profiles)):
        raise ValueError("profiles, recipes, priors, tasks and seeds must not repeat")
    if not all(0 <= seed <= MAX_SEED for seed in seeds):
        raise ValueError(f"seeds must lie in 0..{MAX_SEED}, got {list(seeds)}")


def _goal_line(goal: TransferGoal) -> str:
    return (f"{goal.profile} {goal.recipe} from {goal.prior} {goal.task} seed {goal.seed}: "
            + " ".join(f"{s}:{score}" for s, score in goal.curve)
            + f" (steps to B {goal.steps_to_b if goal.steps_to_b is not None else '-'}, "
            f"drop {goal.drop_points:.0f} points, {goal.wall_s:.0f} s)")


def run_transfer_graph(recipes: Sequence[str], tasks: Sequence[str], seeds: Sequence[int],
                       settings: TransferSettings, log: Callable[[str], None] = print,
                       priors: Sequence[str] = (INITIAL_POLICY,), prior_store: Path | None = None,
                       profiles: Sequence[str] = (DEFAULT_PROFILE,)) -> list[TransferGoal]:
    """The goals of ``run_transfer_bench`` through sim_node + learner_node processes, one pair per arm."""
    import threading
    from contextlib import ExitStack

    from glocal_interfaces.msg import EvaluationResult

    from curriculum_node.ros_learner import RosLearner
    from glocal_app.processes import NodeProcess, isolated_environment, namespace_arguments
    from glocal_ros.curriculum.learner import TrainGoal
    from glocal_ros.domain import reserve_domain_id
    from glocal_ros.seeds import derived_seed
    from learner_node.policy_store import PolicyStore
    from learner_node.training import EVALUATION_STREAM
    from node_common import names, qos
    from node_common.runner import spinning_node

    check_goals(recipes, priors, prior_store, tasks, seeds, settings, 1, profiles)
    if settings.stop_at_threshold:
        raise ValueError("through the graph the goals run to their budget: stop_at_threshold is in-process only")
    domain_id, lock = reserve_domain_id()
    work = Path(tempfile.mkdtemp(prefix="glocal-bench-transfer-graph-"))
    env = isolated_environment(domain_id, work / "logs")
    timeout = 600.0
    stack = ExitStack()

    def pair(index: int, profile: str, recipe: str, prior: str) -> Callable[[], list[TransferGoal]]:
        namespace = f"/transfer{index}"
        remap = namespace_arguments(namespace)
        policy_dir = work / f"policies{index}"
        source = next(store for store in prior_stores(prior_store, profile) if prior in store)
        PolicyStore(policy_dir).add_copy(source, prior, prior)
        # As many evaluation envs as training envs: a seeded evaluation's episodes depend on the envs it
        # runs on (learner_node.evaluation), and in-process goals evaluate on their training envs.
        sim_parameters = {"num_envs": settings.num_envs, "eval_envs": settings.num_envs, "initial_task": tasks[0],
                          **({"objects_dir": str(settings.objects_dir)} if settings.objects_dir else {})}
        processes = [NodeProcess("sim_node", work / "logs", sim_parameters, env=env, extra_args=remap),
                     NodeProcess("learner_node", work / "logs",
                                 {"policy_dir": str(policy_dir), "learner_profile": profile,
                                  "fine_tuning": "" if recipe == PROFILE_RECIPE else recipe, "seed": 0,
                                  "checkpoint_interval": 10_000_000}, env=env, extra_args=remap)]
        stack.callback(lambda: [process.stop() for process in reversed(processes)])
        node = stack.enter_context(spinning_node(f"bench_transfer{index}", domain_id, num_threads=4,
                                                  namespace=namespace))
        scores: dict[str, list[int]] = {}
        heard = threading.Condition()

        def on_evaluation(message: EvaluationResult) -> None:
            if message.purpose == "train":
                with heard:
                    scores.setdefault(message.policy, []).extend(s.successes for s in message.scores)
                    heard.notify_all()

        node.create_subscription(EvaluationResult, names.EVALUATIONS, on_evaluation, qos.EVENTS)
        learner = RosLearner(node, timeout_sec=timeout)

        def goals() -> list[TransferGoal]:
            learner.wait_for_learner()
            done = []
            for task in tasks:
                for seed in seeds:
                    output = f"transfer-{task}-{seed}"
                    started = time.perf_counter()
                    start = learner.evaluate(prior, [task], settings.eval_episodes,
                                             seed=derived_seed(seed, EVALUATION_STREAM, 0))[task]
                    learner.train(TrainGoal(task, prior, output, settings.step_budget,
                                               threshold=settings.threshold, eval_episodes=settings.eval_episodes,
                                               eval_interval=settings.eval_interval, stop_when_learned=False,
                                               seed=seed))
                    wall_s = time.perf_counter() - started
                    expected = settings.step_budget // settings.eval_interval
                    with heard:  # the last evaluation's message may trail the result
                        if not heard.wait_for(lambda: len(scores.get(output, ())) >= expected, timeout):
                            raise RuntimeError(f"{recipe} from {prior}: {len(scores.get(output, ()))} of {expected} "
                                               f"evaluations of {output} heard; see the logs in {work / 'logs'}")
                        curve = [(0, int(start))] + [((k + 1) * settings.eval_interval, score)
                                                     for k, score in enumerate(scores[output][:expected])]
                    goal = TransferGoal(recipe, task, seed, tuple(curve), settings.eval_episodes,
                                        settings.threshold, wall_s, prior, profile)
                    log(_goal_line(goal))
                    done.append(goal)
            return done

        return goals

    try:
        arms = [(profile, recipe, prior) for profile in profiles for prior in priors for recipe in recipes]
        runs = [pair(index, *arm) for index, arm in enumerate(arms)]
        with ThreadPoolExecutor(len(runs)) as pool:
            per_arm = list(pool.map(lambda run: run(), runs))
    finally:
        stack.close()
        lock.close()
    order = {(task, seed): i for i, (task, seed) in enumerate((t, s) for t in tasks for s in seeds)}
    return sorted((g for goals in per_arm for g in goals), key=lambda g: order[(g.task, g.seed)])


def read_transfer_goals(path: Path, settings: TransferSettings) -> list[TransferGoal]:
    """The goals of the per-goal table of a ``transfer_bench_report`` at ``path``.

    ``ValueError`` naming the file when it has no such table or its goals were
    scored at other steps than ``settings`` scores at; reports made before
    arms had priors (no prior column) are read as from ``INITIAL_POLICY``, and before profiles (no
    profile column) as of ``DEFAULT_PROFILE``.
    """
    expected = [str(steps) for steps in range(0, settings.step_budget + 1, settings.eval_interval)]
    goals, columns, instrument_columns = [], None, None
    heard: dict[tuple, dict[int, dict[str, float]]] = {}  # arm, task, seed -> steps -> instrument -> value
    for line in Path(path).read_text().splitlines():
        cells = [cell.strip() for cell in line.strip().strip("|").split("|")]
        if "instrument" in cells and "seed" in cells:
            columns, instrument_columns = None, cells
        elif instrument_columns and len(cells) == len(instrument_columns) and not cells[0].startswith("---"):
            row = dict(zip(instrument_columns, cells))
            arm = (row["profile"], row["recipe"], row.get("prior", INITIAL_POLICY), row["task"], int(row["seed"]))
            for steps in instrument_columns[instrument_columns.index("seed") + 1:]:
                if row[steps] != "-":
                    heard.setdefault(arm, {}).setdefault(int(steps), {})[row["instrument"]] = float(row[steps])
        elif "recipe" in cells and "task" in cells and "seed" in cells:
            columns, instrument_columns = cells, None
            scored_at = columns[columns.index("seed") + 1:columns.index("steps to B")]
            if scored_at != expected:
                raise ValueError(f"{path}: its goals were scored at steps {', '.join(scored_at)}, not at "
                                 f"{', '.join(expected)} (--budget {settings.step_budget} --eval-interval "
                                 f"{settings.eval_interval})")
        elif columns and len(cells) == len(columns) and not cells[0].startswith("---"):
            row = dict(zip(columns, cells))
            goals.append(TransferGoal(
                row["recipe"], row["task"], int(row["seed"]),
                tuple((int(steps), int(row[steps])) for steps in expected),
                settings.eval_episodes, settings.threshold, float(row["s"]), row.get("prior", INITIAL_POLICY),
                row.get("profile", DEFAULT_PROFILE)))
    if not goals:
        raise ValueError(f"{path}: no per-goal table of a bench transfer report in it")
    return [replace(goal, instruments=tuple(sorted(heard.get((*goal.arm, goal.task, goal.seed), {}).items())))
            for goal in goals]


def median_steps_to_b(goals: Sequence[TransferGoal]) -> float:
    """Median with the goals that never passed B counted as infinitely slow."""
    return statistics.median(math.inf if g.steps_to_b is None else g.steps_to_b for g in goals)


def _steps(median: float) -> str:
    return "never" if math.isinf(median) else f"{median:.0f}"


def transfer_bench_report(goals: Sequence[TransferGoal], command: str, settings: TransferSettings,
                          jobs: int, graph: bool = False, sources: Sequence[Path] = ()) -> str:
    """The report; ``sources``: the goals were read from these earlier reports, not run."""
    arms = list(dict.fromkeys(g.arm for g in goals))
    tasks = list(dict.fromkeys(g.task for g in goals))
    seeds = sorted({g.seed for g in goals})
    priors = list(dict.fromkeys(g.prior for g in goals))
    lines = [
        "# bench transfer: fine-tuning an A0 prior, recipe by recipe",
        "",
        f"Command: `{command}`  ",
        f"{time.strftime('%Y-%m-%d %H:%M')}, Python {sys.version.split()[0]}, {os.cpu_count()} CPU cores, "
        + (f"the goals of {', '.join(f'`{source}`' for source in sources)}, tabulated together (how and when "
           "they ran: see those files)" if sources else
           "through the graph (a sim_node and a learner_node per arm, the arms at once)" if graph else
           f"in-process, {jobs} goal{'s' if jobs != 1 else ''} at a time")
        + ("" if sources else f". Load average at the end {os.getloadavg()[0]:.1f} (the machine is shared)")
        + ". One seeded Train goal "
        f"per recipe, prior ({', '.join(f'`{prior}`' for prior in priors)}), task and seed: "
        f"{settings.step_budget} training steps on "
        f"{settings.num_envs} envs, scored every "
        f"{settings.eval_interval} steps over {settings.eval_episodes} deterministic episodes, not stopped when "
        f"learned; B = {settings.threshold:g}. Tasks {', '.join(tasks)}"
        + (f" of `{settings.objects_dir}`" if settings.objects_dir else "")
        + f"; seeds {', '.join(map(str, seeds))}. "
        f"Steps to B: the first evaluation above B (a prior already above it: 0); the median counts a goal "
        f"that never passed as slower than all. A curriculum trains only tasks below B, so the columns of the "
        f"goals that started below B are the speed that matters. Collapse: a score {COLLAPSE_POINTS:g} or more "
        f"points of 100 below the start from step {COLLAPSE_AFTER} on. Wall-clock per goal includes its "
        f"evaluations.",
        "",
        "| profile | recipe | prior | goals | passed B | median steps to B | started below B | of those passed "
        "| their median steps to B | collapses | median drop (points) | median final score "
        "| median wall-clock per goal (s) |",
        "| --- | --- | --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: |",
    ]
    for profile, recipe, prior in arms:
        mine = [g for g in goals if g.arm == (profile, recipe, prior)]
        below = [g for g in mine if g.steps_to_b != 0]
        lines.append(
            f"| {profile} | {recipe} | {prior} | {len(mine)} | {sum(g.steps_to_b is not None for g in mine)} "
            f"| {_steps(median_steps_to_b(mine))} | {len(below)} | {sum(g.steps_to_b is not None for g in below)} "
            f"| {_steps(median_steps_to_b(below)) if below else '-'} | {sum(g.collapsed for g in mine)} "
            f"| {statistics.median(g.drop_points for g in mine):.0f} "
            f"| {statistics.median(g.final for g in mine):.0f} / {settings.eval_episodes} "
            f"| {statistics.median(g.wall_s for g in mine):.0f} |")
    departures = {profile: profile_departures(learner_profile(profile)) for profile, _, _ in arms}
    if any(departures.values()):
        lines += ["", "What each profile with departures changes from its base (`learner_node/profiles.py`):", ""]
        lines += [f"- `{profile}`: " + "; ".join(items) for profile, items in departures.items() if items]
    steps = [s for s, _ in goals[0].curve] if goals else []
    lines += ["", "Every goal (scores out of " f"{settings.eval_episodes} at each step):", "",
              "| profile | recipe | prior | task | seed | " + " | ".join(str(s) for s in steps)
              + " | steps to B | drop | s |",
              "| --- | --- | --- | --- | ---: | " + " | ".join("---:" for _ in steps) + " | ---: | ---: | ---: |"]
    for g in goals:
        lines.append(f"| {g.profile} | {g.recipe} | {g.prior} | {g.task} | {g.seed} | "
                     + " | ".join(str(score) for _, score in g.curve)
                     + f" | {'-' if g.steps_to_b is None else g.steps_to_b} | {g.drop_points:.0f} "
                     f"| {g.wall_s:.0f} |")
    measured = [g for g in goals if g.instruments]
    if measured:
        lines += ["", "What the instruments said at each of a goal's own evaluations (`learner_node/instruments.py`, "
                  "on 256 states of the parent's experience): "
                  + "; ".join(f"*{name}*, {what}" for name, (what, _) in INSTRUMENTS.items())
                  + ". Step 0 is scored outside the goal, so it has none.", "",
                  "| instrument | profile | recipe | prior | task | seed | " + " | ".join(str(s) for s in steps) + " |",
                  "| --- | --- | --- | --- | --- | ---: | " + " | ".join("---:" for _ in steps) + " |"]
        for name in INSTRUMENTS:
            for g in measured:
                values = dict(g.instruments)
                lines.append(f"| {name} | {g.profile} | {g.recipe} | {g.prior} | {g.task} | {g.seed} | "
                             + " | ".join(f"{values[s][name]:.3g}" if s in values else "-" for s in steps) + " |")
    return "\n".join(lines) + "\n"

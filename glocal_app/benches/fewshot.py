"""``glocal-ros bench fewshot``: novel objects learned from a run's global policy, from the prior, from its last policy.

The paper's closing claim, measured: a finished GloCAL run's global policies
are a better start on objects outside the set than the prior. For each run
(a finished run directory that kept its policies), each novel object and each
seed, in-process (``bench transfer``'s ``run_goal``: a ``Trainer`` on envs of
its own, the run's learner profile and its fine-tuning):

- every candidate of ``glocal_ros.adaptation.run_candidates`` (the run's
  global policies, its last policy, the prior) is scored on the object, each
  under its own task's bit (``NAME@PROXY``), on the same seeded episodes; the
  candidate ``adapt`` would start from is ``choose``'s;
- three goals, each stopped at its first score above B or at the budget:
  from adapt's choice, from the prior and from the run's last policy (an arm
  whose start is another's reuses that goal: same start, task and seed give
  the same goal).

The objects: a set that ``assets generate`` made with a seed the committed set
did not use, its lifting-pose shares measured (``assets lifting-poses``);
``per_third`` objects from each third of its shares (the share sorted low to
high: hard to easy), evenly spaced in the third, each named ``<set>_<TASK>``
(``glocal_ros.tasks``: a novel object's name) and prepared as ``adapt``
prepares an object directory (``prepare_object``).

Resumable as ``bench cost`` is (its ``GoalLog`` and ``work_lock``): the cases
run ``jobs`` at a time in spawned workers, each appended, one JSON line, to
``cases.jsonl`` in the work directory as it finishes; the same command skips
the cases found there, and ``--tabulate`` reports them without running
anything. Each line carries the settings that decide its goals and a hash of
its object's files: a work directory of other settings, or whose objects have
since changed, is refused before any case runs.
"""

from __future__ import annotations

import hashlib
import math
import os
import statistics
import sys
import tempfile
import time
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import dataclass, replace
from multiprocessing import get_context
from pathlib import Path
from typing import Callable, Sequence

from glocal_app.benches.cost import GoalLog, work_lock
from glocal_app.benches.transfer import PROFILE_RECIPE, TransferGoal, TransferSettings

#: The arms: where a goal starts.
ARMS = ("adapt's choice", "prior", "last")
THIRDS = ("hard", "middle", "easy")
CASES_FILE = "cases.jsonl"
DEFAULT_WORK_DIR = Path("runs/bench-fewshot")


@dataclass(frozen=True)
class FewshotRun:
    """A finished run as the bench uses it: its id, profile, store and candidates."""

    path: Path
    run_id: str
    profile: str
    candidates: tuple  # glocal_ros.adaptation.Candidate, in run_candidates' order
    #: A hash of its own candidates' weights: two runs of one id (``make run``'s demo and a bench run are both
    #: glocal-seed0) are told apart in a work directory.
    fingerprint: str = ""


@dataclass(frozen=True)
class NovelObject:
    name: str
    source: Path  # the object directory of the generated set
    lifting_pose_share: float
    third: str


@dataclass(frozen=True)
class FewshotCase:
    """One run, object and seed: every candidate's score, adapt's choice, and the goal of each arm."""

    run: str
    profile: str
    object: NovelObject
    seed: int
    scores: tuple[tuple[str, str, float], ...]  # (policy, proxy, score), in the candidates' order
    chosen: str
    goals: dict  # arm -> TransferGoal
    run_fingerprint: str = ""  # FewshotRun's


def read_run(run_dir: Path) -> FewshotRun:
    """``ValueError`` unless ``run_dir`` is a finished run whose policies hold a global one."""
    from glocal_app.adapt import run_profile, run_summary, stored_tasks
    from glocal_ros.adaptation import run_candidates

    options, run = run_summary(Path(run_dir))
    policies = Path(run_dir) / "policies"
    candidates = run_candidates(run["run_id"], run["strategy"], stored_tasks(policies),
                                run.get("current_policy", ""), run["initial_policy"])
    digest = hashlib.sha256()
    for candidate in candidates:  # the weights only: adapt rewrites a candidate's record with its new score
        for path in sorted((policies / candidate.policy).glob("model-*")):
            digest.update(f"{candidate.policy}/{path.name}".encode() + b"\0" + path.read_bytes() + b"\0")
    return FewshotRun(Path(run_dir), run["run_id"], run_profile(options), tuple(candidates),
                      digest.hexdigest()[:16])


def novel_objects(objects_dir: Path, per_third: int = 3, prefix: str | None = None) -> list[NovelObject]:
    """``per_third`` objects from each third of the set's lifting-pose shares; ``ValueError`` if unmeasured."""
    from glocal_ros.objects import ObjectSetMetadata
    from glocal_ros.tasks import sorted_tasks

    metadata = ObjectSetMetadata.load(objects_dir)
    shares = {task: o.lifting_pose_share for task, o in metadata.objects.items()}
    unmeasured = [task for task, share in shares.items() if share is None]
    if unmeasured:
        raise ValueError(f"{objects_dir}: no lifting-pose share for {', '.join(sorted_tasks(unmeasured))}: "
                         f"run `glocal-ros assets lifting-poses --out {objects_dir}` first")
    if per_third < 1 or 3 * per_third > len(shares):
        raise ValueError(f"{per_third} objects per third of {len(shares)}: need 1 to {len(shares) // 3}")
    ranked = sorted(shares, key=lambda task: (shares[task], task))
    prefix = prefix or ("novel" if metadata.seed is None else f"seed{metadata.seed}")
    chosen = []
    for third, name in enumerate(THIRDS):
        members = ranked[third * len(ranked) // 3:(third + 1) * len(ranked) // 3]
        picks = [members[round((k + 0.5) * len(members) / per_third - 0.5)] for k in range(per_third)]
        chosen += [NovelObject(f"{prefix}_{task}", Path(objects_dir) / task, shares[task], name) for task in picks]
    return chosen


def check_novel(objects: Sequence[NovelObject]) -> None:
    """``ValueError`` when one of ``objects`` is an object of the committed set, which every run trains on."""
    from glocal_ros.paths import object_fingerprint, objects_dir
    from glocal_ros.tasks import ALL_TASKS

    committed = {object_fingerprint(task, objects_dir()): task for task in ALL_TASKS}
    known = [f"{novel.source.name} ({committed[fingerprint]})" for novel in objects
             if (fingerprint := object_fingerprint(novel.source.name, novel.source.parent)) in committed]
    if known:
        raise ValueError(f"not novel, objects of the committed set: {', '.join(known)}: give a set that `assets "
                         "generate --seed S` made with a seed the committed set did not use")


def score_candidates(run: FewshotRun, novel: NovelObject, objects: Path, seed: int, settings: TransferSettings
                     ) -> list[tuple[str, str, float]]:
    """Every candidate's successes on the object under its own bit, on adapt's seeded episodes, in-process."""
    from glocal_app.benches.transfer import prior_stores
    from glocal_ros.adaptation import EVALUATION_STREAM
    from glocal_ros.seeds import derived_seed
    from glocal_ros.tasks import novel_task
    from learner_node.evaluation import evaluate
    from learner_node.policies import PolicyRegistry
    from learner_node.policy_store import PolicyStore
    from learner_node.profiles import learner_profile
    from learner_node.training import Trainer
    from sim_node.batch import BatchedEnvs
    from sim_node.grasp_env import GraspEnv

    tasks = [novel_task(novel.name, candidate.proxy) for candidate in run.candidates]
    envs = BatchedEnvs(lambda i: GraspEnv(tasks[0], objects), settings.num_envs, tasks[0])
    try:
        with tempfile.TemporaryDirectory(prefix="glocal-bench-fewshot-") as work:
            policies = PolicyRegistry(PolicyStore(Path(work) / "policies"),
                                      prior_stores(run.path / "policies", run.profile))
            trainer = Trainer(envs, policies, Path(work) / "checkpoints", profile=learner_profile(run.profile))
            scores = []
            for candidate, task in zip(run.candidates, tasks):
                (score,) = evaluate(envs, trainer.evaluation_policy(candidate.policy, [task]), [task],
                                    settings.eval_episodes, seed=derived_seed(seed, EVALUATION_STREAM))
                scores.append((candidate.policy, candidate.proxy, float(score.successes)))
            return scores
    finally:
        envs.close()


def run_case(run: FewshotRun, novel: NovelObject, seed: int, settings: TransferSettings,
             log: Callable[[str], None] = print) -> FewshotCase:
    """One run, object and seed: the candidates scored, then a goal per arm (shared where their starts are)."""
    from glocal_app.benches.transfer import run_goal
    from glocal_ros.adaptation import Candidate, choose
    from glocal_ros.objects.pipeline import prepare_object
    from glocal_ros.tasks import novel_task

    with tempfile.TemporaryDirectory(prefix="glocal-bench-fewshot-objects-") as work:
        objects = Path(work) / "objects"
        prepare_object(novel.source, novel.name, objects)
        scores = score_candidates(run, novel, objects, seed, settings)
        by_policy = {candidate.policy: candidate for candidate in run.candidates}
        chosen = choose([(by_policy[policy], score) for policy, _, score in scores])
        starts = {"adapt's choice": chosen,
                  "prior": next(c for c in run.candidates if "prior" in c.roles),
                  "last": next((c for c in run.candidates if "last" in c.roles), None)}
        goal_settings = replace(settings, objects_dir=objects, stop_at_threshold=True)
        ran: dict[Candidate, TransferGoal] = {}
        goals = {}
        for arm, start in starts.items():
            if start is None:
                continue
            if start not in ran:
                ran[start] = run_goal(PROFILE_RECIPE, start.policy, novel_task(novel.name, start.proxy), seed,
                                      goal_settings, prior_store=run.path / "policies", profile=run.profile)
            goals[arm] = ran[start]
    case = FewshotCase(run.run_id, run.profile, novel, seed, tuple(scores), chosen.policy, goals, run.fingerprint)
    log(_case_line(case))
    return case


def _steps(goal: TransferGoal | None) -> str:
    return "-" if goal is None else "never" if goal.steps_to_b is None else str(goal.steps_to_b)


def _case_line(case: FewshotCase) -> str:
    return (f"{case.run} {case.object.name} ({case.object.third}) seed {case.seed}: chose {case.chosen}; steps to "
            f"B " + ", ".join(f"{arm} {_steps(case.goals.get(arm))}" for arm in ARMS))


class CaseLog(GoalLog):
    """``cases.jsonl``: one JSON line per finished case (``GoalLog``'s rules for torn lines)."""

    FILE = CASES_FILE
    FIELDS = frozenset({"run", "run_fingerprint", "profile", "object", "seed", "scores", "chosen", "goals", "arms",
                        "key"})
    WHAT = "a case of bench fewshot"


def case_key(settings: TransferSettings) -> dict:
    """What, besides its run, object and seed, decides a case: a case of another key is not this bench's."""
    return {"step_budget": settings.step_budget, "eval_interval": settings.eval_interval,
            "eval_episodes": settings.eval_episodes, "threshold": settings.threshold,
            "num_envs": settings.num_envs}


def _fingerprint(novel: NovelObject) -> str:
    from glocal_ros.paths import object_fingerprint

    return object_fingerprint(novel.source.name, novel.source.parent)


def case_record(case: FewshotCase, key: dict) -> dict:
    """One line of ``cases.jsonl``; arms that shared a goal share it again when read back."""
    goals = list({id(goal): goal for goal in case.goals.values()}.values())
    novel = case.object
    return {"run": case.run, "run_fingerprint": case.run_fingerprint, "profile": case.profile, "seed": case.seed,
            "chosen": case.chosen,
            "object": {"name": novel.name, "source": str(novel.source), "third": novel.third,
                       "lifting_pose_share": novel.lifting_pose_share, "fingerprint": _fingerprint(novel)},
            "scores": [list(score) for score in case.scores],
            "goals": [{"recipe": goal.recipe, "task": goal.task, "prior": goal.prior, "profile": goal.profile,
                       "curve": [list(point) for point in goal.curve], "wall_s": goal.wall_s,
                       "instruments": [[steps, values] for steps, values in goal.instruments]} for goal in goals],
            "arms": {arm: next(i for i, goal in enumerate(goals) if goal is case.goals[arm]) for arm in case.goals},
            "key": key}


def case_of_record(record: dict, settings: TransferSettings) -> FewshotCase:
    seed = int(record["seed"])
    goals = [TransferGoal(goal["recipe"], goal["task"], seed, tuple(tuple(point) for point in goal["curve"]),
                          settings.eval_episodes, settings.threshold, float(goal["wall_s"]), goal["prior"],
                          goal["profile"], tuple((int(steps), dict(values)) for steps, values in goal["instruments"]))
             for goal in record["goals"]]
    novel = record["object"]
    return FewshotCase(record["run"], record["profile"],
                       NovelObject(novel["name"], Path(novel["source"]), float(novel["lifting_pose_share"]),
                                   novel["third"]),
                       seed, tuple((policy, proxy, float(score)) for policy, proxy, score in record["scores"]),
                       record["chosen"], {arm: goals[index] for arm, index in record["arms"].items()},
                       record["run_fingerprint"])


def held_cases(work_dir: Path, settings: TransferSettings, objects: Sequence[NovelObject] = (),
               runs: Sequence[FewshotRun] = ()) -> dict[tuple[str, str, int], FewshotCase]:
    """The cases ``work_dir`` holds, by (run, object, seed); ``ValueError`` when any is of other settings, of
    one of ``objects`` whose files have changed since, or of another run than the one of ``runs`` of its id."""
    log = CaseLog(work_dir)
    key, fingerprints, cases = case_key(settings), {novel.name: _fingerprint(novel) for novel in objects}, {}
    run_fingerprints = {run.run_id: run.fingerprint for run in runs}
    for number, record in enumerate(log.records(), 1):
        if record["key"] != key:
            theirs = record["key"] if isinstance(record["key"], dict) else {}
            differ = ", ".join(f"{name} {theirs.get(name)} (now {value})" for name, value in key.items()
                               if theirs.get(name) != value)
            raise ValueError(f"{log.path} holds cases of other settings ({differ}): run with those, or choose "
                             "another --work-dir")
        case = case_of_record(record, settings)
        if fingerprints.get(case.object.name, record["object"]["fingerprint"]) != record["object"]["fingerprint"]:
            raise ValueError(f"the object {case.object.name} has changed since its cases in {log.path} ran (set "
                             "regenerated?): choose another --work-dir")
        if run_fingerprints.get(case.run, case.run_fingerprint) != case.run_fingerprint:
            raise ValueError(f"{log.path} holds cases of another run named {case.run} (other weights): choose "
                             "another --work-dir")
        if (case.run, case.object.name, case.seed) in cases:
            raise ValueError(f"{log.path}, line {number}: {case.run} {case.object.name} seed {case.seed} is in it "
                             "twice")
        cases[(case.run, case.object.name, case.seed)] = case
    return cases


def fewshot_selection(run_dirs: Sequence[Path], objects_dir: Path, seeds: Sequence[int], settings: TransferSettings,
                      per_third: int = 3) -> tuple[list[FewshotRun], list[NovelObject]]:
    """The runs and objects of a bench; ``ValueError`` before any case for a run or a set it cannot use."""
    settings.check()
    objects = novel_objects(objects_dir, per_third)
    check_novel(objects)
    runs = [read_run(path) for path in run_dirs]
    named = [run.run_id for run in runs]
    if len(set(named)) != len(named):
        repeated = next(name for name in named if named.count(name) > 1)
        raise ValueError(f"two runs named {repeated}: give them to separate benches (each its own --work-dir)")
    if not seeds or len(set(seeds)) != len(seeds):
        raise ValueError(f"seeds must be given once each, got {list(seeds)}")
    return runs, objects


def _quiet(_: str) -> None:
    """A worker's log: the bench prints each case as it is kept."""


def run_fewshot_bench(run_dirs: Sequence[Path], objects_dir: Path, seeds: Sequence[int], settings: TransferSettings,
                      per_third: int = 3, work_dir: Path = DEFAULT_WORK_DIR, jobs: int = 1,
                      log: Callable[[str], None] = print) -> list[FewshotCase]:
    """Every run x object x seed that ``work_dir`` does not hold yet, ``jobs`` at a time in spawned workers, each
    kept as it finishes; then every case of the selection, seed by seed, hard objects first."""
    runs, objects = fewshot_selection(run_dirs, objects_dir, seeds, settings, per_third)
    if jobs < 1:
        raise ValueError(f"jobs must be at least 1, got {jobs}")
    held_cases(work_dir, settings, objects, runs)  # refuse other settings before anything is created in it
    with work_lock(work_dir):
        case_log = CaseLog(work_dir)
        case_log.drop_torn_line()
        done = held_cases(work_dir, settings, objects, runs)
        selection = [(run, novel, seed) for run in runs for seed in seeds for novel in objects]
        pending = [(run, novel, seed) for run, novel, seed in selection if (run.run_id, novel.name, seed) not in done]
        log(f"bench fewshot: {len(selection) - len(pending)} of {len(selection)} cases finished before (in "
            f"{case_log.path}), {len(pending)} to run, {min(jobs, len(pending))} at a time")
        if pending:
            key = case_key(settings)
            # Spawned workers: pybullet, torch and JAX do not survive a fork of a process that uses them.
            with ProcessPoolExecutor(max_workers=min(jobs, len(pending)), mp_context=get_context("spawn")) as pool:
                futures = [pool.submit(run_case, run, novel, seed, settings, _quiet) for run, novel, seed in pending]
                try:
                    for finished, future in enumerate(as_completed(futures), 1):
                        case = future.result()
                        case_log.append(case_record(case, key))
                        done[(case.run, case.object.name, case.seed)] = case
                        log(f"[{finished}/{len(pending)}] {_case_line(case)}")
                except BaseException:  # a failed case or Ctrl-C: start nothing more; what finished is kept
                    pool.shutdown(wait=False, cancel_futures=True)
                    raise
    return [done[(run.run_id, novel.name, seed)] for run, novel, seed in selection]


def _median(values: Sequence[float]) -> str:
    if not values:
        return "-"
    median = statistics.median(values)
    return "never" if math.isinf(median) else f"{median:.0f}"


def fewshot_report(cases: Sequence[FewshotCase], command: str, settings: TransferSettings, objects_dir: Path,
                   work_dir: Path | None = None, jobs: int = 1, selected: int | None = None) -> str:
    """The table: median steps to B per arm and difficulty third, then every case. ``work_dir``: where the cases
    are kept; ``selected``: the selection's cases, when ``cases`` are only those of them already held
    (``--tabulate``)."""
    runs = list(dict.fromkeys((case.run, case.profile) for case in cases))
    if work_dir is None:
        provenance = ""
    elif selected is not None:
        provenance = (f"Tabulated from `{work_dir / CASES_FILE}`, nothing run: {len(cases)} of the selection's "
                      f"{selected} cases finished. ")
    else:
        provenance = (f"In-process, {jobs} case{'s' if jobs != 1 else ''} at a time, cases kept in "
                      f"`{work_dir / CASES_FILE}`. ")
    lines = [
        "# bench fewshot: novel objects from a run's global policies, from the prior, from its last policy",
        "",
        f"Command: `{command}`  ",
        f"{time.strftime('%Y-%m-%d %H:%M')}, Python {sys.version.split()[0]}, {os.cpu_count()} CPU cores, "
        f"load average at the end {os.getloadavg()[0]:.1f} (the machine is shared). {provenance}"
        f"Objects from `{objects_dir}`, "
        f"by thirds of their lifting-pose shares (hard: the lowest). Per run, object and seed: every candidate "
        f"scored on the object under its own task's bit over {settings.eval_episodes} seeded episodes, then one "
        f"Train goal per arm on {settings.num_envs} envs, scored every {settings.eval_interval} steps, stopped at "
        f"its first score above B = {settings.threshold:g} or at {settings.step_budget} steps. Steps to B: 0 for a "
        f"start already above B; a goal that never passed counts as slower than all in a median.",
        "",
        "| run | profile | third | cases | " + " | ".join(f"median steps to B from {arm}" for arm in ARMS)
        + " | " + " | ".join(f"passed from {arm}" for arm in ARMS) + " |",
        "| --- | --- | --- | ---: | " + " | ".join(["---:"] * 2 * len(ARMS)) + " |",
    ]
    for run, profile in runs:
        for third in (*THIRDS, "all"):
            mine = [c for c in cases if c.run == run and (third == "all" or c.object.third == third)]
            if not mine:
                continue
            medians = [_median([math.inf if c.goals[arm].steps_to_b is None else c.goals[arm].steps_to_b
                                for c in mine if arm in c.goals]) for arm in ARMS]
            passed = [f"{sum(c.goals[arm].steps_to_b is not None for c in mine if arm in c.goals)} of "
                      f"{sum(arm in c.goals for c in mine)}" for arm in ARMS]
            lines.append(f"| {run} | {profile} | {third} | {len(mine)} | " + " | ".join(medians) + " | "
                         + " | ".join(passed) + " |")
    lines += ["", "Every case (scores out of "
              f"{settings.eval_episodes}; `*` adapt's choice):", "",
              "| run | object | lifting poses | third | seed | candidates | "
              + " | ".join(f"steps to B from {arm}" for arm in ARMS) + " | s |",
              "| --- | --- | ---: | --- | ---: | --- | " + " | ".join("---:" for _ in ARMS) + " | ---: |"]
    for case in cases:
        scores = ", ".join(f"{'*' if policy == case.chosen else ''}{policy} as {proxy}: {score:g}"
                           for policy, proxy, score in case.scores)
        wall = sum(goal.wall_s for goal in {id(g): g for g in case.goals.values()}.values())
        lines.append(f"| {case.run} | {case.object.name} | {case.object.lifting_pose_share:.0%} | "
                     f"{case.object.third} | {case.seed} | {scores} | "
                     + " | ".join(_steps(case.goals.get(arm)) for arm in ARMS) + f" | {wall:.0f} |")
    return "\n".join(lines) + "\n"


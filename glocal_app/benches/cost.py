"""``glocal-ros bench cost``: a learning-cost map, steps to B per object from the prior (issue 31, item 1).

Does the letter say what learning costs? Per object and seed, one seeded
Train goal from the profile's prior, as a curriculum sends it: stopped at
its first score above B (``TransferSettings.stop_at_threshold``, the
learner's ``stop_when_learned``), capped at ``step_budget`` training steps,
and scored every ``eval_interval`` steps on ``eval_episodes`` deterministic
episodes (B = 0.75 of them, ``passes_threshold``). The goal checks before
its first step too, so a prior already above B costs 0 steps. The goals are
``bench transfer``'s (``glocal_app.benches.transfer.run_goal``: in-process,
``jobs`` at a time in spawned workers, every stream derived from the seed);
this module selects them, keeps them and reads the map off them. They
fine-tune with the profile's own recipe, or with ``recipe`` (one of
``learner_node.sac_settings.FINE_TUNING_RECIPES``): a map per recipe is how a
remedy for the dip is judged on every object (issue 45, item 3).

Choices:

- Tasks: ``all`` (49), a comma-separated list, or ``per-row:K`` (K of 1..7):
  row r (A = 0) takes columns (1 + K r + j) mod 7, j < K, so that every
  column is covered as evenly as K allows (``per-row:3``: 21 objects, each
  column 3 times) and A0, which the prior was trained on and passes by
  construction, comes last in its row (in with K = 7 only).
- Defaults, for a map of about 2 hours on 2 cores (``--jobs 2``):
  ``per-row:3`` x seeds 0, 1 (42 goals; all 49 objects x 2 seeds take about
  2.3 times as long); a cap of ``DEFAULT_STEP_BUDGET`` = 15,000 training steps,
  the row-G target's number: the smallest cap that decides that target (a
  goal not learned within it needs more than 15,000 steps), a larger one
  only costs more; an evaluation every ``DEFAULT_EVAL_INTERVAL`` = 1,000
  steps, the interval at which the curriculum presets (``bench``, ``demo``)
  check "score > B", so that steps to B is what a curriculum is charged,
  and the resolution the row-A/B target of 1,000 steps needs; S-bar = the
  paper's 100 episodes (B = 75). Measured here (2 shared cores at load 2.2,
  one process, the 64x64 SBX prior on G6): 57 training steps/s on 4 envs
  (1,000 steps, model loading included), 12 s for an evaluation of 100
  episodes by a policy that passes (98/100) and 24 s by one that fails
  every episode (the paper profile's prior, 0/100: each episode runs its
  50 steps). So a goal that hits the cap costs about 15,000 / 57 + 16 x 24
  s, 11 minutes of a core, and one that passes at step 0 well under a
  minute. If steps to B rises row by row (A about 500, C 3,000, E 10,000)
  and rows F and G hit the cap, the 42 goals take about 13,000 core-seconds:
  under 2 hours with 2 jobs; the worst case, all 42 capped, about 4 hours
  (stop it and resume it: see below).
- Steps to B of a goal: the first evaluation above B (``TransferGoal.steps_to_b``);
  a goal that never passed is "not learned within the cap", counted as
  slower than any learned one (``math.inf``) in every statistic below.
- Per object: the median over its seeds (``median_steps_to_b``). With an even
  number of seeds that is the mean of the middle two, not learned when
  either of them is: with 2 seeds, an object is learned within the cap only
  when both goals were. The per-object table shows every seed as well.
- Row medians: the median over all the row's goals (objects x seeds, each
  goal one vote), not over the objects' medians, which with 2 seeds already
  turn "one seed not learned" into "not learned".
- Spearman: between the letter's index (A = 0 .. G = 6) and the objects'
  medians (``assets validate``'s ``letter_correlation``); not-learned
  objects count as above the cap: they rank above every learned object, tied
  among themselves. NaN (shown as such, a missed target) with fewer than 3
  objects or all medians equal.
- The prior passes B on an object at step 0 when the object's median steps
  to B is 0 (with 2 seeds: both goals' checks before their first step passed).

The report (markdown with the command that made it) has the targets of the
issue, met or missed (nothing here is tuned to them), the row table, the
7x7 map, every object and every goal; the figure beside it (``.png``) is the
7x7 heat map: cells coloured by log steps to B, cap-hit cells hatched and
marked, untested cells blank.

Against another map (``--against REPORT``, issue 45): a recipe's map is
judged on the goals it shares with another map of the same settings, read
back from that map's report (its every-goal table): the issue's targets (rows
A-D still 0, rows E-G halved, the goals that start below B learned within
12,000 steps and without a drop of more than 15 points, wall-clock per
training step at most 1.5 times), and those goals side by side. Wall-clock
per training step is total over total of the goals that trained, their
evaluations included; two maps run on a shared machine at other loads, so a
ratio near the target tells little.

Resumable: every finished goal is appended, one JSON line, flushed and
fsynced, to ``goals.jsonl`` in the work directory as it finishes; the same
command skips the goals found there (a line torn by a kill is dropped and its
goal runs again), and ``--tabulate`` reports them without running anything.
Each line carries what decides its goal (cap, interval, episodes, B, envs,
profile, the prior's stored file, a hash of its object's files): a work
directory of other settings, or whose objects have since changed, is refused
before any goal runs, as is bad input (unknown task, a cap below one
interval, ...). Goals of tasks outside the selection stay in the file and
serve a later, wider selection with the same settings. A lock on the work
directory keeps a second bench out of it.
"""

from __future__ import annotations

import fcntl
import json
import math
import os
import re
import statistics
import sys
import time
from concurrent.futures import CancelledError, ProcessPoolExecutor, as_completed
from contextlib import contextmanager
from dataclasses import dataclass
from multiprocessing import get_context
from pathlib import Path
from typing import Callable, Iterator, Sequence

from glocal_app.benches.transfer import (COLLAPSE_AFTER, INITIAL_POLICY, PROFILE_RECIPE, TransferGoal,
                                         TransferSettings, check_goals, median_steps_to_b, prior_stores, run_goal)
from glocal_ros.curriculum.learner import PAPER_EVAL_EPISODES, passes_threshold
from glocal_ros.files import atomic_write
from glocal_ros.paths import object_fingerprint
from glocal_ros.tasks import (COMPLEXITY_LEVELS, DIFFICULTY_LEVELS, NUM_TASKS, grid_coordinates, parse_task_list,
                              sorted_tasks)
from learner_node.profiles import DEFAULT_PROFILE

DEFAULT_TASKS = "per-row:3"
DEFAULT_SEEDS = (0, 1)
DEFAULT_STEP_BUDGET = 15_000
DEFAULT_EVAL_INTERVAL = 1_000
DEFAULT_EVAL_EPISODES = PAPER_EVAL_EPISODES
DEFAULT_WORK_DIR = Path("runs/bench-cost")
DEFAULT_REPORT = Path("bench/results/cost.md")
GOALS_FILE = "goals.jsonl"
LOCK_FILE = "lock"
PER_ROW = "per-row:"

#: The issue's targets for the map (issue 31); reported, met or missed, never tuned for.
TARGET_SPEARMAN = 0.8
TARGET_EASY_ROWS = ("A", "B")
TARGET_EASY_MEDIAN = 1_000
TARGET_HARD_ROW = "G"
TARGET_HARD_MEDIAN = 15_000
TARGET_START_PASSES = 15  # of NUM_TASKS objects

#: Issue 45's targets for a recipe's map against another map (``--against``); reported, never tuned for.
TARGET_UNCHANGED_ROWS = ("A", "B", "C", "D")  # medians still 0
TARGET_HALVED_ROWS = ("E", "F", "G")  # medians at most half the other map's
TARGET_TRAINED_STEPS = 12_000  # the goals that start below B: their median steps to B at most this,
TARGET_QUICK_GOALS = 10  # and at least this many of them pass B in fewer steps
TARGET_DROP_POINTS = 15.0  # none of them further below its start (``TransferGoal.drop_points``)
TARGET_WALL_RATIO = 1.5  # wall-clock per training step against the other map's


def per_row_tasks(per_row: int) -> list[str]:
    """``per_row`` objects of every row, the columns rotating so that each column is covered as evenly as
    possible; A0 (the prior's own task) is the last column row A takes."""
    if not 1 <= per_row <= len(COMPLEXITY_LEVELS):
        raise ValueError(f"{PER_ROW}{per_row}: objects per row must lie in 1..{len(COMPLEXITY_LEVELS)}")
    columns = len(COMPLEXITY_LEVELS)
    return sorted_tasks([letter + COMPLEXITY_LEVELS[(1 + per_row * row + j) % columns]
                         for row, letter in enumerate(DIFFICULTY_LEVELS) for j in range(per_row)])


def select_tasks(text: str) -> list[str]:
    """``all``, ``per-row:K`` or comma-separated tasks, in grid order; ``ValueError`` naming what is wrong."""
    text = text.strip()
    if text.lower().startswith(PER_ROW):
        count = text[len(PER_ROW):]
        if not count.isdigit():
            raise ValueError(f"{text!r}: expected {PER_ROW}K with K objects per row, 1..{len(COMPLEXITY_LEVELS)}")
        return per_row_tasks(int(count))
    tasks = parse_task_list(text)
    if len(set(tasks)) != len(tasks):
        raise ValueError(f"tasks must not repeat, got {text!r}")
    return sorted_tasks(tasks)


def cost_settings(step_budget: int = DEFAULT_STEP_BUDGET, eval_interval: int = DEFAULT_EVAL_INTERVAL,
                  eval_episodes: int = DEFAULT_EVAL_EPISODES, num_envs: int = TransferSettings.num_envs,
                  objects_dir: Path | None = None) -> TransferSettings:
    """The goals' settings: ``bench transfer``'s, stopped at B; ``objects_dir`` None: the shipped objects."""
    return TransferSettings(step_budget=step_budget, eval_interval=eval_interval, eval_episodes=eval_episodes,
                            num_envs=num_envs, stop_at_threshold=True, objects_dir=objects_dir)


def check_cost(tasks: Sequence[str], seeds: Sequence[int], settings: TransferSettings, jobs: int,
               profile: str = DEFAULT_PROFILE, prior_store: Path | None = None,
               recipe: str = PROFILE_RECIPE) -> None:
    """``ValueError`` for anything that would fail later, before any goal runs."""
    if not settings.stop_at_threshold:
        raise ValueError("a cost map's goals stop at B: use cost_settings")
    check_goals([recipe], [INITIAL_POLICY], prior_store, tasks, seeds, settings, jobs, [profile])


def run_key(settings: TransferSettings, profile: str = DEFAULT_PROFILE, prior_store: Path | None = None,
            recipe: str = PROFILE_RECIPE) -> dict:
    """What, besides its task and seed, decides a goal: a goal of another key is not this map's. The prior
    comes from ``prior_store`` when it holds one (``bench transfer``'s ``prior_stores``)."""
    store = next(store for store in prior_stores(prior_store, profile) if INITIAL_POLICY in store)
    record = store.record(INITIAL_POLICY)
    key = {"step_budget": settings.step_budget, "eval_interval": settings.eval_interval,
           "eval_episodes": settings.eval_episodes, "threshold": settings.threshold,
           "num_envs": settings.num_envs, "profile": profile,
           "prior": f"{INITIAL_POLICY} ({record.model_file}, {record.updated})"}
    # Maps kept before recipes could be chosen ran the profile's own: their keys have no recipe.
    if recipe != PROFILE_RECIPE:
        key["recipe"] = recipe
    return key


class GoalLog:
    """``goals.jsonl`` of a work directory: one JSON line per finished goal, appended as it finishes."""

    FILE = GOALS_FILE
    FIELDS = frozenset({"task", "seed", "curve", "key", "object"})  # every line has them
    WHAT = "a goal of bench cost"

    def __init__(self, work_dir: Path):
        self.path = Path(work_dir) / self.FILE

    def records(self) -> list[dict]:
        """Every whole line; a last line without its newline (a kill mid-write) is not one."""
        if not self.path.is_file():
            return []
        text = self.path.read_text()
        lines = text.split("\n")[:-1]  # the part after the last newline is torn (or empty)
        records = []
        for number, line in enumerate(lines, 1):
            try:
                record = json.loads(line)
            except json.JSONDecodeError:
                record = None
            if not isinstance(record, dict) or not self.FIELDS <= record.keys():
                raise ValueError(f"{self.path}, line {number}: not {self.WHAT} ({line[:60]!r}): "
                                 "choose another --work-dir")
            records.append(record)
        return records

    def drop_torn_line(self) -> None:
        """Rewrite the file without a torn last line, so that the next line starts on a line of its own."""
        text = self.path.read_text() if self.path.is_file() else ""
        if text and not text.endswith("\n"):
            whole = text.rpartition("\n")[0]
            atomic_write(self.path, lambda stream: stream.write((whole + "\n" if whole else "").encode()))

    def append(self, record: dict) -> None:
        with open(self.path, "a") as stream:
            stream.write(json.dumps(record) + "\n")
            stream.flush()
            os.fsync(stream.fileno())


def goal_record(goal: TransferGoal, key: dict, fingerprint: str) -> dict:
    return {"task": goal.task, "seed": goal.seed, "curve": [list(point) for point in goal.curve],
            "wall_s": round(goal.wall_s, 2), "key": key, "object": fingerprint}


def finished_goals(work_dir: Path, settings: TransferSettings, profile: str = DEFAULT_PROFILE,
                   prior_store: Path | None = None,
                   recipe: str = PROFILE_RECIPE) -> dict[tuple[str, int], TransferGoal]:
    """The goals ``work_dir`` holds, by (task, seed); ``ValueError`` when any is of other settings or of an
    object that has changed since."""
    log = GoalLog(work_dir)
    key, goals, fingerprints = run_key(settings, profile, prior_store, recipe), {}, {}
    for number, record in enumerate(log.records(), 1):
        if record.get("key") != key:
            theirs = {"recipe": PROFILE_RECIPE, **(record.get("key") or {})}
            differ = ", ".join(f"{name} {theirs.get(name)} (now {value})"
                               for name, value in {"recipe": recipe, **key}.items() if theirs.get(name) != value)
            raise ValueError(f"{log.path} holds goals of other settings ({differ}): run with those, or choose "
                             "another --work-dir")
        task, seed = record["task"], int(record["seed"])
        if task not in fingerprints:
            fingerprints[task] = object_fingerprint(task, settings.objects_dir)
        if record["object"] != fingerprints[task]:
            raise ValueError(f"the object of {task} has changed since its goals in {log.path} ran (objects "
                             "regenerated?): choose another --work-dir")
        if (task, seed) in goals:
            raise ValueError(f"{log.path}, line {number}: goal {task} seed {seed} is in it twice")
        goals[(task, seed)] = TransferGoal(recipe, task, seed, tuple(tuple(p) for p in record["curve"]),
                                           settings.eval_episodes, settings.threshold, float(record["wall_s"]),
                                           INITIAL_POLICY, profile)
    return goals


def held_cost_map(work_dir: Path, objects_dir: Path | None = None,
                  prior_store: Path | None = None) -> tuple[TransferSettings, list[TransferGoal]]:
    """Every goal a cost map's ``work_dir`` holds, with the settings they ran with (read off their key), for
    a reader that did not run them (``assets validate``); ``ValueError`` when it holds none, or goals of
    another prior or of objects that have changed since (``finished_goals``)."""
    records = GoalLog(work_dir).records()
    if not records:
        raise ValueError(f"{Path(work_dir) / GOALS_FILE} holds no goal of bench cost")
    key = records[0]["key"]
    try:
        settings = cost_settings(key["step_budget"], key["eval_interval"], key["eval_episodes"], key["num_envs"],
                                 objects_dir)
        profile, recipe = key["profile"], key.get("recipe", PROFILE_RECIPE)
    except (KeyError, TypeError):
        raise ValueError(f"{Path(work_dir) / GOALS_FILE}, line 1: not a goal of bench cost (its key lacks "
                         "the settings)") from None
    return settings, list(finished_goals(work_dir, settings, profile, prior_store, recipe).values())


@contextmanager
def work_lock(work_dir: Path) -> Iterator[None]:
    """Hold ``work_dir`` for this process; ``ValueError`` when another bench holds it."""
    Path(work_dir).mkdir(parents=True, exist_ok=True)
    with open(Path(work_dir) / LOCK_FILE, "w") as handle:
        try:
            fcntl.flock(handle, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            raise ValueError(f"another bench cost is running in {work_dir}") from None
        yield


def run_order(tasks: Sequence[str], seeds: Sequence[int]) -> list[tuple[str, int]]:
    """Seed by seed, so that a map stopped half-way has whole seeds; within a seed the hard rows first, so
    that the longest goals do not leave a core idle at the end."""
    return [(task, seed) for seed in seeds
            for task in sorted(tasks, key=lambda task: (-grid_coordinates(task)[0], grid_coordinates(task)[1]))]


def run_cost_map(tasks: Sequence[str], seeds: Sequence[int], settings: TransferSettings, work_dir: Path,
                 jobs: int, profile: str = DEFAULT_PROFILE, log: Callable[[str], None] = print,
                 prior_store: Path | None = None, recipe: str = PROFILE_RECIPE) -> list[TransferGoal]:
    """Every (task, seed) goal that ``work_dir`` does not hold yet, ``jobs`` at a time, each appended to it as
    it finishes; then every goal of the selection, in grid order, each object's seeds together."""
    check_cost(tasks, seeds, settings, jobs, profile, prior_store, recipe)
    # A work dir of other settings is refused before anything is created in it.
    finished_goals(work_dir, settings, profile, prior_store, recipe)
    with work_lock(work_dir):
        goal_log = GoalLog(work_dir)
        goal_log.drop_torn_line()
        done = finished_goals(work_dir, settings, profile, prior_store, recipe)
        selection = run_order(tasks, seeds)
        pending = [goal for goal in selection if goal not in done]
        log(f"bench cost: {len(selection) - len(pending)} of {len(selection)} goals finished before "
            f"(in {goal_log.path}), {len(pending)} to run, {min(jobs, len(pending))} at a time")
        if pending:
            key = run_key(settings, profile, prior_store, recipe)
            fingerprints = {task: object_fingerprint(task, settings.objects_dir)
                            for task in {task for task, _ in pending}}
            _run_pending(pending, settings, jobs, profile, prior_store, done, goal_log, key, fingerprints, log,
                         recipe)
    return [done[(task, seed)] for task, seed in _grid_order(tasks, seeds)]


def _run_pending(pending: list[tuple[str, int]], settings: TransferSettings, jobs: int, profile: str,
                 prior_store: Path | None, done: dict[tuple[str, int], TransferGoal], goal_log: GoalLog, key: dict,
                 fingerprints: dict[str, str], log: Callable[[str], None], recipe: str = PROFILE_RECIPE) -> None:
    """Run ``pending`` in spawned workers, appending each goal to ``goal_log`` and ``done`` as it finishes."""
    # Spawned workers: pybullet, torch and JAX do not survive a fork of a process that uses them.
    with ProcessPoolExecutor(max_workers=min(jobs, len(pending)), mp_context=get_context("spawn")) as pool:
        futures = {pool.submit(run_goal, recipe, INITIAL_POLICY, task, seed, settings, prior_store, profile):
                   (task, seed) for task, seed in pending}
        failed: list[tuple[tuple[str, int], Exception]] = []
        finished = 0
        try:
            for future in as_completed(futures):
                try:
                    goal = future.result()
                except CancelledError:
                    continue
                except Exception as error:  # the others under way finish and are kept; no new one starts
                    if not failed:
                        for other in futures:
                            other.cancel()
                    failed.append((futures[future], error))
                    continue
                goal_log.append(goal_record(goal, key, fingerprints[goal.task]))
                done[(goal.task, goal.seed)] = goal
                finished += 1
                log(f"[{finished}/{len(pending)}] {goal_line(goal, settings)}")
        except BaseException:  # Ctrl-C: start nothing more (the workers got it too)
            pool.shutdown(wait=False, cancel_futures=True)
            raise
    if failed:
        (task, seed), error = failed[0]
        raise RuntimeError(f"the goal {task} seed {seed} failed ({type(error).__name__}: {error}); the goals "
                           f"that finished are kept in {goal_log.path}: the same command resumes") from error


def _grid_order(tasks: Sequence[str], seeds: Sequence[int]) -> list[tuple[str, int]]:
    return [(task, seed) for task in sorted_tasks(tasks) for seed in seeds]


def goal_line(goal: TransferGoal, settings: TransferSettings) -> str:
    steps = goal.steps_to_b
    return (f"{goal.task} seed {goal.seed}: steps to B "
            f"{steps if steps is not None else f'- (not learned within {settings.step_budget})'}, "
            f"{len(goal.curve)} evaluation{'s' if len(goal.curve) != 1 else ''}, {goal.wall_s:.0f} s; scores "
            + " ".join(f"{s}:{score}" for s, score in goal.curve))


# ---- statistics -----------------------------------------------------------------------------------------------

def _steps(goal: TransferGoal) -> float:
    return math.inf if goal.steps_to_b is None else float(goal.steps_to_b)


def object_medians(goals: Sequence[TransferGoal]) -> dict[str, float]:
    """Median steps to B over each object's seeds, ``inf`` where not learned within the cap; grid order."""
    by_task: dict[str, list[TransferGoal]] = {}
    for goal in goals:
        by_task.setdefault(goal.task, []).append(goal)
    return {task: median_steps_to_b(by_task[task]) for task in sorted_tasks(by_task)}


def row_medians(goals: Sequence[TransferGoal]) -> dict[str, float]:
    """Median steps to B over every goal of each tested row (objects x seeds); ``inf``: not learned."""
    return {letter: median_steps_to_b(row) for letter in DIFFICULTY_LEVELS
            if (row := [goal for goal in goals if goal.task[0] == letter])}


def letter_spearman(goals: Sequence[TransferGoal]) -> tuple[float, int]:
    """Spearman's rho between the letter's index and the objects' medians, not learned ranked above the cap;
    and how many objects. NaN with fewer than 3 objects or all medians equal."""
    from glocal_app.benches.assets import letter_correlation

    return letter_correlation(object_medians(goals))


def passed_at_start(goals: Sequence[TransferGoal]) -> list[str]:
    """The objects the prior passes B on at step 0: median steps to B of 0."""
    return [task for task, steps in object_medians(goals).items() if steps == 0]


@dataclass(frozen=True)
class Target:
    name: str
    measured: str
    met: bool | None  # None: nothing to judge it on (rows untested)


def targets(goals: Sequence[TransferGoal], settings: TransferSettings) -> list[Target]:
    """The issue's four targets for the map, as measured on ``goals``."""
    rho, count = letter_spearman(goals)
    rows = row_medians(goals)
    easy = [rows.get(letter) for letter in TARGET_EASY_ROWS]
    hard = rows.get(TARGET_HARD_ROW)
    starts, tested = passed_at_start(goals), len(object_medians(goals))
    share = TARGET_START_PASSES / NUM_TASKS
    return [
        Target(f"Spearman(letter, steps to B) >= +{TARGET_SPEARMAN}",
               ("not measurable (fewer than 3 objects, or all equal)" if math.isnan(rho)
                else f"{rho:+.2f} over {count} objects"),
               None if count == 0 else (not math.isnan(rho) and rho >= TARGET_SPEARMAN)),
        Target(f"row {' and '.join(TARGET_EASY_ROWS)} medians <= {TARGET_EASY_MEDIAN:,} steps",
               ", ".join(f"{letter} {_median_text(value, settings)}" for letter, value
                         in zip(TARGET_EASY_ROWS, easy)),
               None if None in easy else all(value <= TARGET_EASY_MEDIAN for value in easy)),
        Target(f"row {TARGET_HARD_ROW} median >= {TARGET_HARD_MEDIAN:,} steps or not learned within the cap",
               f"{TARGET_HARD_ROW} {_median_text(hard, settings)}"
               + (f" (a cap of {settings.step_budget:,} < {TARGET_HARD_MEDIAN:,}: not learned does not tell)"
                  if hard is not None and math.isinf(hard) and settings.step_budget < TARGET_HARD_MEDIAN else ""),
               None if hard is None else hard >= TARGET_HARD_MEDIAN),
        Target(f"the prior passes B at step 0 on at most {TARGET_START_PASSES} of {NUM_TASKS} objects",
               f"{len(starts)} of {tested} tested" + (f" (the target's share of {tested}: {share * tested:.1f})"
                                                      if 0 < tested < NUM_TASKS else "")
               + (f": {', '.join(starts)}" if starts else ""),
               None if tested == 0 else len(starts) <= share * tested),
    ]


def target_table(measured: Sequence[Target]) -> list[str]:
    """The markdown table of ``measured`` targets: each met, missed or untested (nothing to judge it on)."""
    lines = ["| target | measured | |", "| --- | --- | --- |"]
    for target in measured:
        verdict = "untested" if target.met is None else "met" if target.met else "missed"
        lines.append(f"| {target.name} | {target.measured} | {verdict} |")
    return lines


def _median_text(value: float | None, settings: TransferSettings) -> str:
    if value is None:
        return "untested"
    return f"not learned within the cap of {settings.step_budget:,}" if math.isinf(value) else f"{value:,.0f}"


def _cell(value: float) -> str:
    return "not learned" if math.isinf(value) else f"{value:.0f}"


# ---- a map against another (issue 45) ------------------------------------------------------------------------

@dataclass(frozen=True)
class HeldMap:
    """A cost map read back from its report (``read_cost_report``)."""

    path: Path
    profile: str
    recipe: str
    settings: TransferSettings
    goals: list[TransferGoal]


_REPORT_SETTINGS = re.compile(
    r"\(learner profile (?P<profile>[^,)]+)(?:, fine-tuning recipe (?P<recipe>[^)]+))?\) per object and seed, "
    r"stopped at its first score above B as a curriculum stops it, capped at (?P<cap>[\d,]+) training steps on "
    r"(?P<envs>\d+) envs, scored before its first step and every (?P<interval>[\d,]+) steps over "
    r"(?P<episodes>\d+) deterministic episodes")
_EVERY_GOAL = "Every goal (scores out of"  # the title of ``cost_report``'s every-goal table


def read_cost_report(path: Path) -> HeldMap:
    """The map a ``cost_report`` at ``path`` shows: its settings (from its opening paragraph) and every goal
    (its every-goal table, wall-clock to the second); ``ValueError`` naming the file when it is not one."""
    text = Path(path).read_text()
    found = _REPORT_SETTINGS.search(text)
    if found is None or _EVERY_GOAL not in text:
        raise ValueError(f"{path}: not a report of bench cost (no settings paragraph or no every-goal table)")
    number = lambda name: int(found[name].replace(",", ""))  # noqa: E731
    settings = cost_settings(number("cap"), number("interval"), number("episodes"), number("envs"))
    recipe = found["recipe"] or PROFILE_RECIPE
    goals = []
    for line in text[text.index(_EVERY_GOAL):].splitlines()[4:]:  # the title, a blank line, the header
        cells = [cell.strip() for cell in line.strip().strip("|").split("|")]
        if len(cells) != 5:
            break
        task, seed, scores, _, wall_s = cells
        curve = tuple((int(steps), int(score)) for steps, score in (point.split(":") for point in scores.split()))
        goals.append(TransferGoal(recipe, task, int(seed), curve, settings.eval_episodes, settings.threshold,
                                  float(wall_s), INITIAL_POLICY, found["profile"]))
    if not goals:
        raise ValueError(f"{path}: its every-goal table holds no goal")
    return HeldMap(Path(path), found["profile"], recipe, settings, goals)


def check_against(other: HeldMap, settings: TransferSettings, profile: str) -> None:
    """``ValueError`` when ``other`` is a map of other settings than these: its goals would not compare."""
    mine = (profile, settings.step_budget, settings.eval_interval, settings.eval_episodes, settings.num_envs)
    theirs = (other.profile, other.settings.step_budget, other.settings.eval_interval,
              other.settings.eval_episodes, other.settings.num_envs)
    differ = [f"{name} {their} (here {my})" for name, my, their
              in zip(("profile", "cap", "evaluation interval", "episodes", "envs"), mine, theirs) if my != their]
    if differ:
        raise ValueError(f"{other.path} is a map of other settings ({', '.join(differ)}): it does not compare")


def started_below_b(goals: Sequence[TransferGoal]) -> list[TransferGoal]:
    """The goals that had to train: below B at their check before the first step."""
    return [goal for goal in goals if not passes_threshold(goal.start, goal.threshold)]


def wall_per_kilostep(goals: Sequence[TransferGoal]) -> float:
    """Seconds of wall-clock per 1,000 training steps, total over total (NaN without a training step)."""
    steps = sum(goal.curve[-1][0] for goal in goals)
    return 1000.0 * sum(goal.wall_s for goal in goals) / steps if steps else math.nan


def against_targets(goals: Sequence[TransferGoal], other: Sequence[TransferGoal],
                    settings: TransferSettings) -> list[Target]:
    """Issue 45's targets for ``goals`` against ``other``, on the (task, seed) goals both hold."""
    theirs_by_key = {(goal.task, goal.seed): goal for goal in other}
    mine = [goal for goal in goals if (goal.task, goal.seed) in theirs_by_key]
    theirs = [theirs_by_key[(goal.task, goal.seed)] for goal in mine]
    rows, their_rows = row_medians(mine), row_medians(theirs)

    def rows_text(letters: Sequence[str]) -> str:
        return ", ".join(f"{letter} {_median_text(rows.get(letter), settings)} "
                         f"(against {_median_text(their_rows.get(letter), settings)})" for letter in letters)

    unchanged = [rows.get(letter) for letter in TARGET_UNCHANGED_ROWS]
    halved = [(rows.get(letter), their_rows.get(letter)) for letter in TARGET_HALVED_ROWS]
    trained, their_trained = started_below_b(mine), started_below_b(theirs)
    median, their_median = (median_steps_to_b(trained) if trained else None,
                            median_steps_to_b(their_trained) if their_trained else None)

    def quick(of: Sequence[TransferGoal]) -> int:
        return sum(goal.steps_to_b is not None and goal.steps_to_b < TARGET_TRAINED_STEPS for goal in of)

    def dropped(of: Sequence[TransferGoal]) -> int:
        return sum(goal.drop_points > TARGET_DROP_POINTS for goal in of)

    def drops(of: Sequence[TransferGoal]) -> str:
        return f"median drop {statistics.median(g.drop_points for g in of):.0f}" if of else "none trained"

    wall, their_wall = wall_per_kilostep(trained), wall_per_kilostep(their_trained)
    ratio = wall / their_wall if their_wall else math.nan
    count = f"of {len(trained)} goals that started below B"
    none_trained = "none of the shared goals started below B"
    return [
        Target(f"rows {', '.join(TARGET_UNCHANGED_ROWS)}: medians still 0", rows_text(TARGET_UNCHANGED_ROWS),
               None if None in unchanged else all(value == 0 for value in unchanged)),
        Target(f"rows {', '.join(TARGET_HALVED_ROWS)}: medians at most half the other map's",
               rows_text(TARGET_HALVED_ROWS),
               None if any(None in pair for pair in halved) else
               all(value == 0 or (math.isfinite(value) and 2 * value <= their) for value, their in halved)),
        Target(f"the goals that started below B: median steps to B <= {TARGET_TRAINED_STEPS:,}",
               none_trained if median is None else
               f"{_median_text(median, settings)} over {len(trained)} (against {_median_text(their_median, settings)})",
               None if median is None else median <= TARGET_TRAINED_STEPS),
        Target(f"at least {TARGET_QUICK_GOALS} of them pass B in fewer than {TARGET_TRAINED_STEPS:,} steps",
               f"{quick(trained)} {count} (against {quick(their_trained)})" if trained else none_trained,
               None if not trained else quick(trained) >= TARGET_QUICK_GOALS),
        Target(f"none of them more than {TARGET_DROP_POINTS:.0f} points of 100 below its start from "
               f"{COLLAPSE_AFTER:,} steps on",
               f"{dropped(trained)} {count}, {drops(trained)} (against {dropped(their_trained)}, "
               f"{drops(their_trained)})" if trained else none_trained,
               None if not trained else dropped(trained) == 0),
        Target(f"wall-clock per training step at most {TARGET_WALL_RATIO} times the other map's",
               "no training step in one map or both" if math.isnan(ratio) else
               f"{wall:.1f} s per 1,000 steps against {their_wall:.1f}: {ratio:.2f} times",
               None if math.isnan(ratio) else ratio <= TARGET_WALL_RATIO),
    ]


def against_lines(goals: Sequence[TransferGoal], other: HeldMap, settings: TransferSettings) -> list[str]:
    """The report's section on ``goals`` against ``other``: the targets, then every shared goal that started
    below B side by side."""
    theirs = {(goal.task, goal.seed): goal for goal in other.goals}
    shared = [goal for goal in goals if (goal.task, goal.seed) in theirs]
    lines = ["", f"## Against `{other.path.name}` (recipe {other.recipe})", "",
             f"The {len(shared)} goals of this map that `{other.path.name}` holds too (its every-goal table). "
             "Targets of issue 45 (reported, not tuned for):", ""]
    lines += target_table(against_targets(shared, other.goals, settings))

    def steps(goal: TransferGoal) -> str:
        return "-" if goal.steps_to_b is None else str(goal.steps_to_b)

    lines += ["", f"The goals that started below B (steps to B, - not learned within the cap; drop in points of "
              f"100 below the start from {COLLAPSE_AFTER:,} steps on):", "",
              "| object | seed | start | steps to B | against | drop | against | s | against |",
              "| --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: |"]
    for goal in started_below_b(shared):
        their = theirs[(goal.task, goal.seed)]
        lines.append(f"| {goal.task} | {goal.seed} | {goal.start} | {steps(goal)} | {steps(their)} "
                     f"| {goal.drop_points:.0f} | {their.drop_points:.0f} | {goal.wall_s:.0f} | {their.wall_s:.0f} |")
    return lines


# ---- report and figure ----------------------------------------------------------------------------------------

def cost_report(goals: Sequence[TransferGoal], command: str, settings: TransferSettings, tasks: Sequence[str],
                seeds: Sequence[int], jobs: int, figure: Path | None, work_dir: Path, tabulated: bool = False,
                profile: str = DEFAULT_PROFILE, recipe: str = PROFILE_RECIPE, against: HeldMap | None = None) -> str:
    """The report of the finished ``goals`` of a selection of ``tasks`` x ``seeds``; with ``against``, the
    goals against that map's as well."""
    expected = len(tasks) * len(seeds)
    cap = settings.step_budget
    lines = [
        "# bench cost: steps to B per object, from the prior",
        "",
        f"Command: `{command}`  ",
        f"{time.strftime('%Y-%m-%d %H:%M')}, Python {sys.version.split()[0]}, {os.cpu_count()} CPU cores, "
        + (f"tabulated from `{work_dir / GOALS_FILE}`, nothing run" if tabulated else
           f"in-process, {jobs} goal{'s' if jobs != 1 else ''} at a time, goals kept in `{work_dir / GOALS_FILE}`"
           f". Load average at the end {os.getloadavg()[0]:.1f} (the machine is shared)")
        + f". One seeded Train goal from `{INITIAL_POLICY}` (learner profile {profile}"
        + ("" if recipe == PROFILE_RECIPE else f", fine-tuning recipe {recipe}") + ") per object and seed, "
        f"stopped at its first score above B as a curriculum stops it, capped at {cap:,} training steps on "
        f"{settings.num_envs} envs, scored before its first step and every {settings.eval_interval:,} steps over "
        f"{settings.eval_episodes} deterministic episodes; B = {settings.threshold:g}. "
        f"Objects {len(tasks)} ({', '.join(sorted_tasks(tasks))})"
        + (f" of `{settings.objects_dir}`" if settings.objects_dir else "")
        + f"; seeds {', '.join(map(str, seeds))}. "
        f"Goals finished: {len(goals)} of {expected}"
        + ("" if len(goals) == expected else " (a partial map: the same command without --tabulate resumes it)")
        + ". Steps to B: the first evaluation above B (0: the prior passes already); a goal that never passed is "
        "not learned within the cap and counts as slower than any learned goal. Per object: the median over its "
        "seeds (of two: their mean, not learned when either is). Rows: the median over the row's goals. "
        "Spearman: the letter's index (A = 0) against the objects' medians, not learned ranked above the cap "
        "(tied among themselves). Wall-clock per goal includes its evaluations.",
        "",
    ]
    if figure is not None:
        lines += [f"Figure: `{figure.name}`, the map as a heat map (log steps to B, from one interval, where 0 "
                  "is drawn, to the cap; hatched: not learned within the cap; blank: untested).", ""]
    lines += ["Targets of issue 31 (reported, not tuned for):", ""] + target_table(targets(goals, settings))

    objects = object_medians(goals)
    rows = row_medians(goals)
    lines += ["", "| row | objects | goals | learned within the cap | passed B at step 0 | median steps to B "
              "| median wall-clock per goal (s) |",
              "| --- | ---: | ---: | ---: | ---: | ---: | ---: |"]
    for letter in DIFFICULTY_LEVELS:
        mine = [goal for goal in goals if goal.task[0] == letter]
        if mine:
            lines.append(f"| {letter} | {len({goal.task for goal in mine})} | {len(mine)} "
                         f"| {sum(goal.steps_to_b is not None for goal in mine)} "
                         f"| {sum(goal.steps_to_b == 0 for goal in mine)} | {_cell(rows[letter])} "
                         f"| {statistics.median(goal.wall_s for goal in mine):.0f} |")
    if goals:
        lines.append(f"| all | {len(objects)} | {len(goals)} | {sum(g.steps_to_b is not None for g in goals)} "
                     f"| {sum(g.steps_to_b == 0 for g in goals)} | {_cell(median_steps_to_b(goals))} "
                     f"| {statistics.median(g.wall_s for g in goals):.0f} |")
        lines += ["", f"Cost of the map: {sum(g.curve[-1][0] for g in goals):,} training steps, "
                  f"{sum(len(g.curve) for g in goals):,} evaluations, {sum(g.wall_s for g in goals) / 3600:.2f} "
                  "goal-hours of wall-clock."]

    lines += ["", "The map: median steps to B per object (- untested):", "",
              "| | " + " | ".join(COMPLEXITY_LEVELS) + " |", "| --- |" + " ---: |" * len(COMPLEXITY_LEVELS)]
    for letter in DIFFICULTY_LEVELS:
        lines.append(f"| {letter} | " + " | ".join(
            _cell(objects[letter + digit]) if letter + digit in objects else "-" for digit in COMPLEXITY_LEVELS)
            + " |")

    lines += ["", "Per object (steps to B of each seed; - not learned within the cap):", "",
              "| object | " + " | ".join(f"seed {seed}" for seed in seeds) + " | median |",
              "| --- |" + " ---: |" * (len(seeds) + 1)]
    by_key = {(goal.task, goal.seed): goal for goal in goals}
    for task in objects:
        cells = []
        for seed in seeds:
            goal = by_key.get((task, seed))
            cells.append("not run" if goal is None else "-" if goal.steps_to_b is None else str(goal.steps_to_b))
        lines.append(f"| {task} | " + " | ".join(cells) + f" | {_cell(objects[task])} |")

    lines += ["", f"{_EVERY_GOAL} {settings.eval_episodes}, step:score):", "",
              "| object | seed | scores | steps to B | s |", "| --- | ---: | --- | ---: | ---: |"]
    for goal in goals:
        lines.append(f"| {goal.task} | {goal.seed} | " + " ".join(f"{s}:{score}" for s, score in goal.curve)
                     + f" | {'-' if goal.steps_to_b is None else goal.steps_to_b} | {goal.wall_s:.0f} |")
    if against is not None:
        lines += against_lines(goals, against, settings)
    return "\n".join(lines) + "\n"


def cost_figure(goals: Sequence[TransferGoal], settings: TransferSettings, png: Path) -> Path:
    """The 7x7 heat map: rows A..G, columns 0..6, coloured by log median steps to B; not learned within the
    cap hatched, at the top of the scale; untested blank."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np
    from matplotlib.colors import LogNorm

    objects = object_medians(goals)
    grid = np.full((len(DIFFICULTY_LEVELS), len(COMPLEXITY_LEVELS)), np.nan)
    for task, steps in objects.items():
        grid[grid_coordinates(task)] = steps
    low, high = settings.eval_interval, max(settings.step_budget, 2 * settings.eval_interval)
    shown = np.clip(np.where(np.isinf(grid), high, grid), low, high)  # 0 (passed at once) at the bottom
    cmap = matplotlib.colormaps["RdYlGn_r"].with_extremes(bad="white")
    figure, axis = plt.subplots(figsize=(6.4, 5.6), layout="constrained")
    image = axis.imshow(np.ma.masked_invalid(shown), cmap=cmap, norm=LogNorm(vmin=low, vmax=high))
    for (row, column), steps in np.ndenumerate(grid):
        task = DIFFICULTY_LEVELS[row] + COMPLEXITY_LEVELS[column]
        if np.isnan(steps):
            axis.text(column, row, task, ha="center", va="center", fontsize=7, color="#999999")
            continue
        if np.isinf(steps):
            axis.add_patch(plt.Rectangle((column - 0.5, row - 0.5), 1, 1, fill=False, hatch="xx",
                                         edgecolor="black", linewidth=0))
        label = f"> {_short(settings.step_budget)}" if np.isinf(steps) else _short(steps)
        axis.text(column, row, f"{task}\n{label}", ha="center", va="center", fontsize=7.5,
                  bbox=dict(boxstyle="round,pad=0.15", facecolor="white", alpha=0.7, linewidth=0))
    axis.set_xticks(range(len(COMPLEXITY_LEVELS)), list(COMPLEXITY_LEVELS))
    axis.set_yticks(range(len(DIFFICULTY_LEVELS)), list(DIFFICULTY_LEVELS))
    axis.set_xlabel("shape complexity (digit)")
    axis.set_ylabel("grasp difficulty (letter)")
    rho, count = letter_spearman(goals)
    seeds = len({goal.seed for goal in goals})
    axis.set_title(f"Steps to B from the prior, median of {seeds} seed{'s' if seeds != 1 else ''}; "
                   f"cap {_short(settings.step_budget)}\n"
                   + ("Spearman(letter, steps): n/a" if math.isnan(rho) else
                      f"Spearman(letter, steps) = {rho:+.2f} over {count} objects"), fontsize=9)
    figure.colorbar(image, ax=axis, shrink=0.8, label="steps to B (log; hatched: not learned within the cap)")
    png.parent.mkdir(parents=True, exist_ok=True)
    figure.savefig(png, dpi=110)
    plt.close(figure)
    return png


def _short(steps: float) -> str:
    """1500 -> '1.5k', 16000 -> '16k', 250 -> '250'."""
    return f"{steps / 1000:.3g}k" if steps >= 1000 else f"{steps:.0f}"


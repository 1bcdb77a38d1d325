"""``glocal-ros bench stones``: does a policy that learned an easier object shorten the way to a hard one?

A curriculum has something to exploit only when it does (issue 31, item 6). For each target object T
(default: row G) and seed, a chain of two seeded Train goals in one worker
(``glocal_app.benches.transfer.run_chain``): the first from the prior on the stepping stone S, the
object of the row above in T's column, the second from the policy the first stored on T. Both are the
cost map's goals (``glocal_app.benches.cost``: stopped at their first score above B, capped, scored
every interval), so the second is compared with the cost map's goal from the prior on T: same seed,
same evaluation episodes, only the start differs. A stone that the prior does not bring above B within
the cap ends its chain: there is no policy that learned it.

The bench runs in a cost map's work directory and with its settings: the goals from the prior on T
(and on S) are the map's own, run first where the map lacks them and appended to its ``goals.jsonl``;
the chains go to ``stones.jsonl`` beside it, one line each as it finishes, so the same command
resumes. Per target and seed the report gives steps to B from the prior, from the stone and their
ratio (from the stone / from the prior): below 1, the stone helped. Not learned within the cap counts
as above it, as in the map; a ratio with a goal not learned, or with 0 from the prior, is given as
words, not a number.
"""

from __future__ import annotations

import math
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import dataclass
from multiprocessing import get_context
from pathlib import Path
from typing import Callable, Sequence

from glocal_app.benches.cost import GoalLog, check_cost, run_cost_map, run_key, work_lock
from glocal_app.benches.transfer import INITIAL_POLICY, PROFILE_RECIPE, TransferGoal, TransferSettings, run_chain
from glocal_ros.paths import object_fingerprint
from glocal_ros.tasks import DIFFICULTY_LEVELS, grid_coordinates, sorted_tasks
from learner_node.profiles import DEFAULT_PROFILE

STONES_FILE = "stones.jsonl"


def stone_of(task: str) -> str:
    """The stepping stone of ``task``: the object of the row above in its column."""
    row, column = grid_coordinates(task)
    if row == 0:
        raise ValueError(f"{task} is in row A: no row above it holds a stepping stone")
    return DIFFICULTY_LEVELS[row - 1] + task[1]


@dataclass(frozen=True)
class StoneChain:
    """The chain for one target and seed: the goal from the prior on the stone, then (when the stone was
    learned) the goal from its policy on the target."""

    task: str
    seed: int
    stone: TransferGoal
    target: TransferGoal | None  # None: the stone was not learned within the cap


def _steps(goal: TransferGoal | None) -> float:
    return math.inf if goal is None or goal.steps_to_b is None else float(goal.steps_to_b)


def ratio_text(from_stone: float, from_prior: float) -> str:
    """Steps to B from the stone over steps from the prior, as a number where both are finite and the
    prior's is not 0; words otherwise."""
    if math.isinf(from_stone) and math.isinf(from_prior):
        return "neither learned"
    if math.isinf(from_prior):
        return "learned only from the stone"
    if math.isinf(from_stone):
        return "learned only from the prior"
    if from_prior == 0:
        return "both 0" if from_stone == 0 else "the prior passes at once"
    return f"{from_stone / from_prior:.2f}"


class StoneLog(GoalLog):
    """``stones.jsonl``: one JSON line per finished chain (``GoalLog``'s rules for torn lines)."""

    FILE = STONES_FILE
    FIELDS = frozenset({"task", "seed", "stone", "stone_curve", "curve", "key", "object", "stone_object"})
    WHAT = "a chain of bench stones"


def chain_record(chain: StoneChain, key: dict, fingerprints: dict[str, str]) -> dict:
    return {"task": chain.task, "seed": chain.seed, "stone": chain.stone.task,
            "stone_curve": [list(point) for point in chain.stone.curve],
            "curve": None if chain.target is None else [list(point) for point in chain.target.curve],
            "wall_s": round(chain.stone.wall_s + (chain.target.wall_s if chain.target else 0.0), 2),
            "key": key, "object": fingerprints[chain.task], "stone_object": fingerprints[chain.stone.task]}


def finished_chains(work_dir: Path, settings: TransferSettings, profile: str = DEFAULT_PROFILE,
                    prior_store: Path | None = None) -> dict[tuple[str, int], StoneChain]:
    """The chains ``work_dir`` holds, by (target, seed); ``ValueError`` when any is of other settings or of
    objects that have changed since."""
    log = StoneLog(work_dir)
    key = run_key(settings, profile, prior_store)
    chains: dict[tuple[str, int], StoneChain] = {}
    fingerprints: dict[str, str] = {}

    def fingerprint(task: str) -> str:
        if task not in fingerprints:
            fingerprints[task] = object_fingerprint(task, settings.objects_dir)
        return fingerprints[task]

    for number, record in enumerate(log.records(), 1):
        if record["key"] != key:
            raise ValueError(f"{log.path}, line {number}: a chain of other settings than the map's: choose "
                             "another --work-dir")
        task, stone, seed = record["task"], record["stone"], int(record["seed"])
        if (record["object"], record["stone_object"]) != (fingerprint(task), fingerprint(stone)):
            raise ValueError(f"the objects of {stone} or {task} have changed since their chain in {log.path} "
                             "ran: choose another --work-dir")

        def goal(curve, on: str, start: str) -> TransferGoal:
            return TransferGoal(PROFILE_RECIPE, on, seed, tuple(tuple(point) for point in curve),
                                settings.eval_episodes, settings.threshold, 0.0, start, profile)

        chains[(task, seed)] = StoneChain(
            task, seed, goal(record["stone_curve"], stone, INITIAL_POLICY),
            None if record["curve"] is None else goal(record["curve"], task, f"learned {stone}"))
    return chains


def _run_chain(task: str, seed: int, settings: TransferSettings, prior_store: Path | None,
               profile: str) -> StoneChain:
    goals = run_chain(PROFILE_RECIPE, INITIAL_POLICY, [stone_of(task), task], seed, settings, prior_store, profile)
    return StoneChain(task, seed, goals[0], goals[1] if len(goals) > 1 else None)


def run_stones(targets: Sequence[str], seeds: Sequence[int], settings: TransferSettings, work_dir: Path,
               jobs: int, profile: str = DEFAULT_PROFILE, prior_store: Path | None = None,
               log: Callable[[str], None] = print) -> tuple[dict[tuple[str, int], TransferGoal], list[StoneChain]]:
    """The map's goals from the prior on the targets and their stones (run where missing), then every chain
    ``work_dir`` lacks, ``jobs`` at a time; returns both, in grid order."""
    stones = [stone_of(task) for task in targets]
    check_cost(sorted_tasks({*targets, *stones}), seeds, settings, jobs, profile, prior_store)
    finished_chains(work_dir, settings, profile, prior_store)  # refuse other settings before running anything
    direct = run_cost_map(sorted_tasks({*targets, *stones}), seeds, settings, work_dir, jobs, profile, log,
                          prior_store)
    with work_lock(work_dir):
        chain_log = StoneLog(work_dir)
        chain_log.drop_torn_line()
        done = finished_chains(work_dir, settings, profile, prior_store)
        pending = [(task, seed) for task in sorted_tasks(targets) for seed in seeds if (task, seed) not in done]
        log(f"bench stones: {len(done)} chains finished before (in {chain_log.path}), {len(pending)} to run")
        if pending:
            key = run_key(settings, profile, prior_store)
            fingerprints = {task: object_fingerprint(task, settings.objects_dir) for task in {*targets, *stones}}
            # Spawned workers: pybullet, torch and JAX do not survive a fork of a process that uses them.
            with ProcessPoolExecutor(max_workers=min(jobs, len(pending)), mp_context=get_context("spawn")) as pool:
                futures = [pool.submit(_run_chain, task, seed, settings, prior_store, profile)
                           for task, seed in pending]
                for future in as_completed(futures):
                    chain = future.result()
                    chain_log.append(chain_record(chain, key, fingerprints))
                    done[(chain.task, chain.seed)] = chain
                    log(f"[{len(done)}] {chain_line(chain)}")
    by_key = {(goal.task, goal.seed): goal for goal in direct}
    return by_key, [done[(task, seed)] for task in sorted_tasks(targets) for seed in seeds]


def chain_line(chain: StoneChain) -> str:
    stone = "-" if chain.stone.steps_to_b is None else chain.stone.steps_to_b
    target = ("stone not learned" if chain.target is None else
              "-" if chain.target.steps_to_b is None else chain.target.steps_to_b)
    return f"{chain.task} seed {chain.seed}: stone {chain.stone.task} steps to B {stone}, then {chain.task} {target}"


def stones_report(direct: dict[tuple[str, int], TransferGoal], chains: Sequence[StoneChain], command: str,
                  settings: TransferSettings, work_dir: Path) -> str:
    """Per target and seed: steps to B from the prior, the stone's own, from the stone, and their ratio."""
    lines = [
        "# bench stones: steps to B from the policy that learned the object of the row above",
        "",
        f"Command: `{command}`  ",
        f"Goals of the cost map in `{work_dir}` (its settings: cap {settings.step_budget:,} training steps, an "
        f"evaluation every {settings.eval_interval:,} over {settings.eval_episodes} episodes, B = "
        f"{settings.threshold:g}, {settings.num_envs} envs"
        + (f", objects of `{settings.objects_dir}`" if settings.objects_dir else "")
        + "). From the stone: a goal on the target from the policy that the goal from the prior on the stone "
        "stored, with the seed, and so the evaluation episodes, of the goal from the prior. Ratio: from the "
        "stone / from the prior; below 1 the stone helped. A stone the prior passes at step 0 is stored "
        "unchanged, so its chain repeats the goal from the prior. - : not learned within the cap.",
        "",
        "| target | seed | from the prior | stone | the stone from the prior | from the stone | ratio |",
        "| --- | ---: | ---: | --- | ---: | ---: | --- |",
    ]

    def cell(value: float) -> str:
        return "-" if math.isinf(value) else f"{value:,.0f}"

    for chain in chains:
        from_prior = _steps(direct.get((chain.task, chain.seed)))
        from_stone = _steps(chain.target)
        if chain.target is None:
            ratio = "-"
        elif chain.stone.steps_to_b == 0:  # stored unchanged: the chain's goal repeats the one from the prior
            ratio = "the stone's policy is the prior"
        else:
            ratio = ratio_text(from_stone, from_prior)
        lines.append(f"| {chain.task} | {chain.seed} | {cell(from_prior)} | {chain.stone.task} "
                     f"| {cell(_steps(chain.stone))} | "
                     + ("stone not learned" if chain.target is None else cell(from_stone)) + f" | {ratio} |")
    lines += ["", "Every chain (scores out of "
              f"{settings.eval_episodes}, step:score):", "", "| target | seed | stone's goal | target's goal |",
              "| --- | ---: | --- | --- |"]
    for chain in chains:
        lines.append(f"| {chain.task} | {chain.seed} | " + " ".join(f"{s}:{v}" for s, v in chain.stone.curve)
                     + " | " + ("-" if chain.target is None else
                                " ".join(f"{s}:{v}" for s, v in chain.target.curve)) + " |")
    return "\n".join(lines) + "\n"

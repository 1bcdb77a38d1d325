"""Runs as recorded: a run directory's bags -> :class:`RunData`, and statistics across seeds.

A run directory holds ``bag/`` and, when the run was interrupted and resumed,
``bag.1/``, ``bag.2/``...; the run is the union of their messages in time
order. Everything is derived from ``/glocal/curriculum_state`` (one
CurriculumState after every decision of the curriculum); ``/glocal/episodes``
is only counted. Both are found under whatever namespace the bag was
recorded in (``glocal_ros.recording.table_topic``).

Bags are read with ``rosbags``' AnyReader, which decodes with the message
definitions embedded in the bag: a bag recorded before a field was added to
a message still decodes, and the missing fields take their defaults here.
"""

from __future__ import annotations

import functools
import re
import sys
import warnings
from collections.abc import Iterable, Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from rosbags.highlevel import AnyReader, AnyReaderError
from rosbags.rosbag2 import Reader, ReaderError
from rosbags.serde import SerdeError
from rosbags.typesys.store import Typestore

from glocal_ros.curriculum.codes import (
    STATUS_FINISHED, STATUS_STARTING, STATUS_TRAINING_GLOBAL, STATUS_TRAINING_LOCAL, STRATEGY_NAMES,
)
from glocal_ros.recording import graph_typestore, table_topic
from glocal_ros.sim_contract import PHASE_EVAL
from glocal_ros.tasks import UnknownTaskError, sorted_tasks
from glocal_ros.topics import CURRICULUM_STATE, EPISODES, TopicSpec

CURRICULUM_STATE_TOPIC = CURRICULUM_STATE.name

#: The paper's strategies in the order tables and legends list them; others follow alphabetically.
STRATEGY_ORDER: tuple[str, ...] = STRATEGY_NAMES
#: The strategy every other one is t-tested against.
REFERENCE_STRATEGY = "glocal"

# Opening or decoding a damaged bag raises one of these; such a bag is skipped, not fatal.
_BAG_ERRORS = (AnyReaderError, ReaderError, SerdeError, OSError, KeyError, ValueError, AssertionError)
_BAG_DIR = re.compile(r"^bag(?:\.(\d+))?$")
_RUN_ID_SEED = re.compile(r"-seed(\d+)$")


@dataclass(frozen=True)
class CurriculumSnapshot:
    """The fields of one CurriculumState that the analysis uses (plain Python types)."""

    stamp_ns: int  # header stamp
    log_time_ns: int  # when the recorder received it; breaks ties of equal stamps
    run_id: str
    strategy: str
    seed: int | None  # None in bags recorded before CurriculumState had a seed
    status: int
    iteration: int
    total_steps: int
    step_budget: int
    evaluation_episodes: int  # -1: the state predates the field
    num_clusters: int
    chosen_cluster: int
    global_task: str
    local_tasks: tuple[str, ...]
    learned_tasks: tuple[str, ...]
    learned_policies: tuple[str, ...]
    learned_at_steps: tuple[int, ...]
    remaining_tasks: tuple[str, ...]
    milestone_interval: int
    milestone_steps: tuple[int, ...]
    milestone_learned: tuple[int, ...]

    @property
    def order_key(self) -> tuple[int, int]:
        return self.stamp_ns, self.log_time_ns

    @classmethod
    def from_message(cls, msg: object, log_time_ns: int) -> CurriculumSnapshot:
        def get(name: str, default):
            # Fields added to CurriculumState later are absent from older bags' definitions.
            return getattr(msg, name, default)

        stamp = msg.header.stamp
        seed = get("seed", None)
        return cls(
            stamp_ns=int(stamp.sec) * 1_000_000_000 + int(stamp.nanosec),
            log_time_ns=int(log_time_ns),
            run_id=str(get("run_id", "")),
            strategy=str(get("strategy", "")),
            seed=None if seed is None else int(seed),
            status=int(get("status", STATUS_STARTING)),
            iteration=int(get("iteration", 0)),
            total_steps=int(get("total_steps", 0)),
            step_budget=int(get("step_budget", 0)),
            evaluation_episodes=int(get("evaluation_episodes", -1)),
            num_clusters=len(get("clusters", ())),
            chosen_cluster=int(get("chosen_cluster", 0)),
            global_task=str(get("global_task", "")),
            local_tasks=tuple(get("local_tasks", ())),
            learned_tasks=tuple(get("learned_tasks", ())),
            learned_policies=tuple(get("learned_policies", ())),
            learned_at_steps=tuple(int(s) for s in get("learned_at_steps", ())),
            remaining_tasks=tuple(get("remaining_tasks", ())),
            milestone_interval=int(get("milestone_interval", 0)),
            milestone_steps=tuple(int(s) for s in get("milestone_steps", ())),
            milestone_learned=tuple(int(n) for n in get("milestone_learned", ())),
        )


@dataclass
class EpisodeCounts:
    """EpisodeRecords of a run by phase; ``complete`` excludes interrupted episodes."""

    train: int = 0
    eval: int = 0
    complete: int = 0

    @property
    def total(self) -> int:
        return self.train + self.eval

    def __add__(self, other: EpisodeCounts) -> EpisodeCounts:
        return EpisodeCounts(self.train + other.train, self.eval + other.eval, self.complete + other.complete)


@dataclass(frozen=True)
class IterationRecord:
    """One GloCAL iteration: its global task, local tasks and which of them were learned in it."""

    iteration: int
    start_steps: int  # total_steps when the iteration's training began
    global_task: str
    local_tasks: tuple[str, ...]
    learned: frozenset[str]
    num_clusters: int
    chosen_cluster: int

    @property
    def tasks(self) -> tuple[str, ...]:
        return ((self.global_task,) if self.global_task else ()) + self.local_tasks


@dataclass(frozen=True)
class BagContents:
    """What one bag contributes to a run."""

    path: Path
    states: tuple[CurriculumSnapshot, ...]
    episodes: EpisodeCounts | None  # None when episodes were not counted
    message_counts: dict[str, int]


@dataclass
class RunData:
    """One run (one strategy, one seed), merged from all of its bags."""

    run_dir: Path
    states: list[CurriculumSnapshot]  # time order, duplicates (re-sent latched state) removed
    bags_read: list[Path] = field(default_factory=list)
    bags_skipped: list[tuple[Path, str]] = field(default_factory=list)  # (bag, why)
    episodes: EpisodeCounts | None = None
    message_counts: dict[str, int] = field(default_factory=dict)
    #: Wall-clock seconds the curriculum ran: per bag, its first state to its last, summed over bags.
    curriculum_seconds: float = 0.0

    def __post_init__(self) -> None:
        if not self.states:
            raise ValueError(f"run {self.run_dir} has no curriculum state")

    # --- identity -----------------------------------------------------------------------------
    @property
    def final(self) -> CurriculumSnapshot:
        """The latest state (by header stamp, then log time)."""
        return self.states[-1]

    @property
    def run_id(self) -> str:
        return next((s.run_id for s in reversed(self.states) if s.run_id), "")

    @property
    def strategy(self) -> str:
        strategy = next((s.strategy for s in reversed(self.states) if s.strategy), "")
        if not strategy and (match := _RUN_ID_SEED.search(self.run_id)):
            strategy = self.run_id[: match.start()]
        return strategy or "unknown"

    @property
    def seed(self) -> int | None:
        if self.final.seed is not None:
            return self.final.seed
        match = _RUN_ID_SEED.search(self.run_id)
        return int(match.group(1)) if match else None

    @property
    def label(self) -> str:
        return f"{self.strategy} seed {'?' if self.seed is None else self.seed}"

    # --- outcome ------------------------------------------------------------------------------
    @property
    def total_steps(self) -> int:
        return max(s.total_steps for s in self.states)

    @property
    def step_budget(self) -> int:
        return self.final.step_budget

    @property
    def evaluation_episodes(self) -> int | None:
        """Evaluation episodes the curriculum ran (not charged to the budget); None when not published."""
        count = max(s.evaluation_episodes for s in self.states)
        return None if count < 0 else count

    @property
    def finished(self) -> bool:
        return self.final.status == STATUS_FINISHED

    @property
    def iterations(self) -> int:
        return self.final.iteration

    @property
    def learned_tasks(self) -> tuple[str, ...]:
        """In the order they were learned."""
        return self.final.learned_tasks

    @property
    def tasks(self) -> tuple[str, ...]:
        """Every task of the run (learned or remaining at any time), in grid order."""
        seen = {t for s in self.states for t in (*s.learned_tasks, *s.remaining_tasks)}
        try:
            return tuple(sorted_tasks(list(seen)))
        except UnknownTaskError:  # a task set outside the grid still gets a report
            return tuple(sorted(seen))

    def learned_at_steps(self) -> list[int]:
        """total_steps at which each learned task was learned, ascending.

        From the final state's ``learned_at_steps``; bags from before that field
        existed fall back to the steps of the first state showing each new count.
        """
        final = self.final
        if len(final.learned_at_steps) == len(final.learned_tasks):
            return sorted(final.learned_at_steps)
        steps: list[int] = []
        for state in self.states:
            while len(steps) < len(state.learned_tasks):
                steps.append(state.total_steps)
        return steps[: len(final.learned_tasks)]

    def learned_count_at(self, steps: int) -> int:
        """Tasks learned by the time ``steps`` training steps were spent."""
        return sum(1 for s in self.learned_at_steps() if s <= steps)

    def learned_curve(self) -> tuple[np.ndarray, np.ndarray]:
        """The learned-count step function (draw with ``steps-post``), from 0 to the final total_steps.

        A finished run's count is final: its curve goes on to the step budget, as its milestones do
        (``glocal_ros.curriculum.run``), so that a run that learned everything early is not left out of
        the mean after it ended.
        """
        at = self.learned_at_steps()
        end = max(self.total_steps, at[-1] if at else 0, self.step_budget if self.finished else 0)
        xs = np.array([0, *at, end], dtype=np.int64)
        ys = np.array([self.learned_count_at(0), *[self.learned_count_at(s) for s in at], len(at)], dtype=np.int64)
        return xs, ys

    def milestones(self) -> list[tuple[int, int]]:
        """``(k * milestone_interval, learned tasks then)`` for every milestone reached.

        As published when the state has them; otherwise derived from
        learned_at_steps up to the final total_steps.
        """
        final = self.final
        if final.milestone_steps and len(final.milestone_steps) == len(final.milestone_learned):
            return list(zip(final.milestone_steps, final.milestone_learned))
        interval = final.milestone_interval
        if interval <= 0:
            return []
        return [(k * interval, self.learned_count_at(k * interval)) for k in range(1, self.total_steps // interval + 1)]

    def iteration_timeline(self) -> list[IterationRecord]:
        """GloCAL's iterations, from the states published while training global and local tasks.

        A task that is not learned goes back into the pool and may come up in a
        later iteration, so a learned task counts as learned in the last
        iteration it appears in.
        """
        by_iteration: dict[int, list[CurriculumSnapshot]] = {}
        for state in self.states:
            if state.status in (STATUS_TRAINING_GLOBAL, STATUS_TRAINING_LOCAL) and state.iteration > 0:
                by_iteration.setdefault(state.iteration, []).append(state)
        last_seen: dict[str, int] = {}
        for iteration in sorted(by_iteration):
            for state in by_iteration[iteration]:
                for task in (state.global_task, *state.local_tasks):
                    if task:
                        last_seen[task] = iteration
        learned = set(self.learned_tasks)
        records = []
        for iteration in sorted(by_iteration):
            states = by_iteration[iteration]
            latest = states[-1]
            global_task = next((s.global_task for s in reversed(states) if s.global_task), "")
            local_tasks = tuple(t for t in latest.local_tasks if t != global_task)
            records.append(IterationRecord(
                iteration=iteration,
                start_steps=min(s.total_steps for s in states),
                global_task=global_task,
                local_tasks=local_tasks,
                learned=frozenset(t for t in (global_task, *local_tasks)
                                  if t in learned and last_seen.get(t) == iteration),
                num_clusters=latest.num_clusters,
                chosen_cluster=latest.chosen_cluster,
            ))
        return records


# --- reading ----------------------------------------------------------------------------------

def warn(message: str) -> None:
    """A problem with the input that the report works around: printed, not raised."""
    print(f"warning: {message}", file=sys.stderr, flush=True)


@functools.lru_cache(maxsize=1)
def _fallback_typestore() -> Typestore:
    return graph_typestore()


def _bag_index(path: Path) -> int:
    match = _BAG_DIR.match(path.name)
    return int(match.group(1) or 0) if match else 0


def find_bags(run_dir: Path) -> list[Path]:
    """``bag/``, ``bag.1/``, ``bag.2/``... of ``run_dir`` in resume order; ``run_dir`` itself if it is a bag."""
    run_dir = Path(run_dir)
    bags = sorted((p for p in run_dir.iterdir() if p.is_dir() and _BAG_DIR.match(p.name)), key=_bag_index)
    if not bags and ((run_dir / "metadata.yaml").is_file() or any(run_dir.glob("*.mcap"))):
        return [run_dir]
    return bags


def _messages(bag: Path, topics: Sequence[TopicSpec], counts: dict[str, int]) -> Iterator[tuple[str, int, object]]:
    """``(topic, log time, message)`` of the table's ``topics`` under any namespace, decoded with the bag's own
    definitions; ``topic`` is the table's name (``/glocal/episodes`` for ``/robot1/glocal/episodes``).

    Fills ``counts`` with the messages per topic of the whole bag (from its
    metadata) on opening. Falls back to glocal_interfaces' current definitions
    when rosbags cannot open the bag with the embedded ones (none embedded, or
    a hash that does not match them); when the fallback cannot open it either,
    the first error is the one raised. Errors while reading are not caught.
    """
    reader, decode = _open_for_decoding(bag)
    try:
        counts.update({c.topic: c.msgcount for c in reader.connections})
        specs = {c.topic: spec for c in reader.connections if (spec := table_topic(c.topic, topics)) is not None}
        connections = [c for c in reader.connections if c.topic in specs]
        if not connections:  # an empty selection would mean every topic to rosbags
            return
        for connection, log_time, raw in reader.messages(connections=connections):
            yield specs[connection.topic].name, log_time, decode(raw, connection.msgtype)
    finally:
        reader.close()


def _open_for_decoding(bag: Path):
    """An open reader of ``bag`` and its ``decode(raw, msgtype)``: the embedded definitions, else the current."""
    reader = AnyReader([bag], default_typestore=_fallback_typestore())
    try:
        reader.open()
        return reader, reader.deserialize
    except AnyReaderError as first_error:
        try:
            fallback = Reader(bag)
            fallback.open()
        except Exception as error:  # noqa: BLE001 - the first error says what is wrong with the bag
            raise first_error from error
        return fallback, _fallback_typestore().deserialize_cdr


def read_bag(bag: Path, count_episodes: bool = True) -> BagContents:
    """The curriculum states (and episode counts) of one bag; raises on a bag that cannot be read."""
    bag = Path(bag)
    if not (bag / "metadata.yaml").is_file():
        # The recorder was killed before closing the bag; `glocal-ros` has a separate repair command.
        raise ReaderError(f"no metadata.yaml (recorder killed?): `glocal-ros bag repair {bag}` recovers it")
    topics = [CURRICULUM_STATE] + ([EPISODES] if count_episodes else [])
    states: list[CurriculumSnapshot] = []
    episodes = EpisodeCounts()
    message_counts: dict[str, int] = {}
    for topic, log_time, msg in _messages(bag, topics, message_counts):
        if topic == CURRICULUM_STATE_TOPIC:
            states.append(CurriculumSnapshot.from_message(msg, log_time))
        else:
            if msg.phase == PHASE_EVAL:
                episodes.eval += 1
            else:
                episodes.train += 1
            episodes.complete += not msg.interrupted
    return BagContents(bag, tuple(states), episodes if count_episodes else None, message_counts)


def _dedupe(states: Iterable[CurriculumSnapshot]) -> list[CurriculumSnapshot]:
    # A resumed recorder receives the latched last state again: same stamp, same content.
    unique: dict[tuple, CurriculumSnapshot] = {}
    for state in sorted(states, key=lambda s: s.order_key):
        unique.setdefault((state.stamp_ns, state.status, state.iteration, state.total_steps,
                           state.learned_tasks), state)
    return list(unique.values())


def read_run(run_dir: Path, count_episodes: bool = True) -> RunData | None:
    """All bags of ``run_dir`` merged into one run; None (with a warning) when no bag has a state.

    A bag that cannot be read (e.g. no metadata.yaml because the recorder was
    killed) is skipped with a warning and listed in ``bags_skipped``.
    """
    run_dir = Path(run_dir)
    if not run_dir.is_dir():
        warn(f"{run_dir}: not a directory, skipped")
        return None
    bags = find_bags(run_dir)
    if not bags:
        warn(f"{run_dir}: no bag/ directory, skipped")
        return None
    contents: list[BagContents] = []
    skipped: list[tuple[Path, str]] = []
    for bag in bags:
        try:
            contents.append(read_bag(bag, count_episodes))
        except _BAG_ERRORS as error:
            reason = f"{type(error).__name__}: {error}"
            warn(f"skipping bag {bag}: {reason}")
            skipped.append((bag, reason))
    states = _dedupe(s for c in contents for s in c.states)
    if not states:
        warn(f"{run_dir}: no {CURRICULUM_STATE_TOPIC} message in {len(contents)} readable bag(s), skipped")
        return None
    message_counts: dict[str, int] = {}
    for c in contents:
        for topic, count in c.message_counts.items():
            message_counts[topic] = message_counts.get(topic, 0) + count
    episodes = None
    if count_episodes:
        episodes = sum((c.episodes for c in contents if c.episodes is not None), EpisodeCounts())
    seconds = sum((max(s.log_time_ns for s in c.states) - min(s.log_time_ns for s in c.states)) / 1e9
                  for c in contents if c.states)
    return RunData(run_dir, states, [c.path for c in contents], skipped, episodes, message_counts, seconds)


def read_runs(run_dirs: Iterable[Path], count_episodes: bool = True) -> list[RunData]:
    """The readable runs among ``run_dirs``, sorted by strategy (paper order) and seed."""
    runs = [run for d in run_dirs if (run := read_run(Path(d), count_episodes)) is not None]
    seen: dict[tuple[str, int | None], Path] = {}
    for run in runs:
        key = (run.strategy, run.seed)
        if key in seen:
            warn(f"{run.run_dir} and {seen[key]} are both {run.label}: both are counted")
        seen.setdefault(key, run.run_dir)
    return sorted(runs, key=lambda r: (strategy_sort_key(r.strategy), -1 if r.seed is None else r.seed, str(r.run_dir)))


# --- across seeds -----------------------------------------------------------------------------

def strategy_sort_key(strategy: str) -> tuple[int, str]:
    return (STRATEGY_ORDER.index(strategy) if strategy in STRATEGY_ORDER else len(STRATEGY_ORDER), strategy)


def is_glocal_family(strategy: str) -> bool:
    """GloCAL and its ablations: the strategies with iterations of global and local tasks."""
    return strategy.startswith("glocal")


def group_by_strategy(runs: Iterable[RunData]) -> dict[str, list[RunData]]:
    """Runs per strategy, strategies in paper order, runs by seed."""
    groups: dict[str, list[RunData]] = {}
    for run in sorted(runs, key=lambda r: (strategy_sort_key(r.strategy), -1 if r.seed is None else r.seed)):
        groups.setdefault(run.strategy, []).append(run)
    return groups


def welch_p_value(a: Sequence[float], b: Sequence[float]) -> float | None:
    """Two-sided p of Welch's t-test (unequal variances); None when a group has < 2 values or p is undefined."""
    if len(a) < 2 or len(b) < 2:
        return None
    from scipy.stats import ttest_ind  # scipy is slow to import: only when a test is due

    with warnings.catch_warnings(), np.errstate(all="ignore"):
        # Two constant groups give a zero variance: scipy warns and answers 0 or NaN.
        warnings.simplefilter("ignore", RuntimeWarning)
        p = float(ttest_ind(np.asarray(a, float), np.asarray(b, float), equal_var=False).pvalue)
    return None if np.isnan(p) else p


@dataclass
class MilestoneTable:
    """Learned tasks at each milestone per strategy (one value per seed that reached it), and p vs the reference."""

    steps: list[int]
    values: dict[str, dict[int, list[int]]]  # strategy -> milestone step -> learned per run
    p_values: dict[str, dict[int, float | None]]  # strategy (not the reference) -> step -> p
    reference: str | None  # None when the reference strategy has no runs, or is the only strategy

    def stats(self, strategy: str, step: int) -> tuple[float, float, int] | None:
        """(mean, sample std, n) or None when no run of ``strategy`` reached ``step``."""
        values = self.values.get(strategy, {}).get(step, [])
        if not values:
            return None
        std = float(np.std(values, ddof=1)) if len(values) > 1 else 0.0
        return float(np.mean(values)), std, len(values)


def milestone_table(groups: dict[str, list[RunData]], reference: str = REFERENCE_STRATEGY) -> MilestoneTable:
    values: dict[str, dict[int, list[int]]] = {}
    for strategy, runs in groups.items():
        per_step: dict[int, list[int]] = {}
        for run in runs:
            for step, learned in run.milestones():
                per_step.setdefault(step, []).append(learned)
        values[strategy] = per_step
    steps = sorted({step for per_step in values.values() for step in per_step})
    has_reference = reference in groups and len(groups) > 1
    p_values = {
        strategy: {step: welch_p_value(values[reference].get(step, []), per_step.get(step, [])) for step in steps}
        for strategy, per_step in values.items() if has_reference and strategy != reference
    }
    return MilestoneTable(steps, values, p_values, reference if has_reference else None)


def learned_curve_band(runs: Sequence[RunData]) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """``(steps, mean, std, min, max)`` of the learned count over ``runs`` (a steps-post step function).

    At each step only the runs that had got that far count, so a shorter run
    does not drag the mean down after it ended.
    """
    curves = [run.learned_curve() for run in runs]
    grid = np.unique(np.concatenate([xs for xs, _ in curves]))
    table = np.full((len(curves), len(grid)), np.nan)
    for row, (xs, ys) in enumerate(curves):
        index = np.searchsorted(xs, grid, side="right") - 1  # the step function's value at each grid point
        table[row] = np.where(grid <= xs[-1], ys[np.clip(index, 0, len(ys) - 1)], np.nan)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # all-NaN columns cannot occur, but keep numpy quiet
        return (grid, np.nanmean(table, axis=0), np.nanstd(table, axis=0),
                np.nanmin(table, axis=0), np.nanmax(table, axis=0))


def format_steps(steps: int) -> str:
    """1000000 -> '1M', 250000 -> '250k', 1500000 -> '1.5M'."""
    for unit, size in (("M", 1_000_000), ("k", 1_000)):
        if steps >= size:
            return f"{steps / size:.3g}{unit}"
    return str(steps)

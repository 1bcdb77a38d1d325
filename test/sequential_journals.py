"""Journals of sequential runs against the learner double, and the references the code before the one
scheduler wrote.

``test_curriculum.test_sequential_journals_are_unchanged`` runs these again and compares them, line by line
and less each line's ``key`` and ``learner`` (which the old code did not write), with the references in
``test/data/sequential-journals`` (written by ``python test/sequential_journals.py`` from the sequential code
before parallel locals, kept since): ``parallel_locals: false`` must keep every call, seed and answer of the
runs written before. ``python test/sequential_journals.py`` writes today's journals to a temporary
directory and says whether each is its reference's.
"""

from __future__ import annotations

import json
import sys
import tempfile
from pathlib import Path

sys.path.insert(0, str(Path(__file__).parent))

from glocal_ros.curriculum.journal import CallJournal  # noqa: E402
from glocal_ros.curriculum.run import Run, RunConfig  # noqa: E402
from glocal_ros.curriculum.strategies import run_strategy  # noqa: E402
from learner_double import SimulatedLearner  # noqa: E402

REFERENCES = Path(__file__).parent / "data" / "sequential-journals"
TASKS = ("A0", "A1", "A2", "B0", "B1", "C0", "C3", "D2", "E5", "G6")
SETTINGS = dict(step_budget=60_000, task_step_budget=8_000, eval_interval=2_000, milestone_interval=10_000,
                baseline_eval_interval=5_000, baseline_chunk_episodes=20, eval_episodes=100, threshold=75,
                seed=3)
STRATEGIES = ("glocal", "glocal_random_cluster", "glocal_no_global", "random")


def write_journal(strategy: str, path: Path, learner: SimulatedLearner | None = None) -> None:
    config = RunConfig(strategy, TASKS, **SETTINGS)
    journal = CallJournal(path, config.journal_settings())
    run_strategy(Run(config, learner or SimulatedLearner(seed=1, lockstep_envs=2), journal=journal))


def without_keys(path: Path) -> list[dict]:
    """The journal's lines, less what the references lack: each answer's key and learner."""
    lines = [json.loads(line) for line in path.read_text().splitlines()]
    return [{name: value for name, value in line.items() if name not in ("key", "learner")} for line in lines]


if __name__ == "__main__":
    today = Path(tempfile.mkdtemp(prefix="sequential-journals-"))
    for name in STRATEGIES:
        target = today / f"{name}.jsonl"
        write_journal(name, target)
        same = without_keys(target) == without_keys(REFERENCES / f"{name}.jsonl")
        print(target, len(target.read_text().splitlines()), "lines,", "the reference's" if same else "NOT the reference's")

"""Journals of sequential runs against the learner double, as the code before parallel locals wrote them.

``test_curriculum.test_sequential_journals_are_unchanged`` runs these again and compares them byte for
byte with the references in ``test/data/sequential-journals`` (written by ``python test/sequential_journals.py``
from the sequential code, before the run became a scheduler): ``parallel_locals: false`` must keep every
call, seed and answer of today's runs.
"""

from __future__ import annotations

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).parent))

from glocal_ros.curriculum.journal import JournaledLearner  # noqa: E402
from glocal_ros.curriculum.run import Run, RunConfig  # noqa: E402
from glocal_ros.curriculum.strategies import run_strategy  # noqa: E402
from learner_double import SimulatedLearner  # noqa: E402

REFERENCES = Path(__file__).parent / "data" / "sequential-journals"
TASKS = ("A0", "A1", "A2", "B0", "B1", "C0", "C3", "D2", "E5", "G6")
SETTINGS = dict(step_budget=60_000, task_step_budget=8_000, eval_interval=2_000, milestone_interval=10_000,
                baseline_eval_interval=5_000, baseline_chunk_episodes=20, eval_episodes=100, threshold=75,
                seed=3)
STRATEGIES = ("glocal", "glocal_random_cluster", "glocal_no_global", "random")


def write_journal(strategy: str, path: Path) -> None:
    config = RunConfig(strategy, TASKS, **SETTINGS)
    journal = JournaledLearner(SimulatedLearner(seed=1, lockstep_envs=2), path, config.journal_settings(), seed=config.seed)
    run_strategy(Run(config, journal))


if __name__ == "__main__":
    REFERENCES.mkdir(parents=True, exist_ok=True)
    for name in STRATEGIES:
        target = REFERENCES / f"{name}.jsonl"
        target.unlink(missing_ok=True)
        write_journal(name, target)
        print(target, len(target.read_text().splitlines()), "lines")

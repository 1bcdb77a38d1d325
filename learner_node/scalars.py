"""A Train goal's training curves: TensorBoard event files, with a CSV of the same numbers beside them.

``GoalScalars(folder)`` holds one goal's curves in ``folder``
(``tensorboard_dir/<output policy>``: a run's learners write under
``RUN_DIR/tensorboard``, so ``tensorboard --logdir RUN_DIR/tensorboard`` lists
one run per goal). The x axis is the goal's training env steps. The tags are
stable-baselines3's, so that curves sit beside SB3's and rl-baselines3-zoo's:

- at every progress report (``Trainer.progress_interval_sec``, once a second):
  ``rollout/success_rate`` and ``rollout/ep_rew_mean`` (the goal's last
  finished training episodes, ``RECENT_EPISODES``), ``train/actor_loss``,
  ``train/critic_loss``, ``train/ent_coef`` (the last gradient step's),
  ``time/fps`` (env steps/s of the goal);
- at every evaluation of the goal: ``eval/successes`` (the paper's score)
  and ``eval/success_rate``, and the goal's instruments
  (``learner_node.instruments``): ``instruments/q_parent_action``,
  ``instruments/q_current_action``, ``instruments/action_distance``,
  ``instruments/policy_entropy``.

The numbers are those the learner publishes, as float32, the type of the
messages' fields: a report's are those of its ``glocal/training_progress``
message, an evaluation's those of its ``glocal/evaluations`` message (its
instruments: those of the ``glocal/training_progress`` message sent right
after it), so the bag and TensorBoard hold the same curves. A value the learner does not have
yet (a loss before the first gradient step, a return before the first
episode) is NaN in the message and left out here (an empty CSV cell).

``progress.csv`` has one row per write: ``goal_steps``, ``wall_time`` (Unix
seconds) and a column per tag. A goal resumed from its checkpoint appends: a
new event file and more CSV rows, so the steps between the checkpoint and
the interruption show twice, as they were trained twice.
"""

from __future__ import annotations

import csv
import math
import time
from pathlib import Path
from typing import Mapping

import numpy as np

#: Finished training episodes behind ``rollout/success_rate`` and ``rollout/ep_rew_mean``.
RECENT_EPISODES = 50
#: The tags of a progress report, in CSV column order.
PROGRESS_TAGS = ("rollout/success_rate", "rollout/ep_rew_mean", "train/actor_loss", "train/critic_loss",
                 "train/ent_coef", "time/fps")
#: The tags of an evaluation: its score, and the goal's instruments (``learner_node.instruments``).
EVALUATION_TAGS = ("eval/successes", "eval/success_rate", "instruments/q_parent_action",
                   "instruments/q_current_action", "instruments/action_distance", "instruments/policy_entropy")
CSV_FILE = "progress.csv"
CSV_COLUMNS = ("goal_steps", "wall_time", *PROGRESS_TAGS, *EVALUATION_TAGS)


def as_float32(value: float) -> float:
    """``value`` as a float32 message field holds it."""
    return float(np.float32(value))


class GoalScalars:
    """One goal's TensorBoard events and CSV in ``folder``; ``close`` when the goal ends."""

    def __init__(self, folder: Path):
        from torch.utils.tensorboard import SummaryWriter  # tensorboard's writer, without TensorFlow

        folder.mkdir(parents=True, exist_ok=True)
        self.folder = folder
        self._writer = SummaryWriter(log_dir=str(folder), flush_secs=10)
        path = folder / CSV_FILE
        new = not path.is_file() or path.stat().st_size == 0
        self._csv_file = path.open("a", newline="")
        self._csv = csv.writer(self._csv_file)
        if new:
            self._csv.writerow(CSV_COLUMNS)

    def write(self, steps: int, values: Mapping[str, float]) -> None:
        """``values`` (tag: value) at goal step ``steps``; NaN values are left out."""
        unknown = set(values) - set(CSV_COLUMNS[2:])
        if unknown:
            raise ValueError(f"no scalar tag {sorted(unknown)}: the tags are {', '.join(CSV_COLUMNS[2:])}")
        now = time.time()
        kept = {tag: as_float32(value) for tag, value in values.items() if not math.isnan(value)}
        for tag, value in kept.items():
            self._writer.add_scalar(tag, value, steps, walltime=now)
        self._csv.writerow([steps, f"{now:.3f}", *(repr(kept[tag]) if tag in kept else "" for tag in CSV_COLUMNS[2:])])
        self._csv_file.flush()  # a killed learner keeps its rows (the event file flushes every 10 s)

    def close(self) -> None:
        self._writer.close()
        self._csv_file.close()

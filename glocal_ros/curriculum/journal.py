"""Resuming a run: every answered learner call, journaled and replayed.

A strategy is plain code that calls its learner through a ``Run``, which
schedules every call (``glocal_ros.curriculum.run``). ``CallJournal``
appends each answered call (its key, the learner slot that answered, what
was asked, what came back) to a JSON-lines file, fsynced, before the
strategy sees the answer. A restarted run runs the same strategy code from
the start with the same seed: answers found in the journal are taken from
it (no learner is asked again), in the order they came, and each must
match a call the run has outstanding; after the last one the run goes on
live. So every strategy resumes exactly where it stopped, with no
per-strategy save code, and the calls in flight at the kill are simply
asked again (the learner resumes a re-sent Train goal from its checkpoint).

Each entry of a call also says what it cost: ``training_steps`` for a train
call, ``evaluation_episodes`` for an evaluate call (the budget counts only
the former, as the paper does; the sums of both compare strategies).

The file: a first line with the run's settings, then one answered call a
line: ``{"key", "learner", "call", "arguments", "answer", "cost"}``. Lines
of sequential runs written before calls had keys lack ``key`` and
``learner``; they still resume (``Run`` gives such a line to the one call
outstanding).
"""

from __future__ import annotations

import json
import os
from dataclasses import asdict
from pathlib import Path
from typing import Any, Callable

from glocal_ros.curriculum.learner import EpisodeSummary, TrainResult


class JournalMismatch(RuntimeError):
    """The journal was written by a run with other settings or other code."""


class CallJournal:
    """A run's answered calls by key, in the order they came (see the module doc)."""

    def __init__(self, path: Path, config: dict[str, Any], on_replayed: Callable[[int, int], None] | None = None):
        """``on_replayed(replayed, total)`` is called after each entry replayed: a replay re-runs the
        strategy from the start (ALP-GMM refits its sampler at every answer) and can take minutes."""
        self.path = Path(path)
        self._replay = _open_journal(self.path, config)
        self.replayed = 0
        self.on_replayed = on_replayed

    @property
    def replaying(self) -> bool:
        return self.replayed < len(self._replay)

    @property
    def to_replay(self) -> int:
        return len(self._replay)

    def next_entry(self) -> dict:
        entry = self._replay[self.replayed]
        self.replayed += 1
        if self.on_replayed is not None:
            self.on_replayed(self.replayed, len(self._replay))
        return entry

    def record(self, key: str, learner: int, name: str, arguments: dict, answer: Any, cost: dict[str, int]) -> None:
        _append(self.path, {"key": key, "learner": learner, "call": name, "arguments": arguments,
                            "answer": plain(answer), "cost": cost})


def _open_journal(path: Path, config: dict[str, Any]) -> list[dict]:
    """The answered calls of the journal at ``path`` (written by a run with ``config``); a new journal
    gets its first line."""
    if not path.is_file():
        path.parent.mkdir(parents=True, exist_ok=True)
        _append(path, {"config": plain(config)})
        return []
    lines = _read_entries(path)
    if lines and lines[0].get("config") != plain(config):
        raise JournalMismatch(
            f"{path} belongs to a run with other settings: {lines[0].get('config')}; "
            "use another state directory or the same settings"
        )
    return lines[1:]


def _append(path: Path, entry: dict) -> None:
    with open(path, "a") as stream:
        stream.write(json.dumps(entry) + "\n")
        stream.flush()
        os.fsync(stream.fileno())


def _read_entries(path: Path) -> list[dict]:
    """The journal's entries; a last line cut short by a kill is dropped from the file too."""
    lines = path.read_text().splitlines(keepends=True)
    entries = []
    for number, line in enumerate(lines):
        try:
            entries.append(json.loads(line))
        except json.JSONDecodeError:
            if number != len(lines) - 1:
                raise JournalMismatch(f"{path}, line {number + 1}: not JSON")
            path.write_text("".join(lines[:-1]))
    return entries


def plain(value: Any) -> Any:
    """JSON's view of ``value`` (dataclasses as dicts, tuples as lists), for comparison and storage."""
    if hasattr(value, "__dataclass_fields__"):
        value = asdict(value)
    return json.loads(json.dumps(value))


def train_result(answer: dict) -> TrainResult:
    episodes = tuple(EpisodeSummary(**episode) for episode in answer["episodes"])
    return TrainResult(answer["learned"], answer["score"], answer["steps_used"], episodes)


"""Resuming a run: every answered learner call, journaled and replayed.

A strategy is plain code that calls its learner. ``JournaledLearner``
appends each answered call (what was asked, what came back) to a JSON-lines
file, fsynced, before the strategy sees the answer. A restarted run runs the
same strategy code from the start with the same seed: calls found in the
journal are answered from it (the learner is not asked again), in order, and
each must match what was journaled; after the last one the run goes on live.
So every strategy resumes exactly where it stopped, with no per-strategy
save code, and the call in flight at the kill is simply asked again (the
learner resumes a re-sent Train goal from its checkpoint).

Each entry of a call also says what it cost: ``training_steps`` for a train
call, ``evaluation_episodes`` for an evaluate call (the budget counts only
the former, as the paper does; the sums of both compare strategies).

Given a run seed, the n-th call (evaluate or train) carries the seed
``derived_seed(seed, n)``: its episodes and SAC's sampling are then a
function of the run seed, the call and the policies it reads, not of what
the learner and the sim did before. So a run resumed after a kill, with its
nodes restarted or not, asks and hears the same as the uninterrupted run
from the kill on, down to every episode (limits: ``Trainer._seeded``).

Runs with outstanding calls (``parallel_locals``) journal by key instead:
``CallJournal`` holds each answer under the key that names its call (and
the learner slot that gave it), in the order the answers came, and
``Run`` replays them in that order (see ``glocal_ros.curriculum.run``).
Their seeds come from the run seed and the key, so that a call asks the
same whichever learner runs it and whenever. Both journals share the file
format: a first line with the settings, then one answered call a line.
"""

from __future__ import annotations

import json
import os
from dataclasses import asdict, replace
from pathlib import Path
from typing import Any, Callable, Sequence

from glocal_ros.curriculum.learner import EpisodeSummary, Learner, TrainGoal, TrainResult
from glocal_ros.seeds import derived_seed


class JournalMismatch(RuntimeError):
    """The journal was written by a run with other settings or other code."""


class JournaledLearner:
    """A ``Learner`` whose answers are journaled to ``path`` and replayed from it.

    With a ``seed``, every evaluate and train call gets a seed of its own (see
    the module doc); a call's own seed, when it has one, is kept.
    """

    def __init__(self, learner: Learner, path: Path, config: dict[str, Any], seed: int | None = None):
        self.learner = learner
        self.path = Path(path)
        self.seed = seed
        self._calls = 0  # calls of this run so far, replayed or live: the next call's index
        self._replay = _open_journal(self.path, config)
        self.replayed = 0

    @property
    def replaying(self) -> bool:
        """True while answers still come from the journal."""
        return self.replayed < len(self._replay)

    def evaluate(self, policy: str, tasks: Sequence[str], episodes: int, seed: int | None = None) -> dict[str, float]:
        seed = self._call_seed() if seed is None else seed
        arguments = {"policy": policy, "tasks": list(tasks), "episodes": episodes}
        if seed is not None:
            arguments["seed"] = seed
        return self._call("evaluate", arguments, lambda: self.learner.evaluate(policy, tasks, episodes, seed),
                          lambda answer: answer, lambda answer: {"evaluation_episodes": episodes * len(answer)})

    def train(self, request: TrainGoal) -> TrainResult:
        if request.seed is None:
            request = replace(request, seed=self._call_seed())
        return self._call("train", asdict(request), lambda: self.learner.train(request), _train_result,
                          lambda answer: {"training_steps": answer.steps_used})

    def copy(self, source: str, destination: str) -> None:
        self._call("copy", {"source": source, "destination": destination},
                   lambda: self.learner.copy(source, destination), lambda answer: None, lambda answer: {})

    def _call_seed(self) -> int | None:
        return None if self.seed is None else derived_seed(self.seed, self._calls)

    def _call(self, name: str, arguments: dict, ask: Callable[[], Any], load: Callable[[Any], Any],
              cost: Callable[[Any], dict[str, int]]):
        self._calls += 1
        arguments = _plain(arguments)
        if self.replaying:
            entry = self._replay[self.replayed]
            if (entry["call"], entry["arguments"]) != (name, arguments):
                raise JournalMismatch(f"{self.path}, entry {self.replayed + 1}: journaled {entry['call']} "
                                      f"{entry['arguments']}, but the run now asks {name} {arguments}")
            self.replayed += 1
            return load(entry["answer"])
        answer = ask()
        self._append({"call": name, "arguments": arguments, "answer": _plain(answer), "cost": cost(answer)})
        return answer

    def _append(self, entry: dict) -> None:
        _append(self.path, entry)


class CallJournal:
    """Answers of outstanding calls by key, in the order they came (see the module doc)."""

    def __init__(self, path: Path, config: dict[str, Any]):
        self.path = Path(path)
        self._replay = _open_journal(self.path, config)
        self.replayed = 0

    @property
    def replaying(self) -> bool:
        return self.replayed < len(self._replay)

    def next_entry(self) -> dict:
        entry = self._replay[self.replayed]
        if "key" not in entry:
            raise JournalMismatch(f"{self.path}, entry {self.replayed + 1}: no key (a sequential run's journal)")
        self.replayed += 1
        return entry

    def record(self, key: str, learner: int, name: str, arguments: dict, answer: Any, cost: dict[str, int]) -> None:
        _append(self.path, {"key": key, "learner": learner, "call": name, "arguments": arguments,
                            "answer": _plain(answer), "cost": cost})


def _open_journal(path: Path, config: dict[str, Any]) -> list[dict]:
    """The answered calls of the journal at ``path`` (written by a run with ``config``); a new journal
    gets its first line."""
    if not path.is_file():
        path.parent.mkdir(parents=True, exist_ok=True)
        _append(path, {"config": _plain(config)})
        return []
    lines = _read_entries(path)
    if lines and lines[0].get("config") != _plain(config):
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


def _plain(value: Any) -> Any:
    """JSON's view of ``value`` (dataclasses as dicts, tuples as lists), for comparison and storage."""
    if hasattr(value, "__dataclass_fields__"):
        value = asdict(value)
    return json.loads(json.dumps(value))


def _train_result(answer: dict) -> TrainResult:
    episodes = tuple(EpisodeSummary(**episode) for episode in answer["episodes"])
    return TrainResult(answer["learned"], answer["score"], answer["steps_used"], episodes)


plain = _plain
train_result = _train_result

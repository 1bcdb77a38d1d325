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
"""

from __future__ import annotations

import json
import os
from dataclasses import asdict
from pathlib import Path
from typing import Any, Callable, Sequence

from glocal_ros.curriculum.learner import EpisodeSummary, Learner, TrainRequest, TrainResult


class JournalMismatch(RuntimeError):
    """The journal was written by a run with other settings or other code."""


class JournaledLearner:
    """A ``Learner`` whose answers are journaled to ``path`` and replayed from it."""

    def __init__(self, learner: Learner, path: Path, config: dict[str, Any]):
        self.learner = learner
        self.path = Path(path)
        self._replay: list[dict] = []
        if self.path.is_file():
            lines = _read_entries(self.path)
            if lines and lines[0].get("config") != _plain(config):
                raise JournalMismatch(
                    f"{self.path} belongs to a run with other settings: {lines[0].get('config')}; "
                    "use another state directory or the same settings"
                )
            self._replay = lines[1:]
        else:
            self.path.parent.mkdir(parents=True, exist_ok=True)
            self._append({"config": _plain(config)})
        self.replayed = 0

    @property
    def replaying(self) -> bool:
        """True while answers still come from the journal."""
        return self.replayed < len(self._replay)

    def evaluate(self, policy: str, tasks: Sequence[str], episodes: int) -> dict[str, float]:
        return self._call("evaluate", {"policy": policy, "tasks": list(tasks), "episodes": episodes},
                          lambda: self.learner.evaluate(policy, tasks, episodes), lambda answer: answer)

    def train(self, request: TrainRequest) -> TrainResult:
        return self._call("train", asdict(request), lambda: self.learner.train(request), _train_result)

    def copy(self, source: str, destination: str) -> None:
        self._call("copy", {"source": source, "destination": destination},
                   lambda: self.learner.copy(source, destination), lambda answer: None)

    def _call(self, name: str, arguments: dict, ask: Callable[[], Any], load: Callable[[Any], Any]):
        arguments = _plain(arguments)
        if self.replaying:
            entry = self._replay[self.replayed]
            if (entry["call"], entry["arguments"]) != (name, arguments):
                raise JournalMismatch(f"{self.path}, entry {self.replayed + 1}: journaled {entry['call']} "
                                      f"{entry['arguments']}, but the run now asks {name} {arguments}")
            self.replayed += 1
            return load(entry["answer"])
        answer = ask()
        self._append({"call": name, "arguments": arguments, "answer": _plain(answer)})
        return answer

    def _append(self, entry: dict) -> None:
        with open(self.path, "a") as stream:
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

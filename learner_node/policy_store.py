"""Named policies on disk: stable-baselines3 models plus what they are.

Layout: ``<root>/<name>/policy.json`` (metadata, and which model file is
current) and ``<root>/<name>/model-<version>.zip``. A save writes the new
model file, then replaces policy.json, each through a temporary file and an
atomic rename, then deletes the old model file. A process killed at any
moment leaves policy.json naming a complete model: the old one or the new.

ROS-free; loading a model imports stable-baselines3 (and torch) lazily.
"""

from __future__ import annotations

import json
import re
from dataclasses import asdict, dataclass, field
from datetime import datetime, timezone
from pathlib import Path
from typing import Any

from glocal_ros.files import atomic_write

METADATA_FILE = "policy.json"
_NAME = re.compile(r"^[A-Za-z0-9_][A-Za-z0-9_.-]{0,127}$")
#: The only model file names a store writes: a policy.json naming anything else (``../x``, an
#: absolute path) would make a load read outside the store.
_MODEL_FILE = re.compile(r"^model-([1-9][0-9]{0,17})\.zip$")


class UnknownPolicyError(KeyError):
    def __str__(self) -> str:
        return f"unknown policy {self.args[0]!r}"


def _now() -> str:
    return datetime.now(timezone.utc).isoformat(timespec="seconds")


@dataclass
class PolicyRecord:
    name: str
    task: str = ""  # last trained on
    parent: str = ""  # trained from
    steps_trained: int = 0  # env steps, ancestors' included
    last_score: float = -1.0  # -1: never evaluated
    last_score_task: str = ""
    updated: str = field(default_factory=_now)
    model_file: str = ""
    extra: dict[str, Any] = field(default_factory=dict)


def check_name(name: str) -> str:
    if not _NAME.match(name):
        raise ValueError(f"invalid policy name {name!r}: letters, digits, '_', '.', '-', at most 128")
    return name


class PolicyStore:
    def __init__(self, root: Path):
        self.root = Path(root)

    def names(self) -> list[str]:
        if not self.root.is_dir():
            return []
        return sorted(p.name for p in self.root.iterdir() if (p / METADATA_FILE).is_file())

    def __contains__(self, name: str) -> bool:
        return (self.root / name / METADATA_FILE).is_file()

    def record(self, name: str) -> PolicyRecord:
        path = self.root / check_name(name) / METADATA_FILE
        if not path.is_file():
            raise UnknownPolicyError(name)
        record = PolicyRecord(**json.loads(path.read_text()))
        if record.model_file and not _MODEL_FILE.match(record.model_file):
            raise ValueError(f"{path}: model_file {record.model_file!r} is not a model file of this store "
                             f"(model-<N>.zip): refusing to load it")
        return record

    def model_path(self, name: str) -> Path:
        return self.root / name / self.record(name).model_file

    def load(self, name: str, **kwargs):
        """The stable-baselines3 SAC model of ``name``."""
        from stable_baselines3 import SAC

        return SAC.load(self.model_path(name), device="cpu", **kwargs)

    def save(self, model, record: PolicyRecord) -> PolicyRecord:
        """Store ``model`` (anything with SB3's ``save``) under ``record.name``, atomically."""
        return self._store(record, model.save)

    def add_copy(self, source: "PolicyStore", name: str, destination: str) -> PolicyRecord:
        """Store a copy of ``source``'s policy ``name`` as ``destination`` (model and metadata)."""
        record = source.record(name)
        model_bytes = source.model_path(name).read_bytes()
        record.name = destination
        return self._store(record, lambda stream: stream.write(model_bytes))

    def update(self, name: str, **changes) -> PolicyRecord:
        """Change metadata only (e.g. the last score)."""
        record = self.record(name)
        for key, value in changes.items():
            setattr(record, key, value)
        record.updated = _now()
        self._write_record(record)
        return record

    def _store(self, record: PolicyRecord, write_model) -> PolicyRecord:
        """A new model file written by ``write_model(stream)``, then the record naming it."""
        folder = self.root / check_name(record.name)
        folder.mkdir(parents=True, exist_ok=True)
        previous = self.record(record.name).model_file if record.name in self else ""
        version = int(_MODEL_FILE.match(previous).group(1)) + 1 if previous else 1
        record.model_file, record.updated = f"model-{version}.zip", _now()
        atomic_write(folder / record.model_file, write_model)
        self._write_record(record)
        if previous:
            (folder / previous).unlink(missing_ok=True)
        return record

    def _write_record(self, record: PolicyRecord) -> None:
        text = json.dumps(asdict(record), indent=2, sort_keys=True).encode() + b"\n"
        atomic_write(self.root / record.name / METADATA_FILE, lambda stream: stream.write(text))

"""Named policies on disk: SAC models (SBX's) plus what they are, all of it data.

Layout: ``<root>/<name>/policy.json`` (metadata, and which model file is
current), ``<root>/<name>/model-<version>.npz`` (arrays and JSON,
``learner_node.model_files``) and, when the policy keeps experience
(transitions for a goal that fine-tunes it to start its buffer with,
``learner_node.replay_buffer``), ``<root>/<name>/experience-<version>.npz``.
A save writes the new files, then replaces policy.json, each through a
temporary file and an atomic rename, then deletes the old files. A process
killed at any moment leaves policy.json naming complete files: the old ones
or the new.

Nothing a store holds is unpickled or run: policy.json is JSON, the other
files are ``.npz`` arrays read with ``allow_pickle=False``. A file that is not
what its name says is refused with a ``ValueError`` naming it. Loading reads
only files of the policy's own folder whose names the store writes. A policy
of the format before, ``model-<version>.zip`` (stable-baselines3's pickles),
is listed but not loaded or copied: ``glocal-ros policy import ZIP --trust``
converts it, running the code it holds.

ROS-free; loading a model imports SBX (and JAX) lazily.
"""

from __future__ import annotations

import json
import re
from dataclasses import asdict, dataclass, field
from datetime import datetime, timezone
from pathlib import Path
from typing import Any

from glocal_ros.files import atomic_write
from glocal_ros.paths import ros_home
from glocal_ros.spaces import OBSERVATION_LAYOUT
from learner_node.model_files import load_model, write_model
from learner_node.replay_buffer import Experience, load_experience, save_experience

METADATA_FILE = "policy.json"
_NAME = re.compile(r"^[A-Za-z0-9_][A-Za-z0-9_.-]{0,127}$")
#: The only model file names a store writes: a policy.json naming anything else (``../x``, an
#: absolute path) would make a load read outside the store.
_MODEL_FILE = re.compile(r"^model-([1-9][0-9]{0,17})\.npz$")
#: A model file of the format before (SB3's zip, pickles): listed, never loaded.
_PICKLED_MODEL_FILE = re.compile(r"^model-([1-9][0-9]{0,17})\.zip$")
_EXPERIENCE_FILE = re.compile(r"^experience-[1-9][0-9]{0,17}\.npz$")


def default_policy_dir() -> Path:
    """The learner's policy store unless told otherwise: ``$ROS_HOME/glocal_ros/policies`` (``~/.ros``)."""
    return ros_home() / "glocal_ros" / "policies"


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
    experience_file: str = ""  # "": the policy keeps no experience
    # The learner profile it was trained under (``learner_node.profiles``); records from before profiles
    # existed were all trained as ``glocal_ros``.
    profile: str = "glocal_ros"
    # The observation it acts on (``glocal_ros.spaces.OBSERVATION_LAYOUT``); records without one are
    # of layout 1, the only one before the field existed.
    observation_layout: int = OBSERVATION_LAYOUT

    def check_observation_layout(self) -> None:
        """``ValueError`` unless the policy acts on the observation the sim gives now (``OBSERVATION_LAYOUT``)."""
        if self.observation_layout != OBSERVATION_LAYOUT:
            raise ValueError(f"policy {self.name!r} was trained on observation layout {self.observation_layout}, "
                             f"and the sim's is {OBSERVATION_LAYOUT} (glocal_ros/spaces.py): it would act on "
                             f"numbers that mean something else; train it again from a policy of layout "
                             f"{OBSERVATION_LAYOUT}")


def check_name(name: str) -> str:
    if not _NAME.fullmatch(name):
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
        try:
            fields = json.loads(path.read_bytes())
            record = PolicyRecord(**{"observation_layout": 1, **fields})
        except (ValueError, TypeError) as error:  # not JSON (e.g. a pickle), or not a record's fields
            raise ValueError(f"{path}: not a policy record ({error})") from error
        if record.model_file and not (_MODEL_FILE.match(record.model_file)
                                      or _PICKLED_MODEL_FILE.match(record.model_file)):
            raise ValueError(f"{path}: model_file {record.model_file!r} is not a model file of this store "
                             f"(model-<N>.npz): refusing to load it")
        if record.experience_file and not _EXPERIENCE_FILE.match(record.experience_file):
            raise ValueError(f"{path}: experience_file {record.experience_file!r} is not an experience file "
                             f"of this store (experience-<N>.npz): refusing to load it")
        return record

    def model_path(self, name: str) -> Path:
        return self.root / name / self.record(name).model_file

    def load(self, name: str, env=None):
        """The SAC model of ``name`` (on ``env``), in a process that computes as the learner's
        (``model_files.load_model``); ``ValueError`` when it acts on another observation layout than the sim's,
        or when its files are not whole files of this store's format."""
        record = self.record(name)
        record.check_observation_layout()
        return load_model(self._data_model_path(name, record), env=env)

    def experience(self, name: str) -> Experience | None:
        """The transitions ``name`` keeps; None when it keeps none."""
        record = self.record(name)
        return load_experience(self.root / name / record.experience_file) if record.experience_file else None

    def save(self, model, record: PolicyRecord, experience: Experience | None = None) -> PolicyRecord:
        """Store ``model`` (SBX's SAC) and ``experience`` under ``record.name``, atomically."""
        write_experience = None if experience is None else lambda stream: save_experience(experience, stream)
        return self._store(record, lambda stream: write_model(model, stream), write_experience)

    def add_copy(self, source: "PolicyStore", name: str, destination: str) -> PolicyRecord:
        """Store a copy of ``source``'s policy ``name`` as ``destination`` (model, experience and metadata)."""
        record = source.record(name)
        model_bytes = source._data_model_path(name, record).read_bytes()
        experience_bytes = (source.root / name / record.experience_file).read_bytes() if record.experience_file \
            else None
        record.name = destination
        return self._store(record, lambda stream: stream.write(model_bytes),
                           None if experience_bytes is None else lambda stream: stream.write(experience_bytes))

    def keep_experience(self, name: str, experience: Experience) -> PolicyRecord:
        """Store ``experience`` with ``name``'s model, which stays as it is."""
        record = self.record(name)
        model_bytes = self._data_model_path(name, record).read_bytes()
        return self._store(record, lambda stream: stream.write(model_bytes),
                           lambda stream: save_experience(experience, stream))

    def update(self, name: str, **changes) -> PolicyRecord:
        """Change metadata only (e.g. the last score)."""
        record = self.record(name)
        for key, value in changes.items():
            setattr(record, key, value)
        record.updated = _now()
        self._write_record(record)
        return record

    def _data_model_path(self, name: str, record: PolicyRecord) -> Path:
        """The model file of ``name``; ``ValueError`` when it is of the pickled format before."""
        path = self.root / name / record.model_file
        if _PICKLED_MODEL_FILE.match(record.model_file):
            raise ValueError(f"{path}: policy {name!r} is a stable-baselines3 zip, whose loading unpickles and runs "
                             f"the code it holds; this learner loads only arrays and JSON. If you trust the file, "
                             f"convert it with `glocal-ros policy import {path} --trust --store {self.root}`")
        return path

    def _store(self, record: PolicyRecord, write_model, write_experience=None) -> PolicyRecord:
        """New files written by ``write_model(stream)`` (and ``write_experience``), then the record naming them."""
        folder = self.root / check_name(record.name)
        folder.mkdir(parents=True, exist_ok=True)
        previous = self.record(record.name) if record.name in self else PolicyRecord(record.name)
        version = _version(previous.model_file) + 1
        record.model_file, record.updated = f"model-{version}.npz", _now()
        record.experience_file = f"experience-{version}.npz" if write_experience else ""
        atomic_write(folder / record.model_file, write_model)
        if write_experience:
            atomic_write(folder / record.experience_file, write_experience)
        self._write_record(record)
        for old in (previous.model_file, previous.experience_file):
            if old:
                (folder / old).unlink(missing_ok=True)
        return record

    def _write_record(self, record: PolicyRecord) -> None:
        text = json.dumps(asdict(record), indent=2, sort_keys=True).encode() + b"\n"
        atomic_write(self.root / record.name / METADATA_FILE, lambda stream: stream.write(text))


def _version(model_file: str) -> int:
    """The version of a model file name of the store (0: none), of either format."""
    match = _MODEL_FILE.match(model_file) or _PICKLED_MODEL_FILE.match(model_file)
    return int(match.group(1)) if match else 0

"""Compact files of an SB3 replay buffer (only the filled rows), and experience.

A Train goal's buffer is a ``learner_node.updates.TransitionRing``; the SB3
buffers here are those of ``glocal-ros train-prior``, which trains with SB3's
own ``learn``.

SB3's ``save_replay_buffer`` pickles the whole preallocated buffer (about
110 MB at 200k transitions of this env) however little of it is used; a
checkpoint every few thousand steps needs only what was collected.

*Experience* is a bounded set of transitions kept beside a stored policy
(``PolicyStore``), flat (one row per transition, whatever the number of envs
that collected them) so that a goal on any number of envs can start its
buffer with them. Both file kinds are plain ``.npz`` arrays, loaded with
``allow_pickle=False`` (a pickle, an object array or a member that is no
array is refused); a file that is not what it should be is a ``ValueError``
naming it.
"""

from __future__ import annotations

from pathlib import Path
from typing import BinaryIO, Iterable

import numpy as np

from glocal_ros.files import read_npz

TRANSITION_ARRAYS = ("observations", "next_observations", "actions", "rewards", "dones", "timeouts")

#: Transitions, one row each: the arrays of ``TRANSITION_ARRAYS`` with the env axis folded into the first.
Experience = dict[str, np.ndarray]


def save_replay_buffer(buffer, stream: BinaryIO) -> None:
    filled = buffer.buffer_size if buffer.full else buffer.pos
    arrays = {name: getattr(buffer, name)[:filled] for name in TRANSITION_ARRAYS}
    np.savez(stream, pos=buffer.pos, full=buffer.full, **arrays)


def load_replay_buffer(buffer, path: Path) -> bool:
    """Fill ``buffer`` from ``path``; False (buffer left empty) when the shapes differ, e.g. another N.
    ``ValueError`` naming ``path`` when it is not a whole buffer file."""
    saved = read_arrays(path, (*TRANSITION_ARRAYS, "pos", "full"))
    observations = saved["observations"]
    if observations.ndim < 1 or len(observations) > buffer.buffer_size \
            or observations.shape[1:] != buffer.observations.shape[1:]:
        return False
    try:
        if saved["pos"].shape != () or saved["full"].shape != () or not 0 <= int(saved["pos"]) < buffer.buffer_size:
            raise ValueError("pos and full are not a position in the buffer and a flag")
        for name in TRANSITION_ARRAYS:
            getattr(buffer, name)[:len(observations)] = saved[name]
    except (ValueError, TypeError) as error:  # arrays of other lengths or shapes than the observations'
        raise ValueError(f"{path}: {error}") from error
    buffer.pos, buffer.full = int(saved["pos"]), bool(saved["full"])
    return True


def recent_experience(buffer, count: int) -> Experience:
    """The last ``count`` transitions (fewer when fewer are in) of an SB3 replay buffer, oldest first."""
    rows = buffer.buffer_size if buffer.full else buffer.pos
    order = np.roll(np.arange(rows), -buffer.pos) if buffer.full else np.arange(rows)  # oldest row first
    keep = order[max(0, rows - -(-count // buffer.n_envs)):]
    return {name: _flat(getattr(buffer, name)[keep])[-count:] for name in TRANSITION_ARRAYS}


def save_experience(experience: Experience, stream: BinaryIO) -> None:
    np.savez_compressed(stream, **{name: experience[name] for name in TRANSITION_ARRAYS})


def load_experience(path: Path) -> Experience:
    """The transitions in the experience file ``path``; ``ValueError`` naming it when it is not one."""
    experience = read_arrays(path, TRANSITION_ARRAYS)
    if any(values.ndim == 0 for values in experience.values()) or \
            len({len(values) for values in experience.values()}) != 1:
        raise ValueError(f"{path}: the arrays of the experience differ in length")
    return experience


def read_arrays(path: Path, names: Iterable[str]) -> dict[str, np.ndarray]:
    """The arrays ``names`` of the ``.npz`` file ``path`` (``glocal_ros.files.read_npz``); ``ValueError`` naming
    ``path`` when one is missing."""
    arrays = read_npz(path)
    missing = sorted(set(names) - set(arrays))
    if missing:
        raise ValueError(f"{path}: arrays {missing} are missing")
    return {name: arrays[name] for name in names}


def _flat(values: np.ndarray) -> np.ndarray:
    """(rows, n_envs, ...) -> (rows * n_envs, ...), transitions of one row next to each other."""
    return values.reshape((-1,) + values.shape[2:])

"""Compact checkpoints of an SB3 replay buffer: only the filled rows.

SB3's ``save_replay_buffer`` pickles the whole preallocated buffer (about
110 MB at 200k transitions of this env) however little of it is used; a
checkpoint every few thousand steps needs only what was collected.
"""

from __future__ import annotations

from pathlib import Path
from typing import BinaryIO

import numpy as np

_ARRAYS = ("observations", "next_observations", "actions", "rewards", "dones", "timeouts")


def save_replay_buffer(buffer, stream: BinaryIO) -> None:
    filled = buffer.buffer_size if buffer.full else buffer.pos
    arrays = {name: getattr(buffer, name)[:filled] for name in _ARRAYS}
    np.savez(stream, pos=buffer.pos, full=buffer.full, **arrays)


def load_replay_buffer(buffer, path: Path) -> bool:
    """Fill ``buffer`` from ``path``; False (buffer left empty) when the shapes differ, e.g. another N."""
    with np.load(path) as saved:
        filled = len(saved["observations"])
        if filled > buffer.buffer_size or saved["observations"].shape[1:] != buffer.observations.shape[1:]:
            return False
        for name in _ARRAYS:
            getattr(buffer, name)[:filled] = saved[name]
        buffer.pos, buffer.full = int(saved["pos"]), bool(saved["full"])
    return True

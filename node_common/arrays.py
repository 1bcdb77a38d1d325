"""numpy <-> ROS sequence fields without per-element Python loops.

rclpy stores ``float32[]`` fields as ``array.array('f')`` and accepts one
without checking each element; a list or ndarray would be checked one value
at a time, which dominates a batched step.
"""

from __future__ import annotations

import array

import numpy as np


def to_float32_field(values: np.ndarray) -> array.array:
    field = array.array("f")
    field.frombytes(np.ascontiguousarray(values, dtype=np.float32).tobytes())
    return field


def from_float32_field(field, rows: int | None = None) -> np.ndarray:
    """A float32 ndarray of ``field`` (array.array or list), as ``rows`` rows if given."""
    values = np.asarray(field, dtype=np.float32)
    return values.reshape(rows, -1) if rows else values

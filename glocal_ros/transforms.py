"""Rigid transforms as ROS carries them: a translation (x, y, z) and a unit quaternion (x, y, z, w).

ROS-free and small on purpose: the sim node turns world poses of links into
the parent-to-child transforms of /tf, and the bag renderer chains /tf back
into world poses; both use these few operations, so the two sides agree.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Iterable, Mapping, Sequence

import numpy as np


@dataclass(frozen=True)
class Transform:
    """``child`` expressed in ``parent``: p_parent = rotation(quaternion) @ p_child + translation."""

    translation: tuple[float, float, float] = (0.0, 0.0, 0.0)
    rotation: tuple[float, float, float, float] = (0.0, 0.0, 0.0, 1.0)  # x, y, z, w

    @classmethod
    def of(cls, translation: Sequence[float], rotation: Sequence[float]) -> "Transform":
        """From any sequences (numpy arrays, PyBullet tuples); the quaternion is normalised."""
        quaternion = np.asarray(rotation, dtype=float)
        quaternion = quaternion / np.linalg.norm(quaternion)
        return cls(tuple(float(v) for v in translation), tuple(float(v) for v in quaternion))

    def matrix(self) -> np.ndarray:
        """The 4x4 homogeneous matrix."""
        x, y, z, w = self.rotation
        result = np.eye(4)
        result[:3, :3] = (
            (1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)),
            (2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)),
            (2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)),
        )
        result[:3, 3] = self.translation
        return result

    def __mul__(self, other: "Transform") -> "Transform":
        """Composition: ``(a * b)`` maps b's child into a's parent."""
        x1, y1, z1, w1 = self.rotation
        x2, y2, z2, w2 = other.rotation
        rotation = (
            w1 * x2 + x1 * w2 + y1 * z2 - z1 * y2,
            w1 * y2 - x1 * z2 + y1 * w2 + z1 * x2,
            w1 * z2 + x1 * y2 - y1 * x2 + z1 * w2,
            w1 * w2 - x1 * x2 - y1 * y2 - z1 * z2,
        )
        translation = self.matrix()[:3, :3] @ np.asarray(other.translation) + np.asarray(self.translation)
        return Transform.of(translation, rotation)

    def inverse(self) -> "Transform":
        x, y, z, w = self.rotation
        rotation = self.matrix()[:3, :3]
        return Transform.of(-rotation.T @ np.asarray(self.translation), (-x, -y, -z, w))


IDENTITY = Transform()


def rpy_quaternion(roll: float, pitch: float, yaw: float) -> tuple[float, float, float, float]:
    """URDF's fixed-axis roll, pitch, yaw (rotation about x, then y, then z) as a quaternion x, y, z, w."""
    cr, sr = np.cos(roll / 2), np.sin(roll / 2)
    cp, sp = np.cos(pitch / 2), np.sin(pitch / 2)
    cy, sy = np.cos(yaw / 2), np.sin(yaw / 2)
    return (
        float(sr * cp * cy - cr * sp * sy),
        float(cr * sp * cy + sr * cp * sy),
        float(cr * cp * sy - sr * sp * cy),
        float(cr * cp * cy + sr * sp * sy),
    )


class FrameLookupError(LookupError):
    """A frame is not connected to the root of a transform tree; the message names where the chain breaks."""


def resolve_frames(edges: Mapping[str, tuple[str, Transform]], root: str,
                   frames: Iterable[str] | None = None) -> dict[str, Transform]:
    """Every frame's pose in ``root``, by chaining parent -> child transforms as a TF buffer does.

    ``edges`` maps each child frame to its parent and the child's transform
    in it (one TF tree at one instant: /tf_static and the /tf of one stamp).
    ``frames`` are those wanted (default: every child of ``edges``); the
    result holds them, ``root`` and every frame on their chains.

    :raises FrameLookupError: when a wanted frame's chain ends before ``root``
        (a frame with no parent) or runs in a loop.
    """
    poses: dict[str, Transform] = {root: IDENTITY}
    for frame in (edges if frames is None else frames):
        chain = []  # from ``frame`` up to the first frame whose pose is known
        current = frame
        while current not in poses:
            if current in chain:
                raise FrameLookupError(f"frame {frame!r}: its parents run in a loop through {current!r}")
            chain.append(current)
            if current not in edges:
                path = " -> ".join(reversed(chain))
                raise FrameLookupError(f"frame {frame!r} is not connected to {root!r}: no transform has "
                                       f"{current!r} as its child (chain {path})")
            current = edges[current][0]
        for child in reversed(chain):
            parent, transform = edges[child]
            poses[child] = poses[parent] * transform
    return poses

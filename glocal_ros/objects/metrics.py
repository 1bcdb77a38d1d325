"""EGAD's two grid axes: morphological complexity and grasp difficulty."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import trimesh

from glocal_ros.objects.meshing import GRIPPER_WIDTH
from glocal_ros.objects.raycast import first_hits

# EGAD (after Auerbach & Bongard 2014) histograms per-vertex angular deficits
# into 512 equal bins over [-2 pi, 2 pi] (bin width ~0.0245 rad) and takes the
# base-2 entropy; kept identical so values compare with EGAD's.
COMPLEXITY_BINS = 512
COMPLEXITY_RANGE = (-2.0 * np.pi, 2.0 * np.pi)

# Dex-Net's default friction coefficient for antipodal sampling.
FRICTION_COEFFICIENT = 0.5
QUALITY_PERCENTILE = 75.0
# Below this many antipodal grasps the percentile is noise: quality 0 (hardest).
MIN_ANTIPODAL_GRASPS = 10


def angular_deficits(mesh: trimesh.Trimesh) -> np.ndarray:
    """2 pi minus the sum of incident triangle angles, for every referenced vertex."""
    sums = np.bincount(
        np.asarray(mesh.faces).ravel(),
        weights=np.asarray(mesh.face_angles).ravel(),
        minlength=len(mesh.vertices),
    )
    used = np.zeros(len(mesh.vertices), dtype=bool)
    used[np.asarray(mesh.faces).ravel()] = True
    return 2.0 * np.pi - sums[used]


def morphological_complexity(mesh: trimesh.Trimesh) -> float:
    """Entropy (bits) of the angular-deficit histogram; higher = more complex.

    Flat or uniformly curved surfaces put almost every vertex in one or two
    bins (entropy near 0); ridges, saddles and lobes spread the deficits.
    The value depends on tessellation density, so it is computed on the
    marching-cubes mesh of a fixed grid, before decimation.
    """
    hist = np.histogram(angular_deficits(mesh), bins=COMPLEXITY_BINS, range=COMPLEXITY_RANGE)[0]
    prob = hist[hist > 0] / hist.sum()
    return float(max(0.0, -(prob * np.log2(prob)).sum()))


@dataclass(frozen=True)
class GraspDifficulty:
    """Result of :func:`grasp_difficulty`.

    ``difficulty = 1 - quality_q75``, in [0, 1], larger = harder.
    ``antipodal_fraction`` is the share of sampled grasps that fit the
    gripper, lie inside both friction cones and leave room for the fingers.
    """

    difficulty: float
    quality_q75: float
    antipodal_fraction: float
    samples: int


def grasp_difficulty(
    mesh: trimesh.Trimesh,
    rng: np.random.Generator,
    samples: int = 400,
    gripper_width: float = GRIPPER_WIDTH,
    friction: float = FRICTION_COEFFICIENT,
) -> GraspDifficulty:
    """Difficulty from the 75th-percentile quality of sampled antipodal grasps.

    Grasp candidates are drawn as Dex-Net's antipodal sampler does: a
    surface point (area-weighted) and a closing direction uniform inside its
    friction cone, a ray through the body giving the opposite contact. A
    candidate is antipodal if it fits in ``gripper_width``, the opposite
    contact also lies inside its friction cone, and no material blocks a
    finger outside either contact. As in EGAD, the percentile is taken over
    the antipodal grasps only (how good the good grasps are), so the axis is
    not just a proxy for complexity; how many there are is reported as
    ``antipodal_fraction``. With fewer than ``MIN_ANTIPODAL_GRASPS`` of them
    the quality is 0. The quality of an antipodal grasp is

        min(friction margin at both contacts) * max(0, 1 - d / (width / 2))

    where the margin is ``(cos(theta) - cos(alpha)) / (1 - cos(alpha))``
    for contact angle ``theta`` and cone half-angle ``alpha = atan(mu)``, and
    ``d`` is the distance from the centre of mass to the grasp axis (the
    lever arm gravity acts on, which dominates Ferrari-Canny for these
    objects). EGAD used the 75th percentile of Dex-Net's Ferrari-Canny
    quality; this keeps the percentile and replaces the wrench-space metric
    by its two geometric drivers.
    """
    triangles = np.asarray(mesh.triangles)
    normals = np.asarray(mesh.face_normals)
    areas = np.asarray(mesh.area_faces)
    face = rng.choice(len(areas), size=samples, p=areas / areas.sum())
    bary = rng.random((samples, 2))
    flip = bary.sum(axis=1) > 1.0
    bary[flip] = 1.0 - bary[flip]
    tri = triangles[face]
    points = tri[:, 0] + bary[:, :1] * (tri[:, 1] - tri[:, 0]) + bary[:, 1:] * (tri[:, 2] - tri[:, 0])

    cos_alpha = 1.0 / np.sqrt(1.0 + friction**2)
    axis = _directions_in_cone(-normals[face], cos_alpha, rng)
    eps = 1e-5
    width, hit_face = first_hits(triangles, points + eps * axis, axis)
    hit = hit_face >= 0
    width = np.where(hit, width + eps, np.inf)
    cos_p = np.einsum("ij,ij->i", axis, -normals[face])
    cos_q = np.where(hit, np.einsum("ij,ij->i", axis, normals[np.maximum(hit_face, 0)]), -1.0)

    # A finger waits (gripper_width - w) / 2 outside each contact when the
    # open gripper is centred on the grasp; material there blocks it.
    clearance = np.maximum((gripper_width - width) / 2.0, 0.0)
    far = np.where(hit[:, None], points + axis * np.where(hit, width, 0.0)[:, None], points)
    back_p, _ = first_hits(triangles, points - eps * axis, -axis)
    back_q, _ = first_hits(triangles, far + eps * axis, axis)
    free = (back_p > clearance) & (back_q > clearance)

    feasible = hit & (width <= gripper_width) & (cos_p >= cos_alpha) & (cos_q >= cos_alpha) & free
    margin = np.minimum(cos_p, cos_q)
    margin = np.clip((margin - cos_alpha) / (1.0 - cos_alpha), 0.0, 1.0)
    lever = np.linalg.norm(np.cross(np.asarray(mesh.center_mass) - points, axis), axis=1)
    centring = np.clip(1.0 - lever / (gripper_width / 2.0), 0.0, 1.0)
    quality = np.where(feasible, margin * centring, 0.0)

    good = quality[feasible]
    q75 = float(np.percentile(good, QUALITY_PERCENTILE)) if len(good) >= MIN_ANTIPODAL_GRASPS else 0.0
    return GraspDifficulty(
        difficulty=1.0 - q75,
        quality_q75=q75,
        antipodal_fraction=float(feasible.mean()),
        samples=samples,
    )


def _directions_in_cone(centres: np.ndarray, cos_alpha: float, rng: np.random.Generator) -> np.ndarray:
    """Unit vectors uniform over the spherical cap of half-angle alpha around each centre."""
    n = len(centres)
    cos_t = rng.uniform(cos_alpha, 1.0, size=n)
    sin_t = np.sqrt(1.0 - cos_t**2)
    phi = rng.uniform(0.0, 2.0 * np.pi, size=n)
    helper = np.where(np.abs(centres[:, :1]) < 0.9, [[1.0, 0.0, 0.0]], [[0.0, 1.0, 0.0]])
    e1 = np.cross(centres, helper)
    e1 /= np.linalg.norm(e1, axis=1, keepdims=True)
    e2 = np.cross(centres, e1)
    return centres * cos_t[:, None] + (e1 * np.cos(phi)[:, None] + e2 * np.sin(phi)[:, None]) * sin_t[:, None]

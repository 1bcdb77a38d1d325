"""Field -> mesh, and the EGAD mesh preparation for a parallel-jaw gripper."""

from __future__ import annotations

from pathlib import Path

import fast_simplification
import numpy as np
import trimesh
from scipy import ndimage
from skimage import measure

# Panda hand: 0.08 m maximum opening. EGAD's prepare_meshes.py scales the
# longest oriented-bounding-box extent to the gripper width and then, if the
# shortest extent exceeds 0.8 x width, shrinks it so it fits between the fingers.
GRIPPER_WIDTH = 0.08
GRIPPER_FIT_FRACTION = 0.8


class EmptyFieldError(ValueError):
    """The field has no solid region large enough to mesh."""


def field_to_mesh(field: np.ndarray, spacing: float, min_voxels: int = 64) -> trimesh.Trimesh:
    """Largest solid component of ``field > 0`` (after an opening) as a smoothed closed mesh.

    Marching cubes runs on the continuous field (sub-voxel surface placement)
    rather than on the binary occupancy, so simple fields give genuinely
    smooth surfaces; components other than the largest are pushed below the
    iso-level first, as EGAD kept only the biggest piece.
    """
    # A one-voxel opening removes fins and shards thinner than about two
    # voxels (EGAD applied binary_opening too): they print badly, simulate
    # badly and inflate the complexity metric with noise.
    solid = ndimage.binary_opening(field > 0.0)
    labels, count = ndimage.label(solid)
    if count == 0:
        raise EmptyFieldError("field has no solid voxels")
    sizes = np.bincount(labels.ravel())[1:]
    largest = int(np.argmax(sizes)) + 1
    if sizes[largest - 1] < min_voxels:
        raise EmptyFieldError(f"largest component has only {sizes[largest - 1]} voxels")
    # Filling internal cavities: EGAD's fill_orthographic did the same, a
    # hollow print is not what a grasp simulator should see.
    keep = ndimage.binary_fill_holes(labels == largest)
    masked = np.where(keep, np.maximum(field, 1e-6), np.minimum(field, -1e-6))
    padded = np.pad(masked, 1, constant_values=-1.0)
    verts, faces, _, _ = measure.marching_cubes(padded, level=0.0, spacing=(spacing,) * 3)
    mesh = trimesh.Trimesh(verts, faces, process=True)
    # Taubin smoothing removes marching-cubes terracing without shrinking.
    trimesh.smoothing.filter_taubin(mesh, lamb=0.5, nu=0.53, iterations=10)
    if mesh.volume < 0:
        mesh.invert()
    return mesh


def prepare_for_gripper(
    visual: trimesh.Trimesh,
    solid: trimesh.Trimesh,
    gripper_width: float = GRIPPER_WIDTH,
    fit_fraction: float = GRIPPER_FIT_FRACTION,
) -> tuple[trimesh.Trimesh, trimesh.Trimesh]:
    """Scale as EGAD does for a gripper and express both meshes in a canonical frame.

    Frame and scale come from ``visual`` (the decimated mesh the simulator
    shows, so the gripper constraint holds exactly for it): axes are its
    oriented-bounding-box axes sorted so x is the longest and z the shortest
    extent (the object lies flat at identity orientation, and its
    axis-aligned extents equal the oriented ones). The origin is the centre
    of mass of ``solid``, the watertight full-resolution mesh of the same
    shape, so inertial and link frames coincide.
    """
    to_box, extents = trimesh.bounds.oriented_bounds(visual)
    order = np.argsort(extents)[::-1]
    rotation = np.eye(4)
    rotation[:3, :3] = np.eye(3)[order]
    if np.linalg.det(rotation[:3, :3]) < 0:
        rotation[2, :3] *= -1.0
    extents = np.asarray(extents)[order]
    scale = gripper_width / float(extents.max())
    if extents.min() * scale > fit_fraction * gripper_width:
        scale = fit_fraction * gripper_width / float(extents.min())
    transform = np.diag([scale, scale, scale, 1.0]) @ rotation @ to_box

    out_visual, out_solid = visual.copy(), solid.copy()
    out_visual.apply_transform(transform)
    out_solid.apply_transform(transform)
    centre = np.asarray(out_solid.center_mass)
    out_visual.apply_translation(-centre)
    out_solid.apply_translation(-centre)
    return out_visual, out_solid


def decimate(mesh: trimesh.Trimesh, target_faces: int) -> trimesh.Trimesh:
    """Quadric decimation to about ``target_faces`` faces (no-op if already smaller)."""
    if len(mesh.faces) <= target_faces:
        return mesh.copy()
    reduction = 1.0 - target_faces / len(mesh.faces)
    verts, faces = fast_simplification.simplify(
        np.asarray(mesh.vertices, dtype=np.float64), np.asarray(mesh.faces), target_reduction=reduction
    )
    return trimesh.Trimesh(verts, faces, process=True)


def write_obj(mesh: trimesh.Trimesh, path: Path, digits: int = 5) -> None:
    """Write a plain OBJ (vertices and faces only), with ``digits`` decimals to keep files small."""
    fmt = f"v {{:.{digits}f}} {{:.{digits}f}} {{:.{digits}f}}\n"
    with open(path, "w") as f:
        f.writelines(fmt.format(*v) for v in np.asarray(mesh.vertices))
        f.writelines(f"f {a + 1} {b + 1} {c + 1}\n" for a, b, c in np.asarray(mesh.faces))

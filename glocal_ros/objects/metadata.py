"""``objects.json``: what was generated or imported, and every object's metrics."""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass, field, fields
from pathlib import Path
from typing import Any, Mapping, Optional

from glocal_ros.files import atomic_write

METADATA_FILE = "objects.json"


@dataclass
class ObjectMetadata:
    """One task's object. Lengths in m, mass in kg, inertia in kg m^2 about the
    centre of mass (the mesh origin), expressed in the mesh frame."""

    task: str
    source: str
    complexity: float
    difficulty: float
    grasp_quality_q75: float
    antipodal_fraction: float
    grasp_samples: int
    extents: list[float]
    volume: float
    mass: float
    density: float
    inertia: list[list[float]]
    raw_vertices: int
    raw_faces: int
    visual_vertices: int
    visual_faces: int
    hull_count: int
    collision_vertices: int
    seed: Optional[int] = None
    candidate_index: Optional[int] = None
    source_file: Optional[str] = None
    generator_params: Optional[dict[str, Any]] = None
    # Measured in the simulator (see record_grasp_success): the share of episodes in which the scripted grasp
    # (exact, with retries) and a single perturbed grasp lift the object.
    scripted_grasp_success: Optional[float] = None
    perturbed_grasp_success: Optional[float] = None
    # Measured in the simulator (sim_node.lifting_poses, see record_lifting_poses): the share of top-down
    # poses over the object's footprint, yaw uniform, whose scripted descent, close and lift lifts it; and
    # the success rate of its best pose, repeated (the set keeps it at 80% or more).
    lifting_pose_share: Optional[float] = None
    best_pose_success: Optional[float] = None
    # An imported mesh that was repaired (glocal_ros.objects.repair.MeshRepair.to_dict): the method, the
    # non-manifold edges closed, and the volume and extents before and after, in the file's units.
    repair: Optional[dict[str, Any]] = None


@dataclass
class ObjectSetMetadata:
    """The whole 7x7 set: provenance, settings, binning and per-task metadata."""

    generator_version: str
    source: str
    config: dict[str, Any]
    binning: dict[str, Any]
    objects: dict[str, ObjectMetadata] = field(default_factory=dict)
    seed: Optional[int] = None
    candidates: Optional[int] = None
    valid_candidates: Optional[int] = None
    lifting_poses: Optional[dict[str, Any]] = None
    """How ``lifting_pose_share`` was measured: seed, budget, the best pose's minimum success."""
    warnings: Optional[list[str]] = None
    """What an imported set keeps although a generated one would be refused for it (an object whose best pose
    lifts it less than the minimum)."""

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)

    def save(self, objects_dir: Path) -> Path:
        """Write ``<objects_dir>/objects.json`` and return its path."""
        path = Path(objects_dir) / METADATA_FILE
        text = (json.dumps(self.to_dict(), indent=1) + "\n").encode()
        atomic_write(path, lambda stream: stream.write(text))
        return path

    @classmethod
    def load(cls, objects_dir: Path) -> "ObjectSetMetadata":
        """Read ``<objects_dir>/objects.json``."""
        data = json.loads((Path(objects_dir) / METADATA_FILE).read_text())
        objects = {task: ObjectMetadata(**entry) for task, entry in data.pop("objects").items()}
        known = {f.name for f in fields(cls)}
        return cls(objects=objects, **{k: v for k, v in data.items() if k in known})


def record_grasp_success(objects_dir: Path, scripted: Mapping[str, float] = {},
                         perturbed: Mapping[str, float] = {}) -> ObjectSetMetadata:
    """Store success rates (0..1) per task in ``objects.json``: of the scripted grasp and of the perturbed one.

    The hook for the simulator's checks (``glocal-ros assets check``); tasks
    not given keep their current values.
    """
    metadata = ObjectSetMetadata.load(objects_dir)
    for rates, name in ((scripted, "scripted_grasp_success"), (perturbed, "perturbed_grasp_success")):
        for task, rate in rates.items():
            if task not in metadata.objects:
                raise KeyError(f"task {task!r} is not in {Path(objects_dir) / METADATA_FILE}")
            setattr(metadata.objects[task], name, float(rate))
    metadata.save(objects_dir)
    return metadata


def record_lifting_poses(objects_dir: Path, results: Mapping[str, tuple[float, float]],
                         settings: Mapping[str, Any]) -> ObjectSetMetadata:
    """Store (share of lifting poses, best pose's success) per task in ``objects.json``, and how they were
    measured (``settings``) in its ``lifting_poses``; tasks not given keep their values. Written atomically,
    and not at all if a task is not in the set (``KeyError``)."""
    metadata = ObjectSetMetadata.load(objects_dir)
    unknown = [task for task in results if task not in metadata.objects]
    if unknown:
        raise KeyError(f"tasks {unknown} are not in {Path(objects_dir) / METADATA_FILE}")
    for task, (share, best) in results.items():
        metadata.objects[task].lifting_pose_share = float(share)
        metadata.objects[task].best_pose_success = float(best)
    metadata.lifting_poses = dict(settings)
    metadata.save(objects_dir)
    return metadata

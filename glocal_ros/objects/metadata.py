"""``objects.json``: what was generated or imported, and every object's metrics."""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass, field, fields
from pathlib import Path
from typing import Any, Mapping, Optional

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
    # Filled by the scripted-grasp check (see record_scripted_grasp_success).
    scripted_grasp_success: Optional[float] = None


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

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)

    def save(self, objects_dir: Path) -> Path:
        """Write ``<objects_dir>/objects.json`` and return its path."""
        path = Path(objects_dir) / METADATA_FILE
        path.write_text(json.dumps(self.to_dict(), indent=1) + "\n")
        return path

    @classmethod
    def load(cls, objects_dir: Path) -> "ObjectSetMetadata":
        """Read ``<objects_dir>/objects.json``."""
        data = json.loads((Path(objects_dir) / METADATA_FILE).read_text())
        objects = {task: ObjectMetadata(**entry) for task, entry in data.pop("objects").items()}
        known = {f.name for f in fields(cls)}
        return cls(objects=objects, **{k: v for k, v in data.items() if k in known})


def record_scripted_grasp_success(objects_dir: Path, success_rates: Mapping[str, float]) -> ObjectSetMetadata:
    """Store scripted-controller success rates (0..1) per task in ``objects.json``.

    The hook for the graspability check run by the controller's owner; tasks
    not in ``success_rates`` keep their current value.
    """
    metadata = ObjectSetMetadata.load(objects_dir)
    for task, rate in success_rates.items():
        if task not in metadata.objects:
            raise KeyError(f"task {task!r} is not in {Path(objects_dir) / METADATA_FILE}")
        metadata.objects[task].scripted_grasp_success = float(rate)
    metadata.save(objects_dir)
    return metadata

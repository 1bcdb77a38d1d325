"""Generate the 49-object set (or import EGAD's) into ``<out_dir>/<TASK>/``.

Each task directory holds ``model.urdf``, ``visual.obj`` (decimated) and
``collision.obj`` (V-HACD hulls); ``<out_dir>/objects.json`` holds the
metrics (see :mod:`glocal_ros.objects.metadata`).

Everything is written to a staging directory beside ``out_dir`` and moved
into it at the end, so a failure leaves ``out_dir`` as it was.

The letter is either the geometric difficulty (``assign_grid``) or, given a
``MeasuredGrid``, what the simulator measures (``assign_measured_grid``): the
simulator is passed in as a ``GraspTrial``, so this package does not import it.

Given a ``LiftingPoseCheck``, the share of top-down poses that lift each
object and its best pose's success are measured on the staged objects and
stored beside the other metrics; a generated set in which some object's best
pose lifts it less than ``min_best_pose_success`` of the time is refused
(``UnliftableObjectError``) before anything is written to ``out_dir``, and
what was measured is kept beside it (``<out_dir>.refused.json``). An imported
(EGAD) set keeps such an object and lists it in ``warnings`` (see
``import_egad``); a mesh with a few non-manifold edges is repaired on import
(``glocal_ros.objects.repair``) and the repair recorded.
"""

from __future__ import annotations

import concurrent.futures
import contextlib
import json
import shutil
import tempfile
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import Callable, Iterator, Mapping, Optional, Sequence

import numpy as np
import trimesh

from glocal_ros.files import atomic_write
from glocal_ros.objects.cppn import CPPNParams, check_envelope, evaluate_field, sample_cppn, solid_bounds
from glocal_ros.objects.grid import (
    BINNING_METHOD,
    LETTER_MEASURES,
    assign_grid,
    assign_measured_grid,
    measured_binning_method,
    shortlist,
)
from glocal_ros.objects.meshing import (
    GRIPPER_FIT_FRACTION,
    GRIPPER_WIDTH,
    EmptyFieldError,
    decimate,
    field_to_mesh,
    prepare_for_gripper,
    write_obj,
)
from glocal_ros.objects.metadata import ObjectMetadata, ObjectSetMetadata
from glocal_ros.objects.metrics import (
    COMPLEXITY_BINS,
    COMPLEXITY_RANGE,
    FRICTION_COEFFICIENT,
    QUALITY_PERCENTILE,
    GraspDifficulty,
    grasp_difficulty,
    morphological_complexity,
)
from glocal_ros.objects.physics import (
    FrictionConfig,
    MassConfig,
    VhacdConfig,
    convex_decomposition,
    mass_properties,
    write_urdf,
)
from glocal_ros.objects.render import render_contact_sheet
from glocal_ros.objects.repair import MeshRepair, UnrepairableMeshError, repair_mesh
from glocal_ros.tasks import ALL_TASKS, check_novel_name, validate_tasks

GENERATOR_VERSION = "2.0.0"

#: ``progress(stage, done, total)``; stages are "candidates", "grasp trials" and "objects".
ProgressCallback = Callable[[str, int, int], None]

#: ``grasp_trial(objects_dir, task, seed)``: (perturbed-grasp success, scripted-grasp success), 0..1, of
#: the object of ``task`` in ``objects_dir``, measured in the simulator; a function of ``seed``.
GraspTrial = Callable[[Path, str, int], tuple[float, float]]

#: ``lifting_pose_trial(objects_dir, task, seed)``: (share of top-down poses that lift it, its best pose's
#: success), 0..1, of the object of ``task`` in ``objects_dir``; a function of ``seed`` and ``task``
#: (``sim_node.lifting_poses.lifting_pose_trial``).
LiftingPoseTrial = Callable[[Path, str, int], tuple[float, float]]

#: Keep every object learnable: its best scripted pose lifts it at least this often.
MIN_BEST_POSE_SUCCESS = 0.8


@dataclass(frozen=True)
class MeasuredGrid:
    """Letters from grasps in the simulator (``grid.measured_binning_method``).

    ``per_column`` candidates of each complexity digit are built and tried by ``grasp_trial``, which
    gives (the measure the letters follow, whether the candidate can be grasped) as ``letter_by`` says:
    (perturbed-grasp success, scripted-grasp success) for ``"perturbed grasp"``, (share of lifting
    poses, the best pose's success) for ``"lifting poses"`` (``LiftingPoseTrial``). Those whose second
    number is below ``min_scripted_success`` never enter the grid, so every object stays graspable.
    """

    grasp_trial: GraspTrial
    per_column: int = 32
    min_scripted_success: float = 0.8
    letter_by: str = "perturbed grasp"

    def __post_init__(self) -> None:
        if self.letter_by not in LETTER_MEASURES:
            raise ValueError(f"unknown letter_by {self.letter_by!r}: choose one of {', '.join(LETTER_MEASURES)}")


@dataclass(frozen=True)
class LiftingPoseCheck:
    """Measure the share of lifting poses of every written object, and refuse a set with an object whose
    best pose lifts it less than ``min_best_pose_success`` of the time.

    ``settings`` (the trial's budget) is recorded in ``objects.json`` with the seed.
    """

    trial: LiftingPoseTrial
    seed: int = 0
    min_best_pose_success: float = MIN_BEST_POSE_SUCCESS
    workers: int = 1
    settings: dict = field(default_factory=dict)

    def record(self) -> dict:
        """What ``objects.json`` records of this measurement (``ObjectSetMetadata.lifting_poses``)."""
        return {"seed": self.seed, "min_best_pose_success": self.min_best_pose_success, **self.settings}


class UnliftableObjectError(ValueError):
    """Some object's best top-down pose lifts it less often than the set allows; the message names them."""


@dataclass(frozen=True)
class GeneratorConfig:
    """Everything besides the seed that determines the generated set."""

    resolution: int = 56
    coarse_resolution: int = 32
    visual_faces: int = 1000
    grasp_samples: int = 400
    # Candidates with fewer antipodal grasps than this are likely
    # ungraspable by a parallel-jaw gripper and never enter the grid.
    min_antipodal_fraction: float = 0.05
    gripper_width: float = GRIPPER_WIDTH
    fit_fraction: float = GRIPPER_FIT_FRACTION
    mass: MassConfig = field(default_factory=MassConfig)
    friction: FrictionConfig = field(default_factory=FrictionConfig)
    vhacd: VhacdConfig = field(default_factory=VhacdConfig)
    envelope: str = "blob"
    """The base solids' proportions (``glocal_ros.objects.cppn.ENVELOPES``)."""

    def __post_init__(self) -> None:
        check_envelope(self.envelope)

    def to_dict(self) -> dict:
        out = asdict(self)
        out["complexity_histogram"] = {"bins": COMPLEXITY_BINS, "range": list(COMPLEXITY_RANGE)}
        out["grasp_metric"] = {"friction_coefficient": FRICTION_COEFFICIENT, "percentile": QUALITY_PERCENTILE}
        return out


@dataclass(frozen=True)
class CandidateMetrics:
    """Grid metrics of one generated candidate."""

    index: int
    complexity: float
    difficulty: float
    antipodal_fraction: float


@dataclass
class _Measured:
    complexity: float
    grasp: GraspDifficulty
    raw: trimesh.Trimesh
    visual: trimesh.Trimesh
    solid: trimesh.Trimesh


def _measure(mesh: trimesh.Trimesh, grasp_rng: np.random.Generator, config: GeneratorConfig,
             as_given: Optional[trimesh.Trimesh] = None) -> _Measured:
    # Complexity on the full marching-cubes mesh, before decimation and
    # scaling (it is scale-invariant); difficulty on the scaled visual mesh,
    # the geometry the gripper actually meets. A repaired mesh's complexity is
    # its original's (``as_given``): the metric depends on tessellation.
    complexity = morphological_complexity(mesh if as_given is None else as_given)
    visual = decimate(mesh, config.visual_faces)
    visual, solid = prepare_for_gripper(visual, mesh, config.gripper_width, config.fit_fraction)
    grasp = grasp_difficulty(visual, grasp_rng, config.grasp_samples, config.gripper_width)
    return _Measured(complexity, grasp, mesh, visual, solid)


def _candidate_rngs(seed: int, index: int) -> tuple[np.random.Generator, np.random.Generator]:
    # Independent streams per candidate: rebuilding one candidate reproduces
    # its metrics without replaying the others.
    return np.random.default_rng([seed, index, 0]), np.random.default_rng([seed, index, 1])


def candidate_params(seed: int, index: int, config: GeneratorConfig) -> CPPNParams:
    """The CPPN of candidate ``index`` of the pool seeded by ``seed``."""
    shape_rng, _ = _candidate_rngs(seed, index)
    # Square root skews knobs upward: low knobs all give similar plain blobs,
    # the complex end needs more draws to populate its columns.
    return sample_cppn(shape_rng, float(shape_rng.random()) ** 0.5, config.envelope)


def candidate_mesh(seed: int, index: int, config: GeneratorConfig) -> tuple[CPPNParams, trimesh.Trimesh]:
    """The CPPN and marching-cubes mesh of candidate ``index`` of the pool seeded by ``seed``.

    Raises :class:`EmptyFieldError` if the field has no usable solid.
    """
    params = candidate_params(seed, index, config)
    lower, upper = solid_bounds(params, config.coarse_resolution)
    field_values, spacing = evaluate_field(params, config.resolution, lower, upper)
    return params, field_to_mesh(field_values, spacing)


def evaluate_candidate(seed: int, index: int, config: GeneratorConfig) -> Optional[CandidateMetrics]:
    """Grid metrics of one candidate, or None if it does not mesh."""
    try:
        _, mesh = candidate_mesh(seed, index, config)
    except EmptyFieldError:
        return None
    measured = _measure(mesh, _candidate_rngs(seed, index)[1], config)
    return CandidateMetrics(
        index=index,
        complexity=measured.complexity,
        difficulty=measured.grasp.difficulty,
        antipodal_fraction=measured.grasp.antipodal_fraction,
    )


def _evaluate_star(args: tuple[int, int, GeneratorConfig]) -> Optional[CandidateMetrics]:
    return evaluate_candidate(*args)


def sample_candidates(
    seed: int,
    candidates: int,
    config: GeneratorConfig = GeneratorConfig(),
    workers: int = 1,
    progress: Optional[ProgressCallback] = None,
) -> list[Optional[CandidateMetrics]]:
    """Metrics of candidates ``0..candidates-1`` (None where a candidate failed to mesh)."""
    jobs = [(seed, i, config) for i in range(candidates)]
    results: list[Optional[CandidateMetrics]] = []
    if workers > 1:
        with concurrent.futures.ProcessPoolExecutor(max_workers=workers) as pool:
            for result in pool.map(_evaluate_star, jobs, chunksize=8):
                results.append(result)
                if progress:
                    progress("candidates", len(results), candidates)
    else:
        for job in jobs:
            results.append(_evaluate_star(job))
            if progress:
                progress("candidates", len(results), candidates)
    return results


def _write_object(
    task: str, measured: _Measured, out_dir: Path, config: GeneratorConfig, **provenance
) -> ObjectMetadata:
    task_dir = out_dir / task
    task_dir.mkdir(parents=True, exist_ok=True)
    write_obj(measured.visual, task_dir / "visual.obj")
    hulls, hull_vertices = convex_decomposition(measured.solid, task_dir / "collision.obj", config.vhacd)
    props = mass_properties(measured.solid, config.mass)
    write_urdf(task_dir / "model.urdf", task, props, config.friction)
    return ObjectMetadata(
        task=task,
        complexity=round(measured.complexity, 6),
        difficulty=round(measured.grasp.difficulty, 6),
        grasp_quality_q75=round(measured.grasp.quality_q75, 6),
        antipodal_fraction=round(measured.grasp.antipodal_fraction, 6),
        grasp_samples=measured.grasp.samples,
        extents=[round(float(e), 6) for e in measured.visual.extents],
        volume=float(f"{props.volume:.6g}"),
        mass=float(f"{props.mass:.6g}"),
        density=float(f"{props.mass / props.volume:.6g}"),
        inertia=[[float(f"{v:.6e}") for v in row] for row in props.inertia],
        raw_vertices=len(measured.raw.vertices),
        raw_faces=len(measured.raw.faces),
        visual_vertices=len(measured.visual.vertices),
        visual_faces=len(measured.visual.faces),
        hull_count=hulls,
        collision_vertices=hull_vertices,
        **provenance,
    )


@contextlib.contextmanager
def staged(out_dir: Path) -> Iterator[Path]:
    """A staging directory beside ``out_dir`` whose entries replace ``out_dir``'s of the same name once
    the block ends without an error; otherwise ``out_dir`` is left as it was. Removed either way."""
    out_dir = Path(out_dir)
    out_dir.parent.mkdir(parents=True, exist_ok=True)
    staging = Path(tempfile.mkdtemp(dir=out_dir.parent, prefix=f".{out_dir.name}.staging-"))
    try:
        yield staging
        out_dir.mkdir(exist_ok=True)
        for entry in sorted(staging.iterdir()):
            target = out_dir / entry.name
            if target.is_dir() and not target.is_symlink():
                shutil.rmtree(target)
            entry.replace(target)
    finally:
        shutil.rmtree(staging, ignore_errors=True)


def _trial_candidate(seed: int, index: int, config: GeneratorConfig, grasp_trial: GraspTrial,
                     work_dir: Path) -> tuple[int, float, float]:
    """Build candidate ``index`` as task A0 of a scratch objects directory and try grasping it."""
    _, mesh = candidate_mesh(seed, index, config)
    objects = work_dir / f"candidate-{index}"
    _write_object("A0", _measure(mesh, _candidate_rngs(seed, index)[1], config), objects, config,
                  source="generated", seed=seed, candidate_index=index)
    try:
        return (index, *grasp_trial(objects, "A0", seed * 100_003 + index))
    finally:
        shutil.rmtree(objects, ignore_errors=True)


def _trial_star(args: tuple) -> tuple[int, float, float]:
    return _trial_candidate(*args)


@contextlib.contextmanager
def _mapped(function: Callable, jobs: Sequence[tuple], workers: int) -> Iterator:
    """``map(function, jobs)``, in ``workers`` processes when there are several of both."""
    if workers > 1 and len(jobs) > 1:
        with concurrent.futures.ProcessPoolExecutor(max_workers=workers) as pool:
            yield pool.map(function, jobs)
    else:
        yield map(function, jobs)


def trial_candidates(seed: int, indices: Sequence[int], config: GeneratorConfig, grasp_trial: GraspTrial,
                     work_dir: Path, workers: int = 1,
                     progress: Optional[ProgressCallback] = None) -> dict[int, tuple[float, float]]:
    """(perturbed, scripted) grasp success of each candidate in ``indices``."""
    jobs = [(seed, index, config, grasp_trial, work_dir) for index in indices]
    results: dict[int, tuple[float, float]] = {}
    with _mapped(_trial_star, jobs, workers) as outcomes:
        for index, perturbed, scripted in outcomes:
            results[index] = (perturbed, scripted)
            if progress:
                progress("grasp trials", len(results), len(jobs))
    return results


def _lifting_star(args: tuple) -> tuple[str, float, float]:
    objects_dir, task, seed, trial = args
    return (task, *trial(objects_dir, task, seed))


def measure_lifting_poses(objects_dir: Path, tasks: Sequence[str], trial: LiftingPoseTrial, seed: int,
                          workers: int = 1, progress: Optional[ProgressCallback] = None,
                          ) -> dict[str, tuple[float, float]]:
    """(share of lifting poses, best pose's success) of each task's object in ``objects_dir``, measured by
    ``trial`` (each task seeded by ``seed`` alone, so results do not depend on ``workers``)."""
    jobs = [(Path(objects_dir), task, seed, trial) for task in tasks]
    results: dict[str, tuple[float, float]] = {}
    with _mapped(_lifting_star, jobs, workers) as outcomes:
        for task, share, best in outcomes:
            results[task] = (share, best)
            if progress:
                progress("lifting poses", len(results), len(jobs))
    return results


def unliftable(results: dict[str, tuple[float, float]], minimum: float = MIN_BEST_POSE_SUCCESS) -> list[str]:
    """"A2 (best pose lifts it 60% of the time)" for each task of ``results`` whose best pose falls short of
    ``minimum``, in the order given."""
    return [f"{task} (best pose lifts it {best:.0%} of the time)" for task, (_, best) in results.items()
            if best < minimum]


def never_grasped(scripted: Mapping[str, float], best_poses: Mapping[str, Optional[float]],
                  minimum: float = MIN_BEST_POSE_SUCCESS) -> tuple[list[str], list[str]]:
    """The tasks the scripted (centred) grasp never lifts, and those of them that are not learnable: no best
    pose lifting them at least ``minimum`` of the time is on record (None: not measured). A slab that the
    centred descent never lifts is learnable where another top-down pose lifts it."""
    never = [task for task, rate in scripted.items() if rate == 0]
    return never, [task for task in never if (best_poses.get(task) or 0.0) < minimum]


def refused_measurements_path(out_dir: Path) -> Path:
    """Where a refused set's measurements are kept: ``<out_dir>.refused.json``, beside ``out_dir`` (which a
    refusal leaves as it was)."""
    out_dir = Path(out_dir)
    return out_dir.parent / f"{out_dir.name}.refused.json"


def _keep_refused_measurements(metadata: ObjectSetMetadata, out_dir: Path, reason: str) -> Path:
    """Write what was measured of a refused set (its ``objects.json`` as it would have been, and why it was
    refused) beside ``out_dir``, atomically; return the path."""
    path = refused_measurements_path(out_dir)
    text = (json.dumps({"refused": reason, **metadata.to_dict()}, indent=1) + "\n").encode()
    atomic_write(path, lambda stream: stream.write(text))
    return path


def _check_lifting_poses(staging: Path, metadata: ObjectSetMetadata, check: LiftingPoseCheck,
                         out_dir: Path, progress: Optional[ProgressCallback], refuse: bool = True) -> list[str]:
    """Measure the staged objects into ``metadata`` and return those below the rule (``unliftable``'s
    text). With ``refuse``, one below it raises ``UnliftableObjectError`` after keeping the measurements
    beside ``out_dir`` (``refused_measurements_path``): 25 minutes of measurement are not thrown away."""
    results = measure_lifting_poses(staging, list(metadata.objects), check.trial, check.seed, check.workers,
                                    progress)
    for task, (share, best) in results.items():
        metadata.objects[task].lifting_pose_share = share
        metadata.objects[task].best_pose_success = best
    metadata.lifting_poses = check.record()
    failing = unliftable(results, check.min_best_pose_success)
    if failing and refuse:
        reason = (f"every object's best top-down pose must lift it at least {check.min_best_pose_success:.0%} "
                  f"of the time, and {len(failing)} do not: {', '.join(failing)}")
        kept = _keep_refused_measurements(metadata, out_dir, reason)
        raise UnliftableObjectError(f"{reason}; {out_dir} is unchanged; the measurements are kept in {kept}")
    return failing


def generate_object_set(
    out_dir: Path,
    seed: int = 0,
    candidates: int = 1500,
    progress: Optional[ProgressCallback] = None,
    config: GeneratorConfig = GeneratorConfig(),
    workers: int = 1,
    tasks: Optional[Sequence[str]] = None,
    contact_sheet: bool = True,
    measured: Optional[MeasuredGrid] = None,
    lifting_poses: Optional[LiftingPoseCheck] = None,
) -> ObjectSetMetadata:
    """Generate a seeded candidate pool, bin it on the grid and write the chosen objects.

    :param out_dir: output root; ``<out_dir>/<TASK>/`` and ``objects.json`` are written.
    :param seed: pool seed; the same seed and config give the same objects and metrics.
    :param candidates: pool size (at least 49 valid ones are needed; each
        complexity column needs 7).
    :param progress: optional ``progress(stage, done, total)`` callback.
    :param config: generator settings.
    :param workers: processes for candidate evaluation (results do not depend on it).
    :param tasks: write only these tasks (the grid is still chosen from the
        whole pool); ``objects.json`` then lists only them.
    :param contact_sheet: also render ``<out_dir>/contact_sheet.png``.
    :param measured: choose letters by grasps in the simulator rather than by the geometric difficulty.
    :param lifting_poses: measure the share of lifting poses and refuse an unliftable object
        (``UnliftableObjectError``, ``out_dir`` unchanged).
    """
    chosen_tasks = validate_tasks(tasks) if tasks is not None else list(ALL_TASKS)
    pool = sample_candidates(seed, candidates, config, workers, progress)
    valid = [m for m in pool if m is not None and m.antipodal_fraction >= config.min_antipodal_fraction]
    complexity, difficulty = [m.complexity for m in valid], [m.difficulty for m in valid]
    with staged(out_dir) as staging:
        trials: dict[int, tuple[float, float]] = {}
        if measured is None:
            grid, binning = assign_grid(complexity, difficulty), {"method": BINNING_METHOD}
        else:
            columns, edges = shortlist(complexity, difficulty, measured.per_column)
            tried = [valid[i].index for members in columns.values() for i in members]
            with tempfile.TemporaryDirectory() as scratch:
                trials = trial_candidates(seed, tried, config, measured.grasp_trial, Path(scratch), workers,
                                          progress)
            success = {i: trials[valid[i].index][0] for members in columns.values() for i in members
                       if trials[valid[i].index][1] >= measured.min_scripted_success}
            grid = assign_measured_grid(columns, success, edges)
            binning = {"method": measured_binning_method(measured.letter_by), "letter_by": measured.letter_by,
                       "per_column": measured.per_column, "min_scripted_success": measured.min_scripted_success,
                       "trials": {str(index): list(rates) for index, rates in sorted(trials.items())}}
        metadata = ObjectSetMetadata(
            generator_version=GENERATOR_VERSION,
            source="generated",
            config=config.to_dict(),
            binning={**binning, "complexity_edges": grid.complexity_edges},
            seed=seed,
            candidates=candidates,
            valid_candidates=len(valid),
        )
        for done, task in enumerate(chosen_tasks, start=1):
            index = valid[grid.cells[task]].index
            params, mesh = candidate_mesh(seed, index, config)
            grasps = {"perturbed_grasp_success": None, "scripted_grasp_success": None}
            if measured is not None and measured.letter_by == "perturbed grasp":
                grasps = dict(zip(grasps, trials[index]))
            metadata.objects[task] = _write_object(
                task,
                _measure(mesh, _candidate_rngs(seed, index)[1], config),
                staging,
                config,
                source="generated",
                seed=seed,
                candidate_index=index,
                generator_params=params.to_dict(),
                **grasps,
            )
            if progress:
                progress("objects", done, len(chosen_tasks))
        if lifting_poses is not None:
            _check_lifting_poses(staging, metadata, lifting_poses, Path(out_dir), progress)
        metadata.save(staging)
        if contact_sheet:
            render_contact_sheet(staging, staging / "contact_sheet.png")
    return metadata


class MissingEgadFilesError(FileNotFoundError):
    """The EGAD directory lacks some of the A0.obj..G6.obj files."""


class BadMeshError(ValueError):
    """A mesh given to the importer cannot become an object; the message names its file."""


@dataclass
class LoadedMesh:
    """A mesh as given (``given``, outward-facing) and the closed solid made from it (``solid``: the same
    mesh, holes filled, or its repair, described by ``repair``)."""

    given: trimesh.Trimesh
    solid: trimesh.Trimesh
    repair: Optional[MeshRepair] = None


def load_mesh(path: Path) -> LoadedMesh:
    """A closed, outward-facing mesh from ``path``: holes filled, and a few non-manifold edges repaired
    (:func:`glocal_ros.objects.repair.repair_mesh`, recorded in ``LoadedMesh.repair``). ``BadMeshError``
    naming the file if it is missing, not a mesh, empty, cannot be closed or repaired, or has no volume to
    scale into the gripper."""
    path = Path(path)
    if not path.exists():
        raise BadMeshError(f"{path}: no such file")
    if not path.is_file():
        raise BadMeshError(f"{path}: not a file")
    try:
        mesh = trimesh.load(path, force="mesh", process=True)
    except Exception as error:  # trimesh raises whatever its parsers raise
        raise BadMeshError(f"{path}: cannot be read as a mesh ({error})") from error
    if not isinstance(mesh, trimesh.Trimesh):
        raise BadMeshError(f"{path}: cannot be read as a mesh (trimesh made a {type(mesh).__name__} of it)")
    if len(mesh.faces) == 0:
        raise BadMeshError(f"{path}: the mesh is empty")
    repair = None
    given = mesh.copy()
    if not mesh.is_watertight:
        trimesh.repair.fill_holes(mesh)
        if not mesh.is_watertight:
            try:
                mesh, repair = repair_mesh(mesh)
            except UnrepairableMeshError as error:
                raise BadMeshError(f"{path}: the mesh is not watertight, filling its holes did not close it, "
                                   f"and it cannot be repaired: {error}") from error
    if mesh.volume < 0:
        mesh.invert()
    if given.volume < 0:
        given.invert()
    if not mesh.volume > 0 or min(mesh.extents) <= 0:
        raise BadMeshError(f"{path}: the mesh encloses no volume, so it cannot be scaled into the gripper")
    return LoadedMesh(given, mesh, repair)


def import_egad(
    src_dir: Path,
    out_dir: Path,
    config: GeneratorConfig = GeneratorConfig(),
    require_all: bool = True,
    progress: Optional[ProgressCallback] = None,
    contact_sheet: bool = True,
    lifting_poses: Optional[LiftingPoseCheck] = None,
    refuse_unliftable: bool = False,
) -> ObjectSetMetadata:
    """Build the same layout from EGAD's evaluation-set meshes (``A0.obj`` .. ``G6.obj``).

    Each mesh goes through the generator's steps: complexity on the mesh as
    given (EGAD's own marching-cubes mesh), decimation, EGAD gripper scaling,
    grasp difficulty, V-HACD, URDF and metadata. The task is the file name:
    EGAD's own letters are the grid, kept as published, and the measured
    metrics are recorded (the simulator's grasp checks are ``glocal-ros assets
    check``, which ``assets import-egad`` runs after it).

    Every mesh is loaded and checked before anything is written
    (:func:`load_mesh`): a mesh with a few non-manifold edges is repaired, and
    the repair (volume and extents before and after) is recorded in its
    object's ``repair``; a missing file, a file that is not a mesh, or a mesh
    that cannot be closed raises a ``BadMeshError`` (``MissingEgadFilesError``
    for files missing from a full import) naming the file, and ``out_dir``
    stays as it was.

    An imported set is EGAD's, not ours to choose: an object whose best
    top-down pose lifts it less than ``lifting_poses.min_best_pose_success``
    of the time is recorded and listed in ``ObjectSetMetadata.warnings``, not
    refused (the paper learned all 49), unless ``refuse_unliftable``; then
    ``UnliftableObjectError`` is raised, ``out_dir`` is unchanged and the
    measurements are kept beside it (``refused_measurements_path``).

    :param require_all: raise :class:`MissingEgadFilesError` unless all 49 files exist;
        if False, import whichever of them exist (at least one).
    :param lifting_poses: measure the share of lifting poses and the best pose's success of every object.
    :param refuse_unliftable: refuse a set with an object below the rule instead of warning.
    """
    src_dir, out_dir = Path(src_dir), Path(out_dir)
    if not src_dir.is_dir():
        raise MissingEgadFilesError(f"{src_dir}: no such directory")
    found = {task: src_dir / f"{task}.obj" for task in ALL_TASKS if (src_dir / f"{task}.obj").exists()}
    missing = [f"{task}.obj" for task in ALL_TASKS if task not in found]
    if (require_all and missing) or not found:
        raise MissingEgadFilesError(f"{src_dir}: missing {', '.join(missing)}")
    meshes: dict[str, LoadedMesh] = {}
    for done, (task, path) in enumerate(found.items(), start=1):
        meshes[task] = load_mesh(path)
        if progress:
            progress("meshes", done, len(found))
    metadata = ObjectSetMetadata(
        generator_version=GENERATOR_VERSION,
        source="egad",
        config=config.to_dict(),
        binning={"method": "EGAD evaluation-set file names (A0..G6) as published"},
    )
    with staged(out_dir) as staging:
        for done, (task, loaded) in enumerate(meshes.items(), start=1):
            # Seeded by the grid position, so a re-import gives the same metrics.
            measured = _measure(loaded.solid, np.random.default_rng([ALL_TASKS.index(task), 1]), config,
                                as_given=loaded.given if loaded.repair else None)
            metadata.objects[task] = _write_object(
                task, measured, staging, config, source="egad", source_file=found[task].name,
                repair=loaded.repair.to_dict() if loaded.repair else None,
            )
            if progress:
                progress("objects", done, len(found))
        if lifting_poses is not None:
            failing = _check_lifting_poses(staging, metadata, lifting_poses, out_dir, progress,
                                           refuse=refuse_unliftable)
            if failing:
                metadata.warnings = [
                    f"best pose below {lifting_poses.min_best_pose_success:.0%}: {text}; kept, as EGAD published "
                    f"it" for text in failing]
        metadata.save(staging)
        if contact_sheet:
            render_contact_sheet(staging, staging / "contact_sheet.png")
    return metadata


#: The files of one object's directory, as ``_write_object`` writes them.
OBJECT_FILES = ("model.urdf", "visual.obj", "collision.obj")


def prepare_object(source: Path, name: str, out_dir: Path, config: GeneratorConfig = GeneratorConfig(),
                   seed: int = 0) -> ObjectSetMetadata:
    """One object outside the set, as ``<out_dir>/<name>/`` and ``<out_dir>/objects.json``: a set of one.

    ``source`` is a mesh file, which goes through the importer's steps (``load_mesh``'s checks and repair,
    complexity, decimation, gripper scaling, grasp difficulty, V-HACD, URDF; the grasp sampling seeded by
    ``seed``), or an object directory another set holds (``assets generate``, ``assets import-egad``), whose
    files are taken as they are, with its metrics from that set's ``objects.json`` when it has them. ``name``
    must be a novel object's (``glocal_ros.tasks.check_novel_name``). Staged as ``import_egad`` is: a mesh
    that cannot be prepared raises ``BadMeshError`` and ``out_dir`` stays as it was.
    """
    check_novel_name(name)
    source = Path(source)
    metadata = ObjectSetMetadata(generator_version=GENERATOR_VERSION, source="novel", config=config.to_dict(),
                                 binning={"method": "one object outside the set, no grid position"})
    if source.is_dir():
        missing = [file for file in OBJECT_FILES if not (source / file).is_file()]
        if missing:
            raise BadMeshError(f"{source}: not an object directory (no {', '.join(missing)}); give a mesh file "
                               f"or a directory of a set that `assets generate` or `assets import-egad` wrote")
        with staged(out_dir) as staging:
            (staging / name).mkdir()
            for file in OBJECT_FILES:
                shutil.copy2(source / file, staging / name / file)
            known = ObjectSetMetadata.load(source.parent).objects if (source.parent / "objects.json").is_file() else {}
            if source.name in known:
                metadata.objects[name] = replace(known[source.name], task=name, source_file=str(source.resolve()))
            metadata.save(staging)
        return metadata
    loaded = load_mesh(source)
    with staged(out_dir) as staging:
        measured = _measure(loaded.solid, np.random.default_rng([seed, 1]), config,
                            as_given=loaded.given if loaded.repair else None)
        metadata.objects[name] = _write_object(name, measured, staging, config, source="novel",
                                               source_file=str(source.resolve()),
                                               repair=loaded.repair.to_dict() if loaded.repair else None)
        metadata.save(staging)
    return metadata

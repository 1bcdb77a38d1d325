"""Tests for glocal_ros.objects: metrics, binning, pipeline, importer and the committed set."""

from __future__ import annotations

import json
import shutil
import subprocess
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np
import pybullet as p
import pytest
import trimesh

from conftest import REPO
from glocal_ros.objects import (
    GRIPPER_FIT_FRACTION,
    GRIPPER_WIDTH,
    BadMeshError,
    GeneratorConfig,
    GridAssignmentError,
    LiftingPoseCheck,
    MeasuredGrid,
    MissingEgadFilesError,
    ObjectSetMetadata,
    assign_grid,
    generate_object_set,
    grasp_difficulty,
    import_egad,
    morphological_complexity,
    record_grasp_success,
    sample_candidates,
)
from glocal_ros.objects.grid import assign_measured_grid, shortlist
from glocal_ros.objects.meshing import field_to_mesh, prepare_for_gripper
from glocal_ros.objects.metrics import angular_deficits
from glocal_ros.objects.physics import VhacdConfig
from glocal_ros.objects.cppn import ENVELOPES, evaluate_field, sample_cppn, solid_bounds
from glocal_ros.objects.pipeline import candidate_mesh, candidate_params
from glocal_ros.objects.raycast import first_hits
from glocal_ros.tasks import ALL_TASKS, grid_coordinates

ASSETS = REPO / "assets" / "objects"
# Small enough that a whole pool takes seconds; only tests use it. V-HACD at a tenth of its voxels: the
# decomposition runs for every object written, and its quality is the committed set's to check.
FAST = GeneratorConfig(resolution=28, coarse_resolution=20, visual_faces=300, grasp_samples=120,
                       vhacd=VhacdConfig(resolution=20_000))
TOL = 1e-3


def test_library_is_ros_free() -> None:
    code = "import sys, glocal_ros.objects; assert 'rclpy' not in sys.modules"
    subprocess.run([sys.executable, "-c", code], check=True, cwd=REPO)


def test_angular_deficits_obey_gauss_bonnet() -> None:
    sphere = trimesh.creation.icosphere(subdivisions=3)
    assert angular_deficits(sphere).sum() == pytest.approx(4.0 * np.pi)


def test_complexity_orders_box_sphere_and_lobed_shape() -> None:
    box = trimesh.creation.box(extents=(1.0, 2.0, 3.0))
    sphere = trimesh.creation.icosphere(subdivisions=4)
    bumpy = sphere.copy()
    v = bumpy.vertices
    bumpy.vertices = v * (1.0 + 0.3 * np.sin(5 * v[:, :1]) * np.cos(4 * v[:, 1:2]))
    assert morphological_complexity(box) == 0.0  # every corner has deficit pi/2
    assert morphological_complexity(sphere) < morphological_complexity(bumpy)


def test_raycast_hits_box_face() -> None:
    box = trimesh.creation.box(extents=(2.0, 2.0, 2.0))
    dist, face = first_hits(np.asarray(box.triangles), np.zeros((2, 3)), np.array([[1.0, 0, 0], [0, 0, -1.0]]))
    assert dist == pytest.approx([1.0, 1.0])
    assert (face >= 0).all()
    miss, face = first_hits(np.asarray(box.triangles), np.array([[5.0, 0, 0]]), np.array([[1.0, 0, 0]]))
    assert np.isinf(miss[0]) and face[0] == -1


def test_grasp_difficulty_easy_box_vs_too_wide_box() -> None:
    rng = np.random.default_rng(0)
    small = trimesh.creation.box(extents=(0.06, 0.04, 0.03))
    wide = trimesh.creation.box(extents=(0.1, 0.1, 0.1))
    easy = grasp_difficulty(small, rng, samples=300)
    hard = grasp_difficulty(wide, rng, samples=300)
    assert 0.0 <= easy.difficulty < 0.7 and easy.antipodal_fraction > 0.5
    assert hard.difficulty == 1.0 and hard.antipodal_fraction == 0.0


def test_prepare_for_gripper_follows_egad_scaling() -> None:
    long = trimesh.creation.box(extents=(3.0, 1.0, 2.0))
    visual, solid = prepare_for_gripper(long, long)
    assert visual.extents == pytest.approx([GRIPPER_WIDTH, 2 * GRIPPER_WIDTH / 3, GRIPPER_WIDTH / 3])
    assert solid.center_mass == pytest.approx(np.zeros(3), abs=1e-9)
    cube = trimesh.creation.box(extents=(5.0, 5.0, 5.0))
    visual, _ = prepare_for_gripper(cube, cube)
    assert visual.extents == pytest.approx([GRIPPER_FIT_FRACTION * GRIPPER_WIDTH] * 3)


def test_assign_grid_fills_every_cell_in_order() -> None:
    rng = np.random.default_rng(1)
    complexity = rng.random(200)
    difficulty = 0.5 * complexity + 0.5 * rng.random(200)  # correlated, like real pools
    cells = assign_grid(complexity, difficulty).cells
    assert sorted(cells) == sorted(ALL_TASKS)
    assert len(set(cells.values())) == 49
    col_mean = [np.mean([complexity[cells[t]] for t in ALL_TASKS if t[1] == d]) for d in "0123456"]
    assert np.all(np.diff(col_mean) > 0)
    for digit in "0123456":
        column = [difficulty[cells[letter + digit]] for letter in "ABCDEFG"]
        assert np.all(np.diff(column) > 0)
    with pytest.raises(GridAssignmentError):
        assign_grid(complexity[:40], difficulty[:40])


def test_measured_grid_spreads_each_column_from_its_easiest_to_its_hardest() -> None:
    rng = np.random.default_rng(2)
    complexity, difficulty = rng.random(300), rng.random(300)
    columns, edges = shortlist(complexity, difficulty, 12)
    assert all(len(members) == 12 for members in columns.values())
    assert all(np.all(np.diff(difficulty[members]) >= 0) for members in columns.values())
    assert assign_grid(complexity, difficulty).complexity_edges == edges
    success = {m: float(rng.random()) for members in columns.values() for m in members}
    unusable = columns["3"][0]
    del success[unusable]  # e.g. its scripted grasp failed
    cells = assign_measured_grid(columns, success, edges).cells
    assert sorted(cells) == sorted(ALL_TASKS) and unusable not in cells.values()
    for digit, members in columns.items():
        column = [success[cells[letter + digit]] for letter in "ABCDEFG"]
        assert np.all(np.diff(column) < 0), column
        usable = [success[m] for m in members if m in success]
        assert (column[0], column[-1]) == (max(usable), min(usable))
    with pytest.raises(GridAssignmentError, match="column 3"):
        assign_measured_grid(columns, {m: v for m, v in success.items() if m not in columns["3"][:6]}, edges)


def test_candidates_are_deterministic() -> None:
    first = sample_candidates(seed=7, candidates=4, config=FAST)
    again = sample_candidates(seed=7, candidates=4, config=FAST)
    other = sample_candidates(seed=8, candidates=4, config=FAST)
    assert first == again
    assert first != other


@pytest.fixture(scope="module")
def small_set(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, ObjectSetMetadata]:
    out = tmp_path_factory.mktemp("generated")
    metadata = generate_object_set(out, seed=3, candidates=70, config=FAST, tasks=["A0", "G6"])
    return out, metadata


def test_generate_object_set_writes_layout(small_set: tuple[Path, ObjectSetMetadata]) -> None:
    out, metadata = small_set
    assert set(metadata.objects) == {"A0", "G6"}
    for task in ("A0", "G6"):
        for name in ("model.urdf", "visual.obj", "collision.obj"):
            assert (out / task / name).is_file()
    assert (out / "contact_sheet.png").stat().st_size > 1000
    loaded = ObjectSetMetadata.load(out)
    assert loaded == metadata
    a0, g6 = metadata.objects["A0"], metadata.objects["G6"]
    assert a0.complexity < g6.complexity and a0.difficulty < g6.difficulty
    assert a0.scripted_grasp_success is None and a0.generator_params is not None
    # Rebuilding a chosen candidate from its seed reproduces its stored parameters.
    params, _ = candidate_mesh(3, a0.candidate_index, FAST)
    assert params.to_dict() == a0.generator_params


def _proportions(params) -> tuple[str, float]:
    """("slab", "rod" or "blob", the taper) of a wide-envelope field's base solid."""
    thin = sum(axis < 0.3 for axis in params.semi_axes)
    return ("blob", "slab", "rod")[thin], params.taper


def test_the_wide_envelope_adds_tapered_slabs_and_rods_and_the_blob_one_is_unchanged() -> None:
    wide = [_proportions(candidate_params(5, index, replace(FAST, envelope="wide"))) for index in range(90)]
    forms = [form for form, _ in wide]
    assert all(forms.count(form) >= 20 for form in ("blob", "slab", "rod")), forms
    assert all(taper != 0.0 for _, taper in wide) and max(abs(taper) for _, taper in wide) > 0.5
    blobs = [candidate_params(5, index, FAST) for index in range(90)]
    assert all(min(p.semi_axes) >= 0.35 and p.taper == 0.0 for p in blobs)
    with pytest.raises(ValueError, match="unknown envelope 'flat': choose one of blob, wide"):
        replace(FAST, envelope="flat")


def test_a_wide_slab_stays_flat_and_its_taper_narrows_one_end_after_meshing() -> None:
    """Knob 0 (no network perturbation): the base solid alone, as the generator meshes it."""
    slab = next(params for params in (sample_cppn(np.random.default_rng(seed), 0.0, "wide") for seed in range(100))
                if _proportions(params)[0] == "slab" and abs(params.taper) > 0.4)
    lower, upper = solid_bounds(slab, FAST.coarse_resolution)
    mesh = field_to_mesh(*evaluate_field(slab, 40, lower, upper))
    visual, _ = prepare_for_gripper(mesh, mesh)
    extents = np.sort(visual.extents)
    assert extents[0] < 0.35 * extents[2], extents
    # Cross-sections at a quarter and three quarters of the long axis (the field's x): the taper's
    # narrow end is the one it names.
    x, y = mesh.vertices[:, 0], mesh.vertices[:, 1]
    lo, hi = x.min(), x.max()
    widths = [np.ptp(y[np.abs(x - (lo + f * (hi - lo))) < 0.05 * (hi - lo)]) for f in (0.25, 0.75)]
    narrow, wide = (widths[1], widths[0]) if slab.taper < 0 else (widths[0], widths[1])
    assert narrow < 0.75 * wide, (slab.taper, widths)


def test_the_generate_command_offers_every_envelope() -> None:
    from glocal_app.cli import build_parser

    for envelope in ENVELOPES:
        assert build_parser().parse_args(["assets", "generate", "--envelope", envelope]).envelope == envelope


def test_import_egad_builds_same_layout(tmp_path: Path) -> None:
    src = tmp_path / "egad"
    src.mkdir()
    for task, index in (("A0", 0), ("C3", 1)):
        _, mesh = candidate_mesh(11, index, FAST)
        mesh.apply_scale(1000.0)  # EGAD ships meshes in millimetres
        mesh.export(src / f"{task}.obj")
    with pytest.raises(MissingEgadFilesError):
        import_egad(src, tmp_path / "out", config=FAST)
    metadata = import_egad(src, tmp_path / "out", config=FAST, require_all=False, contact_sheet=False)
    assert set(metadata.objects) == {"A0", "C3"}
    for obj in metadata.objects.values():
        assert obj.source == "egad" and obj.source_file == f"{obj.task}.obj"
        assert max(obj.extents) <= GRIPPER_WIDTH + TOL
        assert (tmp_path / "out" / obj.task / "model.urdf").is_file()
    assert ObjectSetMetadata.load(tmp_path / "out").source == "egad"


def test_import_egad_refuses_bad_meshes_and_leaves_the_output_as_it_was(tmp_path: Path) -> None:
    src, out = tmp_path / "egad", tmp_path / "out"
    src.mkdir()
    _, mesh = candidate_mesh(11, 0, FAST)
    mesh.export(src / "A0.obj")
    import_egad(src, out, config=FAST, require_all=False, contact_sheet=False)
    before = {path: path.read_bytes() for path in out.rglob("*") if path.is_file()}
    open_box = trimesh.creation.box((0.03, 0.04, 0.05))
    open_box.update_faces(np.arange(len(open_box.faces)) >= 6)  # three sides gone: too big a hole to fill
    bad = {"empty": "", "open": open_box.export(file_type="obj"), "flat": "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n"}
    for kind, text in bad.items():
        (src / "B2.obj").write_text(text)
        with pytest.raises(BadMeshError, match="B2.obj"):
            import_egad(src, out, config=FAST, require_all=False, contact_sheet=False)
        assert {path: path.read_bytes() for path in out.rglob("*") if path.is_file()} == before, kind
        assert {entry.name for entry in tmp_path.iterdir()} == {"egad", "out"}, "a staging directory was left"


def _thinner_is_easier(objects: Path, task: str, seed: int) -> tuple[float, float]:
    # A deterministic stand-in for the simulator's trial: success falls with the object's narrowest width.
    width = min(np.ptp(_obj_vertices(objects / task / "visual.obj"), axis=0))
    return float(np.clip(1.0 - width / 0.064, 0, 1)), 1.0


def test_a_measured_grid_orders_letters_by_the_grasp_trial(tmp_path: Path) -> None:
    metadata = generate_object_set(tmp_path, seed=3, candidates=70, config=FAST, tasks=["A2", "D2", "G2"],
                                   measured=MeasuredGrid(_thinner_is_easier, per_column=7), contact_sheet=False)
    success = [metadata.objects[task].perturbed_grasp_success for task in ("A2", "D2", "G2")]
    assert success[0] > success[1] > success[2]
    assert metadata.binning["per_column"] == 7 and len(metadata.binning["trials"]) == 49
    assert metadata.binning["letter_by"] == "perturbed grasp"
    assert ObjectSetMetadata.load(tmp_path) == metadata


def test_letters_by_lifting_poses_store_the_share_measured_on_the_written_objects(tmp_path: Path) -> None:
    """The trial's numbers rank the shortlist; what objects.json stores of each object is the
    ``LiftingPoseCheck``'s measurement of the written object, and no grasp success is made up."""
    measured = MeasuredGrid(_thinner_is_easier, per_column=7, letter_by="lifting poses")
    check = LiftingPoseCheck(lambda objects, task, seed: (0.5 if task == "A2" else 0.25, 1.0))
    metadata = generate_object_set(tmp_path, seed=3, candidates=70, config=FAST, tasks=["A2", "G2"],
                                   measured=measured, lifting_poses=check, contact_sheet=False)
    assert metadata.binning["letter_by"] == "lifting poses"
    assert "share of top-down poses that lift it" in metadata.binning["method"]
    shares = {task: obj.lifting_pose_share for task, obj in metadata.objects.items()}
    assert shares == {"A2": 0.5, "G2": 0.25}
    assert all(obj.perturbed_grasp_success is None for obj in metadata.objects.values())
    with pytest.raises(ValueError, match="unknown letter_by 'luck'"):
        MeasuredGrid(_thinner_is_easier, letter_by="luck")


def test_record_grasp_success(small_set: tuple[Path, ObjectSetMetadata], tmp_path: Path) -> None:
    out, _ = small_set
    shutil.copy(out / "objects.json", tmp_path / "objects.json")
    updated = record_grasp_success(tmp_path, scripted={"A0": 0.9}, perturbed={"G6": 0.25})
    assert (updated.objects["A0"].scripted_grasp_success, updated.objects["A0"].perturbed_grasp_success) == (0.9, None)
    assert (updated.objects["G6"].scripted_grasp_success, updated.objects["G6"].perturbed_grasp_success) == (None, 0.25)
    assert ObjectSetMetadata.load(tmp_path) == updated
    with pytest.raises(KeyError):
        record_grasp_success(tmp_path, perturbed={"B1": 1.0})


# --- the committed set under assets/objects ---------------------------------


def _obj_vertices(path: Path) -> np.ndarray:
    with open(path) as f:
        return np.array([[float(v) for v in line.split()[1:4]] for line in f if line.startswith("v ")])


@pytest.fixture(scope="module")
def committed() -> ObjectSetMetadata:
    return ObjectSetMetadata.load(ASSETS)


def test_committed_set_is_complete_and_small(committed: ObjectSetMetadata) -> None:
    assert sorted(committed.objects) == sorted(ALL_TASKS)
    total = sum(f.stat().st_size for f in ASSETS.rglob("*") if f.is_file())
    assert total < 8 * 1024 * 1024
    assert (ASSETS / "contact_sheet.png").is_file()
    raw = json.loads((ASSETS / "objects.json").read_text())
    assert raw["generator_version"] and raw["seed"] is not None


def test_the_generator_still_draws_the_committed_objects(committed: ObjectSetMetadata) -> None:
    config = GeneratorConfig(envelope=committed.config.get("envelope", "blob"))
    for obj in committed.objects.values():
        params = candidate_params(committed.seed, obj.candidate_index, config).to_dict()
        assert {**params, **obj.generator_params} == params, obj.task


def test_committed_grid_follows_metrics(committed: ObjectSetMetadata) -> None:
    edges = committed.binning["complexity_edges"]
    trials = committed.binning["trials"]  # candidate index -> (perturbed, scripted) success when it was chosen
    for task, obj in committed.objects.items():
        difficulty_row, complexity_col = grid_coordinates(task)
        assert np.searchsorted(edges, obj.complexity, side="right") == complexity_col
        assert trials[str(obj.candidate_index)][1] >= committed.binning["min_scripted_success"]
        if difficulty_row > 0:
            easier = committed.objects["ABCDEFG"[difficulty_row - 1] + task[1]]
            assert trials[str(easier.candidate_index)][0] >= trials[str(obj.candidate_index)][0]
        assert 0.0 < obj.difficulty <= 1.0
        assert 0.05 <= obj.mass <= 0.15
        assert obj.visual_faces <= 1500 and 1 <= obj.hull_count <= 8


def test_committed_urdfs_load_rest_and_fit_gripper(committed: ObjectSetMetadata) -> None:
    client = p.connect(p.DIRECT)
    try:
        p.setGravity(0, 0, -9.81, physicsClientId=client)
        plane = p.createCollisionShape(p.GEOM_PLANE, physicsClientId=client)
        p.createMultiBody(0, plane, physicsClientId=client)
        rng = np.random.default_rng(0)
        for task, obj in committed.objects.items():
            body = p.loadURDF(
                str(ASSETS / task / "model.urdf"),
                basePosition=(0, 0, 0.1),
                flags=p.URDF_USE_INERTIA_FROM_FILE,
                physicsClientId=client,
            )
            # pybullet's AABB includes contact margins, so measure the hulls themselves;
            # they may exceed the visual mesh by about a V-HACD voxel.
            extents = np.sort(np.ptp(_obj_vertices(ASSETS / task / "collision.obj"), axis=0))[::-1]
            assert extents[0] <= GRIPPER_WIDTH + 0.004, task
            assert extents[2] <= GRIPPER_FIT_FRACTION * GRIPPER_WIDTH + 0.004, task
            assert max(obj.extents) <= GRIPPER_WIDTH + 1e-6, task
            assert min(obj.extents) <= GRIPPER_FIT_FRACTION * GRIPPER_WIDTH + 1e-6, task
            info = p.getDynamicsInfo(body, -1, physicsClientId=client)
            assert info[0] == pytest.approx(obj.mass, rel=1e-5)
            principal = np.linalg.eigvalsh(np.asarray(obj.inertia))
            assert np.sort(info[2]) == pytest.approx(principal, rel=1e-3), task
            orientation = p.getQuaternionFromEuler(rng.uniform(-np.pi, np.pi, 3))
            p.resetBasePositionAndOrientation(body, (0, 0, 0.1), orientation, physicsClientId=client)
            for _ in range(720):
                p.stepSimulation(physicsClientId=client)
            linear, angular = p.getBaseVelocity(body, physicsClientId=client)
            position, _ = p.getBasePositionAndOrientation(body, physicsClientId=client)
            assert np.linalg.norm(linear) < 0.01 and np.linalg.norm(angular) < 0.1, task
            assert 0.0 < position[2] < 0.06, task
            p.removeBody(body, physicsClientId=client)
    finally:
        p.disconnect(client)


def test_import_egad_command_names_the_bad_file_and_changes_nothing(tmp_path: Path) -> None:
    src, out = tmp_path / "egad", tmp_path / "out"
    src.mkdir()
    (src / "C3.obj").write_text("")
    result = subprocess.run([sys.executable, "-m", "glocal_app.cli", "assets", "import-egad", str(src), "--partial",
                             "--out", str(out)], capture_output=True, text=True, timeout=120, cwd=REPO)
    assert result.returncode == 1 and "C3.obj: the mesh is empty" in result.stderr
    assert "Traceback" not in result.stderr and not out.exists()

"""Importing EGAD-like meshes (issue 42): a mesh with a non-manifold edge is repaired and the repair recorded,
bad input is refused naming the file with the output unchanged, and a best pose below 80% is a warning for an
imported set (a refusal only when asked, with the measurements kept beside the refused set).

Every mesh is built here with trimesh; none of EGAD's meshes is needed."""

from __future__ import annotations

import json
import subprocess
import sys
from functools import partial
from pathlib import Path

import numpy as np
import pybullet as p
import pytest
import trimesh

from conftest import REPO
from glocal_ros.objects import (
    BadMeshError,
    GeneratorConfig,
    LiftingPoseCheck,
    MissingEgadFilesError,
    ObjectSetMetadata,
    UnliftableObjectError,
    VhacdConfig,
    import_egad,
)
from glocal_ros.objects.pipeline import load_mesh, refused_measurements_path
from glocal_ros.objects.repair import UnrepairableMeshError, edge_use, repair_mesh
from sim_node.grasp_env import GraspEnv
from sim_node.lifting_poses import LiftingPoseSettings, lifting_pose_trial
from test_lifting_poses import low_dome  # a spherical cap that no top-down pose lifts

FAST = GeneratorConfig(resolution=28, coarse_resolution=20, visual_faces=300, grasp_samples=120,
                       vhacd=VhacdConfig(resolution=20_000))
SMALL = LiftingPoseSettings(xy_cells=3, yaw_cells=4, repeats=3)


def pinched_ring(size: float = 40.0) -> trimesh.Trimesh:
    """A square block (``size`` wide, half as tall) with a pentagonal hole whose corner touches the outer
    wall along one vertical edge: that edge is shared by four faces, as in EGAD's B4, B5, C5 and D4. Turned a
    little, so that no face lies on the voxel grid."""
    outline = np.array([(0, 0), (4, 0), (4, 4), (0, 4), (0, 2), (1, 3), (3, 3), (3, 1), (1, 1), (0, 2)], float)
    triangles = np.array([(3, 4, 5), (3, 5, 6), (3, 6, 2), (2, 6, 7), (2, 7, 1), (1, 7, 8), (1, 8, 0), (0, 8, 9)])
    ring = trimesh.creation.extrude_triangulation(outline * size / 4, triangles, size / 2)
    ring.merge_vertices()  # the hole's corner and the wall's vertex at (0, 2) become one
    ring.apply_transform(trimesh.transformations.euler_matrix(0.3, 0.2, 0.1))
    return ring


def edge_touching_boxes(size: float = 20.0) -> trimesh.Trimesh:
    """Two cubes that touch only along one edge: non-manifold there, and two solids, not one."""
    first, second = trimesh.creation.box((size,) * 3), trimesh.creation.box((size,) * 3)
    second.apply_translation((size, size, 0.0))
    boxes = trimesh.util.concatenate([first, second])
    boxes.merge_vertices()
    return boxes


def test_a_mesh_with_a_non_manifold_edge_is_closed_and_its_change_measured() -> None:
    ring = pinched_ring()
    assert edge_use(ring) == (0, 1) and not ring.is_watertight
    filled = ring.copy()
    trimesh.repair.fill_holes(filled)
    assert not filled.is_watertight, "filling holes does not close a pinched edge"

    repaired, repair = repair_mesh(ring)
    assert repaired.is_watertight and len(repaired.split(only_watertight=False)) == 1
    assert repair.non_manifold_edges == 1 and repair.volume_before == pytest.approx(ring.volume, rel=1e-5)
    assert abs(repair.volume_change) < 0.01 and max(map(abs, repair.extent_changes)) < 0.02
    assert repair.volume_after == pytest.approx(repaired.volume, rel=1e-5)
    recorded = repair.to_dict()
    assert recorded["volume_change"] == round(repair.volume_change, 5) and len(recorded["extent_changes"]) == 3
    json.dumps(recorded)  # it goes into objects.json


def test_what_is_not_a_solid_with_a_few_bad_edges_is_not_repaired() -> None:
    with pytest.raises(UnrepairableMeshError, match="not one solid"):
        repair_mesh(edge_touching_boxes())
    open_box = trimesh.creation.box((30.0, 40.0, 50.0))
    open_box.update_faces(np.arange(len(open_box.faces)) >= 6)
    with pytest.raises(UnrepairableMeshError, match="open"):
        repair_mesh(open_box)


def _write_set(src: Path) -> None:
    """A0 a box and B4 the pinched ring, in millimetres as EGAD ships them."""
    src.mkdir()
    trimesh.creation.box((30.0, 30.0, 40.0)).export(src / "A0.obj")
    pinched_ring().export(src / "B4.obj")


def test_the_importer_repairs_records_and_writes_objects_that_load_in_the_sim(tmp_path: Path) -> None:
    src, out = tmp_path / "egad", tmp_path / "out"
    _write_set(src)
    assert load_mesh(src / "A0.obj").repair is None
    metadata = import_egad(src, out, config=FAST, require_all=False, contact_sheet=False)
    assert metadata.objects["A0"].repair is None
    repair = metadata.objects["B4"].repair
    assert repair["non_manifold_edges"] == 1 and abs(repair["volume_change"]) < 0.01
    assert repair["method"].startswith("narrow-band voxel remesh")
    assert ObjectSetMetadata.load(out) == metadata and metadata.warnings is None

    client = p.connect(p.DIRECT)
    try:
        for task in metadata.objects:
            body = p.loadURDF(str(out / task / "model.urdf"), flags=p.URDF_USE_INERTIA_FROM_FILE,
                              physicsClientId=client)
            assert p.getDynamicsInfo(body, -1, physicsClientId=client)[0] == pytest.approx(
                metadata.objects[task].mass, rel=1e-5)
    finally:
        p.disconnect(client)
    env = GraspEnv("B4", objects_dir=out)
    try:
        env.reset(seed=0)
        env.reset(seed=1, options={"task": "A0"})
    finally:
        env.close()


def _snapshot(directory: Path) -> dict[Path, bytes]:
    return {path: path.read_bytes() for path in directory.rglob("*") if path.is_file()}


def test_bad_input_is_refused_naming_the_file_and_the_output_is_unchanged(tmp_path: Path) -> None:
    src, out = tmp_path / "egad", tmp_path / "out"
    src.mkdir()
    trimesh.creation.box((30.0, 30.0, 40.0)).export(src / "A0.obj")
    import_egad(src, out, config=FAST, require_all=False, contact_sheet=False)
    before = _snapshot(out)
    bad = {
        "two solids touching along an edge": (edge_touching_boxes().export(file_type="obj"), "cannot be repaired"),
        "binary junk": (bytes(range(256)) * 8, "B2.obj"),
        "text that is no mesh": ("this is not a mesh\n", "B2.obj"),
    }
    for kind, (content, message) in bad.items():
        target = src / "B2.obj"
        target.write_bytes(content) if isinstance(content, bytes) else target.write_text(content)
        with pytest.raises(BadMeshError, match="B2.obj") as refused:
            import_egad(src, out, config=FAST, require_all=False, contact_sheet=False)
        assert message in str(refused.value), (kind, refused.value)
        assert _snapshot(out) == before, kind
        assert {entry.name for entry in tmp_path.iterdir()} == {"egad", "out"}, "a staging directory was left"
    (src / "B2.obj").unlink()
    (src / "B2.obj").mkdir()  # a name that is there but no file
    with pytest.raises(BadMeshError, match="B2.obj: not a file"):
        import_egad(src, out, config=FAST, require_all=False, contact_sheet=False)
    with pytest.raises(MissingEgadFilesError, match="G6.obj"):
        import_egad(src, out, config=FAST)
    with pytest.raises(MissingEgadFilesError, match="no such directory"):
        import_egad(tmp_path / "nowhere", out, config=FAST, require_all=False)
    assert _snapshot(out) == before


def test_the_import_command_names_an_unrepairable_mesh_and_changes_nothing(tmp_path: Path) -> None:
    src, out = tmp_path / "egad", tmp_path / "out"
    src.mkdir()
    edge_touching_boxes().export(src / "D4.obj")
    result = subprocess.run([sys.executable, "-m", "glocal_app.cli", "assets", "import-egad", str(src), "--partial",
                             "--out", str(out)], capture_output=True, text=True, timeout=120, cwd=REPO)
    assert result.returncode == 1 and "Traceback" not in result.stderr, result.stderr
    assert f"{src / 'D4.obj'}: the mesh is not watertight" in result.stderr and "not one solid" in result.stderr
    assert f"{out} is unchanged" in result.stderr and not out.exists()


def test_a_best_pose_below_the_rule_is_a_warning_for_an_imported_set_and_kept_when_refused(
        tmp_path: Path) -> None:
    src = tmp_path / "egad"
    src.mkdir()
    trimesh.creation.box((0.03, 0.03, 0.04)).export(src / "A0.obj")
    low_dome().export(src / "G1.obj")
    check = LiftingPoseCheck(partial(lifting_pose_trial, settings=SMALL), seed=2, settings=SMALL.to_dict())

    out = tmp_path / "strict"
    with pytest.raises(UnliftableObjectError, match=r"G1 \(best pose lifts it 0% of the time\)") as refused:
        import_egad(src, out, config=FAST, require_all=False, contact_sheet=False, lifting_poses=check,
                    refuse_unliftable=True)
    kept = refused_measurements_path(out)
    assert kept == tmp_path / "strict.refused.json" and str(kept) in str(refused.value)
    assert f"{out} is unchanged" in str(refused.value) and not out.exists()
    measured = json.loads(kept.read_text())
    assert "G1 (best pose lifts it 0% of the time)" in measured["refused"]
    assert measured["objects"]["G1"]["best_pose_success"] == 0.0
    assert measured["objects"]["A0"]["best_pose_success"] >= 0.8 and measured["lifting_poses"]["seed"] == 2

    out = tmp_path / "imported"
    metadata = import_egad(src, out, config=FAST, require_all=False, contact_sheet=False, lifting_poses=check)
    assert metadata.warnings == ["best pose below 80%: G1 (best pose lifts it 0% of the time); kept, as EGAD "
                                 "published it"]
    stored = ObjectSetMetadata.load(out)
    assert stored == metadata and stored.objects["G1"].best_pose_success == 0.0
    assert stored.objects["A0"].best_pose_success == measured["objects"]["A0"]["best_pose_success"], \
        "the same seed measures the same"
    assert not refused_measurements_path(out).exists()


def test_a_novel_object_is_prepared_as_a_set_of_one_from_a_mesh_or_another_sets_object(tmp_path: Path) -> None:
    from glocal_ros.objects.pipeline import prepare_object
    from glocal_ros.paths import objects_dir

    mesh = tmp_path / "crate.obj"
    trimesh.creation.box((30.0, 40.0, 50.0)).export(mesh)
    out = tmp_path / "out"
    metadata = prepare_object(mesh, "crate", out, config=FAST)
    assert ObjectSetMetadata.load(out) == metadata and list(metadata.objects) == ["crate"]
    assert metadata.source == "novel" and metadata.objects["crate"].source_file == str(mesh.resolve())
    assert max(metadata.objects["crate"].extents) == pytest.approx(0.08)  # scaled into the gripper as the set is
    env = GraspEnv("crate@D2", objects_dir=out)
    try:
        env.reset(seed=0)
    finally:
        env.close()

    copied = prepare_object(objects_dir() / "C4", "c4_again", tmp_path / "copy")
    assert copied.objects["c4_again"].difficulty == ObjectSetMetadata.load(objects_dir()).objects["C4"].difficulty
    assert (tmp_path / "copy" / "c4_again" / "collision.obj").read_bytes() == (
        objects_dir() / "C4" / "collision.obj").read_bytes()

    before = _snapshot(out)
    (tmp_path / "empty").mkdir()
    with pytest.raises(BadMeshError, match="not an object directory"):
        prepare_object(tmp_path / "empty", "crate", out)
    with pytest.raises(BadMeshError, match="no such file"):
        prepare_object(tmp_path / "missing.obj", "crate", out)
    with pytest.raises(ValueError, match="collides with grid task A1"):
        prepare_object(mesh, "a1", out)
    assert _snapshot(out) == before

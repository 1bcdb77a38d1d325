"""The 49 grasping objects: a seeded EGAD-style generator, an EGAD importer, metrics.

ROS-free. Main entry points:

- :func:`generate_object_set` writes ``<out_dir>/<TASK>/{model.urdf, visual.obj,
  collision.obj}``, ``objects.json`` and ``contact_sheet.png``;
- :func:`import_egad` builds the same layout from EGAD's ``A0.obj`` .. ``G6.obj``;
- :func:`render_contact_sheet` renders a 7x7 overview of an objects directory;
- :func:`record_grasp_success` stores the simulator's grasp checks in ``objects.json``;
- :func:`measure_lifting_poses` and :func:`record_lifting_poses` measure and store the share of
  top-down poses that lift each object (the simulator's part is ``sim_node.lifting_poses``).

Load a task with ``p.loadURDF(str(objects_dir / task / "model.urdf"),
flags=p.URDF_USE_INERTIA_FROM_FILE)``; the link frame is the object's centre
of mass and its axes are sorted so x is the longest extent and z the shortest.
"""

from glocal_ros.objects.grid import GridAssignment, GridAssignmentError, assign_grid
from glocal_ros.objects.meshing import GRIPPER_FIT_FRACTION, GRIPPER_WIDTH
from glocal_ros.objects.metadata import (
    METADATA_FILE,
    ObjectMetadata,
    ObjectSetMetadata,
    record_grasp_success,
    record_lifting_poses,
)
from glocal_ros.objects.metrics import GraspDifficulty, grasp_difficulty, morphological_complexity
from glocal_ros.objects.physics import FrictionConfig, MassConfig, VhacdConfig
from glocal_ros.objects.pipeline import (
    GENERATOR_VERSION,
    MIN_BEST_POSE_SUCCESS,
    BadMeshError,
    CandidateMetrics,
    GeneratorConfig,
    GraspTrial,
    LiftingPoseCheck,
    LiftingPoseTrial,
    MeasuredGrid,
    MissingEgadFilesError,
    ProgressCallback,
    UnliftableObjectError,
    generate_object_set,
    import_egad,
    measure_lifting_poses,
    never_grasped,
    sample_candidates,
    unliftable,
)
from glocal_ros.objects.render import render_contact_sheet

__all__ = [
    "GENERATOR_VERSION",
    "BadMeshError",
    "GRIPPER_FIT_FRACTION",
    "GRIPPER_WIDTH",
    "METADATA_FILE",
    "MIN_BEST_POSE_SUCCESS",
    "CandidateMetrics",
    "FrictionConfig",
    "GeneratorConfig",
    "GraspTrial",
    "GraspDifficulty",
    "GridAssignment",
    "GridAssignmentError",
    "LiftingPoseCheck",
    "LiftingPoseTrial",
    "MassConfig",
    "MeasuredGrid",
    "MissingEgadFilesError",
    "ObjectMetadata",
    "ObjectSetMetadata",
    "ProgressCallback",
    "UnliftableObjectError",
    "VhacdConfig",
    "assign_grid",
    "generate_object_set",
    "grasp_difficulty",
    "import_egad",
    "measure_lifting_poses",
    "morphological_complexity",
    "never_grasped",
    "record_grasp_success",
    "record_lifting_poses",
    "render_contact_sheet",
    "sample_candidates",
    "unliftable",
]

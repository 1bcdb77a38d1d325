"""How many of the top-down grasps a parallel gripper can make lift the object (issue 31).

EGAD's idea, in this simulator: an object is hard when few of the grasps a
top-down parallel gripper can make actually lift it, and those few lie in
small basins. ``lifting_pose_share`` measures it. A pose is where the TCP
goes down, in the frame of the object as it lies after the env's reset:
x and y over its footprint (the bounding box of its collision points, seen
from above, along its heading) and the gripper's yaw relative to that
heading, in [0, pi) (the gripper is symmetric under a half turn). Each pose
gets one attempt of ``ScriptedGraspPolicy``'s descent, close and lift
(``PoseGraspPolicy``: the scripted controller, aimed at the pose instead of
at the narrowest span, without retries), in an episode of its own with the
env's spawn noise; the share is the fraction of poses that lift the object
to the env's success height.

The poses are a stratified sample: one pose drawn uniformly in each cell of
a ``xy_cells`` x ``xy_cells`` x ``yaw_cells`` grid over (x, y, yaw). The
share alone does not say whether an object stays learnable, so the best
poses are repeated (``repeats`` episodes each, fresh spawns): the scripted
controller's own pose (the narrowest span) and the ``basin_poses`` lifting
poses with the most lifting neighbours on the grid (the middles of the
largest basins). ``best_pose_success`` is the highest of their success
rates; the asset pipeline refuses an object set in which it is below 80%
(``glocal_ros.objects.pipeline.LiftingPoseCheck``). A candidate that lifts
the object in all its repeats ends the search (none can do better).

Everything is a function of the seed (and the task, so that an object's
numbers do not depend on which others are measured with it, or in which
process).

Budget (``LiftingPoseSettings``' defaults): 5 x 5 cells of x, y by 4 of
yaw, 100 poses, and 10 repeats per best-pose candidate. One attempt takes
about 0.05 s of CPU (a pose that does not hold the object ends once the lift
has gone 3 steps without a finger on it, not at the episode's 50 steps), so
an object takes 5.5 to 8 s of CPU (A0, D3, G0, G6 of the committed set, env
start included), and all 49 about 5.5 minutes of CPU: about 3 minutes with
``workers=2`` on 2 free cores. (Those four, with the physics of commit
72c2f8e: shares 24%, 45%, 17%, 20%; the scripted controller's own pose
lifted each in 10 of 10 repeats, so no other candidate was tried.) 100 poses
put a share's standard error at 5 points at most (64 poses gave the same
four within 6 points of these), a fifth of the spread between those
objects; 4 yaw cells, 45 degrees wide, still resolve the quarter turn
between grasping an elongated object across and along it.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from glocal_ros.tasks import task_index
from sim_node.grasp_env import GraspEnv
from sim_node.scripted_grasp import Phase, ScriptedGraspPolicy

# A lift that has gone this many steps without a finger on the object has lost it (or never held it).
_LOST_STEPS = 3


@dataclass(frozen=True)
class ObjectPose:
    """A top-down grasp pose in the frame of the object as it lies."""

    x: float
    """Where the TCP goes down along the object's heading, as a fraction of the footprint (0..1)."""
    y: float
    """The same across the heading (0..1)."""
    yaw: float
    """Gripper yaw minus the object's heading (rad, 0..pi)."""


@dataclass(frozen=True)
class LiftingPoseSettings:
    """The budget of ``lifting_pose_share`` (see the module's docstring for the defaults)."""

    xy_cells: int = 5
    """Cells of the footprint along each of x and y."""
    yaw_cells: int = 4
    """Cells of the yaw range [0, pi)."""
    repeats: int = 10
    """Episodes of each best-pose candidate."""
    basin_poses: int = 2
    """Lifting poses of the largest basins repeated, besides the scripted controller's own."""

    def __post_init__(self) -> None:
        for name in ("xy_cells", "yaw_cells", "repeats"):
            if getattr(self, name) < 1:
                raise ValueError(f"{name} must be at least 1, got {getattr(self, name)}")
        if self.basin_poses < 0:
            raise ValueError(f"basin_poses must be at least 0, got {self.basin_poses}")

    @property
    def poses(self) -> int:
        return self.xy_cells * self.xy_cells * self.yaw_cells

    def to_dict(self) -> dict:
        return asdict(self)


@dataclass(frozen=True)
class LiftingPoses:
    """What ``lifting_pose_share`` measured on one object."""

    share: float
    """Fraction of the sampled poses whose one attempt lifts the object."""
    best_pose_success: float
    """The best candidate pose's success rate over its repeats."""
    best_pose: ObjectPose | None
    """That pose; None when it is the scripted controller's (the narrowest span), or when no candidate
    lifted the object at all."""
    poses: tuple[ObjectPose, ...]
    lifted: tuple[bool, ...]
    """Whether each of ``poses`` lifted the object."""


class PoseGraspPolicy(ScriptedGraspPolicy):
    """``ScriptedGraspPolicy``'s single attempt, aimed at ``pose`` instead of the narrowest span.

    The approach, the descent to half the object's height (or until it stalls
    on the object), the close and the lift are the scripted controller's;
    only the target's x, y and yaw differ.
    """

    def __init__(self, pose: ObjectPose, **kwargs):
        super().__init__(retry=False, **kwargs)
        self.pose = pose

    def grasp_target(self, env: GraspEnv, yaw: float) -> tuple[np.ndarray, float, float]:
        target, _, top = self._grasp_pose(env, yaw)
        position, orientation = env.world.object_pose()
        heading = object_heading(env.world.client.getMatrixFromQuaternion(orientation))
        along = np.array((math.cos(heading), math.sin(heading)))
        across = np.array((-math.sin(heading), math.cos(heading)))
        offsets = (env.world.object_points()[:, :2] - position[:2]) @ np.column_stack((along, across))
        low, high = offsets.min(axis=0), offsets.max(axis=0)
        local = low + np.array((self.pose.x, self.pose.y)) * (high - low)
        target[:2] = position[:2] + local[0] * along + local[1] * across
        # Half a turn is the same grasp: the representative in [-pi/2, pi/2), inside the env's yaw range.
        target_yaw = (heading + self.pose.yaw + math.pi / 2) % math.pi - math.pi / 2
        return target, target_yaw, top


def object_heading(rotation) -> float:
    """The object's heading (rad): its link x axis seen from above, or, when that axis stands nearly
    upright (a tipped-over object), the most horizontal of its axes."""
    matrix = np.asarray(rotation, dtype=float).reshape(3, 3)
    horizontal = np.linalg.norm(matrix[:2], axis=0)
    axis = 0 if horizontal[0] > 0.5 else int(np.argmax(horizontal))
    return math.atan2(matrix[1, axis], matrix[0, axis])


def sample_poses(settings: LiftingPoseSettings, rng: np.random.Generator) -> list[ObjectPose]:
    """One pose drawn uniformly in each cell of the (x, y, yaw) grid, cells in C order (x slowest)."""
    cells = settings.xy_cells
    jitter = rng.random((cells, cells, settings.yaw_cells, 3))
    return [ObjectPose((i + jitter[i, j, k, 0]) / cells, (j + jitter[i, j, k, 1]) / cells,
                       (k + jitter[i, j, k, 2]) / settings.yaw_cells * math.pi)
            for i in range(cells) for j in range(cells) for k in range(settings.yaw_cells)]


def basin_order(lifted: np.ndarray) -> list[int]:
    """Flat indices of the lifting cells of ``lifted`` (x, y, yaw), most lifting neighbours first.

    A cell's neighbours are the up to 26 cells around it, itself counted;
    yaw wraps around (a half turn is the same grasp), x and y do not. Ties
    go to the lower index.
    """
    padded = np.pad(lifted.astype(int), ((1, 1), (1, 1), (0, 0)))
    counts = np.zeros(lifted.shape, dtype=int)
    for dx in (-1, 0, 1):
        for dy in (-1, 0, 1):
            shifted = padded[1 + dx:padded.shape[0] - 1 + dx, 1 + dy:padded.shape[1] - 1 + dy]
            # With fewer than 3 yaw cells, each other cell is a neighbour once.
            for dyaw in ((-1, 0, 1) if lifted.shape[2] >= 3 else range(-(lifted.shape[2] // 2), 1)):
                counts += np.roll(shifted, dyaw, axis=2)
    flat = counts.ravel()
    return sorted(np.flatnonzero(lifted.ravel()).tolist(), key=lambda index: (-flat[index], index))


def attempt(env: GraspEnv, task: str, policy: ScriptedGraspPolicy, seed: int) -> bool:
    """Whether one episode of ``policy`` (without retries) lifts ``task``'s object, from a reset seeded by
    ``seed``; a lift that has gone ``_LOST_STEPS`` steps without a finger on the object ends it early."""
    env.reset(seed=seed, options={"task": task})
    untouched = 0
    while True:
        _, _, terminated, truncated, info = env.step(policy.act(env))
        if terminated or truncated:
            return bool(info["is_success"])
        state = env.grasp_state()
        untouched = untouched + 1 if policy.phase is Phase.LIFT and not (
            state.left_contact or state.right_contact) else 0
        if untouched >= _LOST_STEPS:
            return False


def lifting_pose_share(env: GraspEnv, task: str, seed: int,
                       settings: LiftingPoseSettings = LiftingPoseSettings()) -> LiftingPoses:
    """The share of top-down poses that lift ``task``'s object, and its best pose's success rate (see
    the module's docstring). A function of ``seed`` and ``task``."""
    rng = np.random.default_rng([seed, task_index(task)])
    poses = sample_poses(settings, rng)
    spawns = rng.integers(2**31, size=len(poses) + (1 + settings.basin_poses) * settings.repeats)
    lifted = [attempt(env, task, PoseGraspPolicy(pose), int(spawn)) for pose, spawn in zip(poses, spawns)]
    grid = np.array(lifted).reshape(settings.xy_cells, settings.xy_cells, settings.yaw_cells)
    candidates: list[ObjectPose | None] = [None] + [poses[i] for i in basin_order(grid)[:settings.basin_poses]]
    best_success, best_pose = 0.0, None
    repeat_spawns = spawns[len(poses):].reshape(1 + settings.basin_poses, settings.repeats)
    for candidate, seeds in zip(candidates, repeat_spawns):
        success = sum(attempt(env, task, _one_attempt(candidate), int(spawn)) for spawn in seeds) / settings.repeats
        if success > best_success:
            best_success, best_pose = success, candidate
        if best_success == 1.0:
            break
    return LiftingPoses(share=sum(lifted) / len(lifted), best_pose_success=best_success, best_pose=best_pose,
                        poses=tuple(poses), lifted=tuple(lifted))


def _one_attempt(pose: ObjectPose | None) -> ScriptedGraspPolicy:
    """A single attempt at ``pose``, or at the scripted controller's own pose for None."""
    return ScriptedGraspPolicy(retry=False) if pose is None else PoseGraspPolicy(pose)


def lifting_pose_trial(objects_dir: Path, task: str, seed: int,
                       settings: LiftingPoseSettings = LiftingPoseSettings()) -> tuple[float, float]:
    """(share of lifting poses, best pose's success) of ``task``'s object in ``objects_dir``, in an env of
    its own: the ``glocal_ros.objects.LiftingPoseTrial`` of the asset commands."""
    env = GraspEnv(task, objects_dir=objects_dir)
    try:
        measured = lifting_pose_share(env, task, seed, settings)
    finally:
        env.close()
    return measured.share, measured.best_pose_success

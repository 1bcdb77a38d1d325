"""Gymnasium environment of the paper: a Panda grasps one of 49 objects.

One task is one object (``glocal_ros.tasks``). Each episode the object is
dropped near ``OBJECT_SPOT``, its URDF link frame upright (the generated
assets lie flat in that frame) and turned by a uniformly random yaw; the
agent moves a top-down gripper and succeeds when it lifts the object
``success_height`` above where it settled. Reward is -1 per step.

The object's pose is that of its URDF link frame (for the generated assets,
origin at the centre of mass, axes along its bounding box).

Action (5, float32, [-1, 1]; values outside, infinities included, are
clipped; NaN raises ``ValueError``):

====== ====================================================================
index  meaning
====== ====================================================================
0      gripper: > 0 closes, <= 0 opens (binary command to both fingers)
1      yaw change, times ``rotation_step`` (rad)
2..4   x, y, z change of the TCP, times ``translation_step`` (m, world axes)
====== ====================================================================

Moves are relative to the measured TCP pose and kept inside the workspace:
``workspace_half_width`` around ``OBJECT_SPOT`` in x and y, TCP height between
``min_tcp_height`` and ``max_tcp_height`` above the table, yaw within
``YAW_LIMIT`` of home. A parallel gripper is symmetric under a half turn, so
[-pi/2, pi/2] would reach every grasp; the extra pi/8 on each side means no
object orientation forces a swing across the whole range.

Observation (63, float32, layout ``OBSERVATION_LAYOUT``), positions in metres,
in the world axes with the origin at ``OBJECT_SPOT`` on the table top (see
``OBS_*`` slices):

====== ====================================================================
index  meaning
====== ====================================================================
0..48  one-hot task, bit ``one_hot_bit(task)`` (a novel object's: its proxy's)
49..51 TCP position
52, 53 sin, cos of the gripper yaw
54     gripper opening (0 closed .. 0.08 open)
55..57 object position minus TCP position
58, 59 sin, cos of (object yaw - gripper yaw), the object's yaw being
       the heading of its link x axis: a half turn of the object shows,
       since few objects look the same after one (the gripper does, and
       the policy learns that)
60     object lift: its height above where it settled after the reset
61, 62 left, right finger touches the object (0 or 1)
====== ====================================================================

Every observation is clipped to ``observation_space``: the workspace plus
10 cm for the TCP, 1 m for the object's offset and lift. Only a gripper forced
out of its workspace or an object knocked off the table reaches the bounds.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
import pybullet
from gymnasium import spaces
from pybullet_utils.bullet_client import BulletClient

from glocal_ros.paths import object_urdf, objects_dir as shipped_objects_dir
from glocal_ros.sim_contract import DEFAULT_EPISODE_STEPS, GRASP_ENV_ID
from glocal_ros.spaces import ACTION_DIM, OBS_DIM, PHYSICS_TIMESTEP, SUBSTEPS
from glocal_ros.tasks import NUM_TASKS, PRIOR_TASK, check_task, one_hot_bit
from sim_node.grasp_world import OBJECT_SPOT, TABLE_TOP_Z, GraspWorld
from sim_node.panda_robot import FINGER_MAX_POSITION, JOINT_NAMES, yaw_of
from sim_node.physics_client import PhysicsClient

OBS_TASK = slice(0, NUM_TASKS)
OBS_GRIPPER_POSITION = slice(49, 52)
OBS_GRIPPER_YAW = slice(52, 54)
OBS_GRIPPER_OPENING = 54
OBS_OBJECT_RELATIVE_POSITION = slice(55, 58)
OBS_OBJECT_RELATIVE_YAW = slice(58, 60)
OBS_OBJECT_LIFT = 60
OBS_FINGER_CONTACTS = slice(61, 63)

YAW_LIMIT = 5 * math.pi / 8
"""Gripper yaw range (rad, either side of home); joint 7's limits allow about 2.18."""
_RENDER_WIDTH, _RENDER_HEIGHT = 320, 240
_OBS_MARGIN = 0.1
# Object offsets beyond a metre only occur once it has been knocked off the table.
_OBS_OBJECT_REACH = 1.0


@dataclass(frozen=True)
class GraspEnvConfig:
    """Parameters of ``GraspEnv``; defaults follow the verified probe setup."""

    max_steps: int = DEFAULT_EPISODE_STEPS
    """Episode length T: the episode truncates after this many steps."""
    substeps: int = SUBSTEPS
    """Physics steps per env step."""
    timestep: float = PHYSICS_TIMESTEP
    """Physics step (s)."""
    translation_step: float = 0.02
    """TCP move for an action component of 1 (m)."""
    rotation_step: float = 0.2
    """Yaw change for an action component of 1 (rad)."""
    success_height: float = 0.1
    """Lift of the object above where it settled that counts as success (m)."""
    spawn_jitter: float = 0.05
    """Objects spawn uniformly within this distance of ``OBJECT_SPOT`` in x and in y (m)."""
    settle_substeps: int = 48
    """Physics steps the dropped object settles, at least, before the first observation."""
    max_settle_substeps: int = 240
    """Physics steps after which an object still moving (tipping over) is left as it is."""
    workspace_half_width: float = 0.15
    """The TCP stays within this distance of ``OBJECT_SPOT`` in x and in y (m)."""
    min_tcp_height: float = 0.012
    """Lowest TCP height above the table (m); the fingertips are 1.1 cm below the TCP."""
    max_tcp_height: float = 0.3
    """Highest TCP height above the table (m)."""

    def __post_init__(self) -> None:
        for name in ("max_steps", "substeps"):
            if getattr(self, name) < 1:
                raise ValueError(f"{name} must be at least 1, got {getattr(self, name)}")
        positive = ("timestep", "translation_step", "rotation_step", "success_height", "workspace_half_width")
        for name in positive:
            if not getattr(self, name) > 0:
                raise ValueError(f"{name} must be positive, got {getattr(self, name)}")
        if self.spawn_jitter < 0 or not 0 <= self.settle_substeps <= self.max_settle_substeps:
            raise ValueError("need spawn_jitter >= 0 and 0 <= settle_substeps <= max_settle_substeps")
        if not 0 <= self.min_tcp_height < self.max_tcp_height:
            raise ValueError("need 0 <= min_tcp_height < max_tcp_height")


@dataclass(frozen=True)
class GraspState:
    """What the gripper and the object are doing, as of the latest reset or step."""

    left_contact: bool
    right_contact: bool
    gripper_opening: float
    """Distance between the finger pads (m)."""
    object_lift: float
    """Height of the object above where it settled after the reset (m)."""
    step: int
    """Steps taken in the current episode."""


def _observation_bounds(config: GraspEnvConfig) -> tuple[np.ndarray, np.ndarray]:
    low = np.zeros(OBS_DIM, dtype=np.float32)
    high = np.ones(OBS_DIM, dtype=np.float32)
    # The TCP tracks targets inside the workspace to within millimetres; the
    # margin covers an arm pushed by contacts.
    reach = config.workspace_half_width + _OBS_MARGIN
    low[OBS_GRIPPER_POSITION] = (-reach, -reach, config.min_tcp_height - _OBS_MARGIN)
    high[OBS_GRIPPER_POSITION] = (reach, reach, config.max_tcp_height + _OBS_MARGIN)
    low[OBS_GRIPPER_YAW] = -1.0
    high[OBS_GRIPPER_OPENING] = 2 * FINGER_MAX_POSITION
    low[OBS_OBJECT_RELATIVE_POSITION] = -_OBS_OBJECT_REACH
    high[OBS_OBJECT_RELATIVE_POSITION] = _OBS_OBJECT_REACH
    low[OBS_OBJECT_RELATIVE_YAW] = -1.0
    low[OBS_OBJECT_LIFT] = -_OBS_OBJECT_REACH
    high[OBS_OBJECT_LIFT] = _OBS_OBJECT_REACH
    return low, high


class GraspEnv(gym.Env[np.ndarray, np.ndarray]):
    """Grasp the object of one task; the task can change at every reset.

    :param task: the task (object) of the first episode, ``A0`` .. ``G6``, or a novel object's
        ``NAME@PROXY`` (``glocal_ros.tasks``).
    :param objects_dir: holds ``<task>/model.urdf`` for every task used;
        defaults to the package's ``assets/objects``.
    :param config: parameters, ``GraspEnvConfig()`` when omitted.
    :param render_mode: ``None``, ``"human"`` (PyBullet GUI; one per process)
        or ``"rgb_array"``.
    :raises UnknownTaskError: when ``task`` is neither on the A0..G6 grid nor a novel task.
    :raises FileNotFoundError: when the task's URDF is missing.

    ``world`` (a ``GraspWorld``) exposes the simulator's privileged state,
    e.g. to ``ScriptedGraspPolicy``.
    """

    metadata = {"render_modes": ["human", "rgb_array"], "render_fps": 24}
    """``render_fps`` is the env step rate; each instance sets it from its config."""

    def __init__(
        self,
        task: str = PRIOR_TASK,
        objects_dir: str | Path | None = None,
        config: GraspEnvConfig | None = None,
        render_mode: str | None = None,
    ):
        check_task(task)
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            modes = self.metadata["render_modes"]
            raise ValueError(f"render_mode must be one of {modes} or None, got {render_mode!r}")
        self.config = config if config is not None else GraspEnvConfig()
        step_duration = self.config.substeps * self.config.timestep
        self.metadata = {**self.metadata, "render_fps": round(1.0 / step_duration)}
        self.objects_dir = Path(objects_dir) if objects_dir is not None else shipped_objects_dir()
        self.render_mode = render_mode
        self.action_space = spaces.Box(-1.0, 1.0, shape=(ACTION_DIM,), dtype=np.float32)
        low, high = _observation_bounds(self.config)
        self.observation_space = spaces.Box(low, high, dtype=np.float32)

        self._client: BulletClient | None = PhysicsClient(
            connection_mode=pybullet.GUI if render_mode == "human" else pybullet.DIRECT
        )
        try:
            self.world = GraspWorld(self._client, self.config.timestep)
            self.world.load_object(task, self._urdf_path(task))
        except BaseException:
            self.close()
            raise
        if render_mode == "human":
            self._client.configureDebugVisualizer(pybullet.COV_ENABLE_GUI, 0)
            self._client.resetDebugVisualizerCamera(0.9, 50.0, -35.0, (*OBJECT_SPOT, TABLE_TOP_Z))
        self._task = task
        self._steps = 0
        self._needs_reset = True
        self._state: GraspState | None = None
        self._origin = np.array((*OBJECT_SPOT, TABLE_TOP_Z))
        self._workspace_low = self._origin + (
            -self.config.workspace_half_width,
            -self.config.workspace_half_width,
            self.config.min_tcp_height,
        )
        self._workspace_high = self._origin + (
            self.config.workspace_half_width,
            self.config.workspace_half_width,
            self.config.max_tcp_height,
        )

    @property
    def task(self) -> str:
        """The task of the current episode."""
        return self._task

    @property
    def joint_names(self) -> list[str]:
        """The 7 arm and 2 finger joints, in the order of ``joint_positions``."""
        return list(JOINT_NAMES)

    def joint_positions(self) -> np.ndarray:
        """Current positions of ``joint_names`` (rad; m for the fingers)."""
        return self.world.robot.joint_positions()

    def object_pose(self) -> tuple[np.ndarray, np.ndarray]:
        """Position (m) and orientation (quaternion xyzw) of the object's URDF link frame, world frame."""
        return self.world.object_pose()

    def link_poses(self) -> dict[str, tuple[tuple[float, ...], tuple[float, ...]]]:
        """World pose (position, quaternion xyzw) of each of the robot's URDF links, by name."""
        return self.world.robot.link_poses()

    def grasp_state(self) -> GraspState:
        """Contacts, opening and lift as of the latest reset or step (no physics queries)."""
        if self._state is None:
            raise RuntimeError("call reset() before grasp_state()")
        return self._state

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[np.ndarray, dict[str, Any]]:
        """Start an episode: robot home, object dropped at a random pose.

        :param options: ``{"task": "B3"}`` switches the object for this and
            later episodes; other keys raise ``ValueError``.
        """
        super().reset(seed=seed)
        task = self._task
        if options:
            unknown = set(options) - {"task"}
            if unknown:
                raise ValueError(f"unknown reset options {sorted(unknown)}; only 'task' is accepted")
            task = options.get("task", task)
            check_task(task)
        if task != self.world.object.task:
            self.world.load_object(task, self._urdf_path(task))
        self._task = task
        jitter = self.config.spawn_jitter
        dx, dy = self.np_random.uniform(-jitter, jitter, size=2)
        yaw = self.np_random.uniform(-math.pi, math.pi)
        x, y = OBJECT_SPOT[0] + dx, OBJECT_SPOT[1] + dy
        self.world.reset(x, y, yaw, self.config.settle_substeps, self.config.max_settle_substeps)
        self._steps = 0
        self._needs_reset = False
        observation = self._observe()
        return observation, {"is_success": False, "task": task}

    def step(self, action: np.ndarray) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        """Apply one action for ``substeps`` physics steps.

        ``info`` holds ``is_success`` (the object is lifted; the episode
        terminates) and ``task``.

        :raises ValueError: when the action does not have 5 numbers or holds NaN.
        """
        if self._needs_reset:
            raise RuntimeError("call reset() before step()")
        command = np.asarray(action, dtype=np.float64)
        if command.shape != (ACTION_DIM,):
            raise ValueError(f"action must have shape ({ACTION_DIM},), got {command.shape}")
        if np.isnan(command).any():
            raise ValueError(f"action contains NaN: {command.tolist()}")
        command = np.clip(command, -1.0, 1.0)

        tcp, yaw = self.world.robot.tcp_pose()
        target = tcp + command[2:5] * self.config.translation_step
        target = np.clip(target, self._workspace_low, self._workspace_high)
        target_yaw = float(np.clip(yaw + command[1] * self.config.rotation_step, -YAW_LIMIT, YAW_LIMIT))
        self.world.robot.command(target, target_yaw, close=bool(command[0] > 0))
        self.world.step(self.config.substeps)
        self._steps += 1

        observation = self._observe()
        success = self._state.object_lift > self.config.success_height
        truncated = not success and self._steps >= self.config.max_steps
        return observation, -1.0, success, truncated, {"is_success": success, "task": self._task}

    def render(self) -> np.ndarray | None:
        """An RGB frame in ``"rgb_array"`` mode; the GUI draws itself in ``"human"`` mode."""
        if self.render_mode == "rgb_array":
            return self.world.camera_image(_RENDER_WIDTH, _RENDER_HEIGHT)
        return None

    def close(self) -> None:
        if self._client is not None:
            self._client.disconnect()
            self._client = None

    def _urdf_path(self, task: str) -> Path:
        return object_urdf(self.objects_dir, task)

    def _observe(self) -> np.ndarray:
        robot = self.world.robot
        tcp, yaw = robot.tcp_pose()
        opening = robot.gripper_opening()
        position, orientation = self.world.object_pose()
        lift = self.world.object_lift(position)
        left, right = self.world.finger_contacts()
        relative_yaw = yaw_of(tuple(orientation)) - yaw
        self._state = GraspState(left, right, opening, lift, self._steps)

        observation = np.zeros(OBS_DIM, dtype=np.float64)
        observation[one_hot_bit(self._task)] = 1.0
        observation[OBS_GRIPPER_POSITION] = tcp - self._origin
        observation[OBS_GRIPPER_YAW] = (math.sin(yaw), math.cos(yaw))
        observation[OBS_GRIPPER_OPENING] = opening
        observation[OBS_OBJECT_RELATIVE_POSITION] = position - tcp
        observation[OBS_OBJECT_RELATIVE_YAW] = (math.sin(relative_yaw), math.cos(relative_yaw))
        observation[OBS_OBJECT_LIFT] = lift
        observation[OBS_FINGER_CONTACTS] = (left, right)
        observation = np.clip(observation, self.observation_space.low, self.observation_space.high)
        return observation.astype(np.float32)


if GRASP_ENV_ID not in gym.registry:
    gym.register(id=GRASP_ENV_ID, entry_point=GraspEnv)

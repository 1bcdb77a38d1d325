"""A scripted top-down grasp that reads the simulator's privileged state.

It proves objects graspable (``scripted_success_rate``) and provides
demonstrations for the A0 prior (``ScriptedGraspPolicy.act``). It acts in the
same 5-dim action space as an agent, so its transitions can go straight into a
replay buffer.
"""

from __future__ import annotations

import enum
from pathlib import Path
from typing import Callable, Sequence

import gymnasium as gym
import numpy as np

from sim_node.grasp_env import YAW_LIMIT, GraspEnv, GraspState
from sim_node.grasp_world import TABLE_TOP_Z
from sim_node.panda_robot import FINGERTIP_DEPTH

# The gripper's yaw range in 5 degree steps.
_YAW_CANDIDATES = np.linspace(-YAW_LIMIT, YAW_LIMIT, 46)
# At yaw psi the fingers close along (sin psi, -cos psi) and sit along (cos psi, sin psi).
_CLOSING_DIRECTIONS = np.stack((np.sin(_YAW_CANDIDATES), -np.cos(_YAW_CANDIDATES)))
_FINGER_DIRECTIONS = np.stack((np.cos(_YAW_CANDIDATES), np.sin(_YAW_CANDIDATES)))
_WIDTH_SLACK = 0.003
# Gripper opening (m) counted as open before a close starts; fully open is 0.08.
_OPEN = 0.075


class Phase(enum.Enum):
    """Where ``ScriptedGraspPolicy`` is in its grasp."""

    APPROACH = "approach"
    CLOSE = "close"
    LIFT = "lift"


class ScriptedGraspPolicy:
    """Approach, close, lift: align the fingers across the object's narrowest span.

    APPROACH opens the fingers and moves the TCP over the middle of the
    object's narrowest horizontal span, turned across it, staying
    ``hover_clearance`` above the object until aligned, then descends to the
    grasp height (half the object's height, not below the env's lowest TCP
    height). CLOSE holds still for ``close_steps`` steps while the fingers
    close; LIFT raises the TCP. A close that ends without touching the object,
    or a lift that loses it, starts a new approach.

    The phase restarts whenever the env is at step 0 of an episode, so one
    policy serves consecutive episodes.

    :param close_steps: env steps given to the fingers to close.
    :param position_tolerance: how close (m) the TCP must be to the grasp pose before closing.
    :param yaw_tolerance: how close (rad) the gripper yaw must be before closing.
    :param hover_clearance: TCP height above the object's top while not yet aligned (m).
    """

    def __init__(
        self,
        close_steps: int = 3,
        position_tolerance: float = 0.004,
        yaw_tolerance: float = 0.05,
        hover_clearance: float = 0.03,
    ):
        self.close_steps = close_steps
        self.position_tolerance = position_tolerance
        self.yaw_tolerance = yaw_tolerance
        self.hover_clearance = hover_clearance
        self.phase = Phase.APPROACH
        self._steps_in_phase = 0

    def act(self, env: gym.Env) -> np.ndarray:
        """The action for ``env``'s current state (``env`` may be wrapped)."""
        grasp_env: GraspEnv = env.unwrapped
        state = grasp_env.grasp_state()
        touching = state.left_contact or state.right_contact
        if state.step == 0:
            self._enter(Phase.APPROACH)
        elif self.phase is Phase.CLOSE and self._steps_in_phase >= self.close_steps:
            self._enter(Phase.LIFT if touching else Phase.APPROACH)
        elif self.phase is Phase.LIFT and not touching:
            self._enter(Phase.APPROACH)

        action = self._approach(grasp_env, state) if self.phase is Phase.APPROACH else None
        if action is None:
            if self.phase is Phase.APPROACH:
                self._enter(Phase.CLOSE)
            rise = 1.0 if self.phase is Phase.LIFT else 0.0
            action = np.array((1.0, 0.0, 0.0, 0.0, rise), dtype=np.float32)
        self._steps_in_phase += 1
        return action

    def _enter(self, phase: Phase) -> None:
        self.phase = phase
        self._steps_in_phase = 0

    def _approach(self, env: GraspEnv, state: GraspState) -> np.ndarray | None:
        """The next approach move, or None once at the grasp pose with the fingers open."""
        tcp, yaw = env.world.robot.tcp_pose()
        target, target_yaw, top = self._grasp_pose(env, yaw)
        aligned = (
            np.linalg.norm(target[:2] - tcp[:2]) < self.position_tolerance
            and abs(target_yaw - yaw) < self.yaw_tolerance
        )
        if not aligned:
            target[2] = max(target[2], top + self.hover_clearance)
        elif abs(target[2] - tcp[2]) < self.position_tolerance and state.gripper_opening > _OPEN:
            return None
        action = np.empty(5, dtype=np.float32)
        action[0] = -1.0
        action[1] = (target_yaw - yaw) / env.config.rotation_step
        action[2:5] = (target - tcp) / env.config.translation_step
        return np.clip(action, -1.0, 1.0)

    @staticmethod
    def _grasp_pose(env: GraspEnv, current_yaw: float) -> tuple[np.ndarray, float, float]:
        """TCP position and yaw that put the fingers across the object's narrowest span, and its top.

        Spans are measured on the object's collision vertices above the
        fingertips at the grasp height. Among yaws whose span is within
        ``_WIDTH_SLACK`` of the narrowest, the one nearest the current yaw
        wins, so near-symmetric objects do not make the gripper swing between
        equivalent grasps.
        """
        points = env.world.object_points()
        top = float(points[:, 2].max())
        height = TABLE_TOP_Z + max((top - TABLE_TOP_Z) / 2, env.config.min_tcp_height)
        horizontal = points[points[:, 2] >= height - FINGERTIP_DEPTH, :2]
        across = horizontal @ _CLOSING_DIRECTIONS
        spans = across.max(axis=0) - across.min(axis=0)
        candidates = np.flatnonzero(spans <= spans.min() + _WIDTH_SLACK)
        best = candidates[np.argmin(np.abs(_YAW_CANDIDATES[candidates] - current_yaw))]
        along = horizontal @ _FINGER_DIRECTIONS[:, best]
        center = (across[:, best].max() + across[:, best].min()) / 2 * _CLOSING_DIRECTIONS[:, best] + (
            along.max() + along.min()
        ) / 2 * _FINGER_DIRECTIONS[:, best]
        return np.array((*center, height)), float(_YAW_CANDIDATES[best]), top


def scripted_success_rate(env: gym.Env, task: str, episodes: int, seed: int | None = None) -> float:
    """Fraction of ``episodes`` in which ``ScriptedGraspPolicy`` lifts ``task``'s object.

    The first reset is seeded with ``seed``; later ones continue its random stream.
    """
    if episodes < 1:
        raise ValueError(f"episodes must be at least 1, got {episodes}")
    policy = ScriptedGraspPolicy()
    successes = 0
    for episode in range(episodes):
        env.reset(seed=seed if episode == 0 else None, options={"task": task})
        while True:
            _, _, terminated, truncated, info = env.step(policy.act(env))
            if terminated or truncated:
                successes += bool(info["is_success"])
                break
    return successes / episodes


def graspability(
    objects_dir: Path, tasks: Sequence[str], episodes: int, seed: int = 0,
    progress: Callable[[str, float], None] | None = None,
) -> dict[str, float]:
    """Scripted success rate of every task's object, one env reused for all (seeded per task)."""
    env = GraspEnv(tasks[0], objects_dir=objects_dir)
    try:
        rates = {}
        for offset, task in enumerate(tasks):
            rates[task] = scripted_success_rate(env, task, episodes, seed=seed + offset)
            if progress is not None:
                progress(task, rates[task])
        return rates
    finally:
        env.close()

"""A scripted top-down grasp that reads the simulator's privileged state.

It proves objects graspable (``scripted_success_rate``) and provides
demonstrations for the A0 prior (``ScriptedGraspPolicy.act``). It acts in the
same 5-dim action space as an agent, so its transitions can go straight into a
replay buffer.

Off by a ``GraspError`` and without retries, it measures how forgiving an
object is (``perturbed_success_rate``): a learning policy does not find the
narrowest span to the millimetre, and an object that only a precise grasp
lifts is a hard one. ``GraspErrors`` is the spread of those errors; the
choice of ranges is the project's (the paper measures difficulty by the
geometric metric alone): up to 1.5 cm off the span's middle in any
direction, 15 degrees off its yaw, and 0.5 cm lower to 1.5 cm higher.
"""

from __future__ import annotations

import enum
import math
from dataclasses import dataclass
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
# A descent that gains less than this (m) per step for this many steps is blocked (a finger on the
# object): the policy closes where it is.
_STALL_DESCENT = 0.0005
_STALL_STEPS = 2


@dataclass(frozen=True)
class GraspError:
    """How far a grasp is off the scripted one, in the grasp's frame."""

    across: float = 0.0
    """Offset along the fingers' closing direction (m)."""
    along: float = 0.0
    """Offset along the fingers, across the closing direction (m)."""
    yaw: float = 0.0
    """Yaw offset (rad)."""
    height: float = 0.0
    """Offset of the grasp height (m); the TCP stays at or above the env's lowest height."""


@dataclass(frozen=True)
class GraspErrors:
    """The spread of ``GraspError``: uniform in a disc, in an angle and in a height range."""

    max_offset: float = 0.015
    max_yaw: float = math.radians(15)
    lowest: float = -0.005
    highest: float = 0.015

    def sample(self, rng: np.random.Generator) -> GraspError:
        radius = self.max_offset * math.sqrt(rng.random())  # uniform over the disc's area
        direction = rng.uniform(-math.pi, math.pi)
        return GraspError(across=radius * math.cos(direction), along=radius * math.sin(direction),
                          yaw=float(rng.uniform(-self.max_yaw, self.max_yaw)),
                          height=float(rng.uniform(self.lowest, self.highest)))


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
    height) or until its descent stalls on the object. CLOSE holds still
    for ``close_steps`` steps while the fingers close; LIFT raises the TCP. A close that ends without touching the object,
    or a lift that loses it, starts a new approach.

    The phase restarts whenever the env is at step 0 of an episode, so one
    policy serves consecutive episodes.

    :param close_steps: env steps given to the fingers to close.
    :param position_tolerance: how close (m) the TCP must be to the grasp pose before closing.
    :param yaw_tolerance: how close (rad) the gripper yaw must be before closing.
    :param hover_clearance: TCP height above the object's top while not yet aligned (m).
    :param error: how far the grasp pose is off the narrowest span's (none by default).
    :param retry: whether a missed close or a lost lift starts a new approach; without,
        the policy makes one attempt: the grasp pose is fixed once the gripper is aligned
        over it (the object may be pushed during the descent), it closes once and lifts
        whatever it holds.
    """

    def __init__(
        self,
        close_steps: int = 3,
        position_tolerance: float = 0.004,
        yaw_tolerance: float = 0.05,
        hover_clearance: float = 0.03,
        error: GraspError = GraspError(),
        retry: bool = True,
    ):
        self.close_steps = close_steps
        self.position_tolerance = position_tolerance
        self.yaw_tolerance = yaw_tolerance
        self.hover_clearance = hover_clearance
        self.error = error
        self.retry = retry
        self._enter(Phase.APPROACH)

    def act(self, env: gym.Env) -> np.ndarray:
        """The action for ``env``'s current state (``env`` may be wrapped)."""
        grasp_env: GraspEnv = env.unwrapped
        state = grasp_env.grasp_state()
        touching = state.left_contact or state.right_contact
        if state.step == 0:
            self._enter(Phase.APPROACH)
        elif self.phase is Phase.CLOSE and self._steps_in_phase >= self.close_steps:
            self._enter(Phase.LIFT if touching or not self.retry else Phase.APPROACH)
        elif self.phase is Phase.LIFT and not touching and self.retry:
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
        self._last_height: float | None = None
        self._stalled_steps = 0
        self._committed: tuple[np.ndarray, float, float] | None = None

    def _approach(self, env: GraspEnv, state: GraspState) -> np.ndarray | None:
        """The next approach move, or None once at the grasp pose with the fingers open."""
        tcp, yaw = env.world.robot.tcp_pose()
        if self._committed is not None:
            target, target_yaw, top = self._committed
            target = target.copy()
        else:
            target, target_yaw, top = self.grasp_target(env, yaw)
        aligned = (
            np.linalg.norm(target[:2] - tcp[:2]) < self.position_tolerance
            and abs(target_yaw - yaw) < self.yaw_tolerance
        )
        if aligned and not self.retry and self._committed is None:
            # One attempt: from here the descent goes to this pose, wherever the fingers push the object.
            self._committed = (target.copy(), target_yaw, top)
        stalled = aligned and self._last_height is not None and self._last_height - tcp[2] < _STALL_DESCENT
        self._stalled_steps = self._stalled_steps + 1 if stalled else 0
        self._last_height = float(tcp[2]) if aligned else None
        if not aligned:
            target[2] = max(target[2], top + self.hover_clearance)
        elif state.gripper_opening > _OPEN and (abs(target[2] - tcp[2]) < self.position_tolerance
                                                or self._stalled_steps >= _STALL_STEPS):
            return None
        action = np.empty(5, dtype=np.float32)
        action[0] = -1.0
        action[1] = (target_yaw - yaw) / env.config.rotation_step
        action[2:5] = (target - tcp) / env.config.translation_step
        return np.clip(action, -1.0, 1.0)

    def grasp_target(self, env: GraspEnv, yaw: float) -> tuple[np.ndarray, float, float]:
        """Where the approach goes: TCP position and yaw, and the object's top, given the gripper's ``yaw``.

        Here the narrowest span's pose (``_grasp_pose``) off by ``self.error`` (offsets in the grasp's
        frame); a subclass that grasps elsewhere overrides it (``sim_node.lifting_poses.PoseGraspPolicy``).
        """
        target, target_yaw, top = self._grasp_pose(env, yaw - self.error.yaw)
        closing = np.array((math.sin(target_yaw), -math.cos(target_yaw)))
        fingers = np.array((math.cos(target_yaw), math.sin(target_yaw)))
        target[:2] += self.error.across * closing + self.error.along * fingers
        target[2] = max(target[2] + self.error.height, TABLE_TOP_Z + env.config.min_tcp_height)
        return target, float(np.clip(target_yaw + self.error.yaw, -YAW_LIMIT, YAW_LIMIT)), top

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
    policy = ScriptedGraspPolicy()
    return _success_rate(env, task, episodes, seed, lambda: policy)


def perturbed_success_rate(env: gym.Env, task: str, episodes: int, seed: int,
                           errors: GraspErrors = GraspErrors()) -> float:
    """Fraction of ``episodes`` in which one close of ``ScriptedGraspPolicy``, off by an error drawn from
    ``errors``, lifts ``task``'s object. Episodes and errors are functions of ``seed``."""
    rng = np.random.default_rng([seed, 1])
    return _success_rate(env, task, episodes, seed,
                         lambda: ScriptedGraspPolicy(error=errors.sample(rng), retry=False))


def _success_rate(env: gym.Env, task: str, episodes: int, seed: int | None,
                  episode_policy: Callable[[], ScriptedGraspPolicy]) -> float:
    """Fraction of ``episodes`` in which ``episode_policy()``, asked anew each episode, lifts the object."""
    if episodes < 1:
        raise ValueError(f"episodes must be at least 1, got {episodes}")
    successes = 0
    for episode in range(episodes):
        policy = episode_policy()
        env.reset(seed=seed if episode == 0 else None, options={"task": task})
        while True:
            _, _, terminated, truncated, info = env.step(policy.act(env))
            if terminated or truncated:
                successes += bool(info["is_success"])
                break
    return successes / episodes


def grasp_trial(objects_dir: Path, task: str, seed: int, perturbed_episodes: int = 40,
                scripted_episodes: int = 20, errors: GraspErrors = GraspErrors()) -> tuple[float, float]:
    """(perturbed-grasp success, scripted-grasp success) of ``task``'s object in ``objects_dir``: the
    ``glocal_ros.objects.GraspTrial`` that generates a measured grid."""
    env = GraspEnv(task, objects_dir=objects_dir)
    try:
        return (perturbed_success_rate(env, task, perturbed_episodes, seed, errors),
                scripted_success_rate(env, task, scripted_episodes, seed))
    finally:
        env.close()


def graspability(
    objects_dir: Path, tasks: Sequence[str], episodes: int, seed: int = 0,
    progress: Callable[[str, float], None] | None = None, errors: GraspErrors | None = None,
) -> dict[str, float]:
    """Success rate of every task's object, one env reused for all (seeded per task): of the scripted grasp,
    or with ``errors`` of ``perturbed_success_rate``."""
    env = GraspEnv(tasks[0], objects_dir=objects_dir)
    try:
        rates = {}
        for offset, task in enumerate(tasks):
            rates[task] = (scripted_success_rate(env, task, episodes, seed=seed + offset) if errors is None
                           else perturbed_success_rate(env, task, episodes, seed + offset, errors))
            if progress is not None:
                progress(task, rates[task])
        return rates
    finally:
        env.close()

"""N grasp envs stepped in lockstep, with automatic reset and episode logs.

This is the sim node without ROS, a ``glocal_ros.sim_contract.BatchStepper``:
``reset`` and ``step`` take and return whole batches, validate their input (``ValueError`` with a message a user can
act on), and hand back every episode that finished so that the node can
publish it. Envs reset automatically when their episode ends, as in a
stable-baselines3 VecEnv; the last observation comes back separately.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass
from typing import TYPE_CHECKING, Callable, Protocol, Sequence

import numpy as np

from glocal_ros.sim_contract import PHASE_EVAL, PHASE_TRAIN, PHASES, UNSEEDED, EpisodeLog, FinishStep, StepBatch
from glocal_ros.tasks import check_task

if TYPE_CHECKING:  # importing the batch must not load pybullet (workers and tests make their own envs)
    from sim_node.grasp_env import GraspState

#: float32 rounding of a tanh-squashed action can overshoot 1 by an ulp or so.
ACTION_TOLERANCE = 1e-5


class BatchEnv(Protocol):
    """What the batch needs of an env: Gymnasium's API plus the joint state."""

    observation_space: object
    action_space: object
    joint_names: list[str]

    def reset(self, *, seed: int | None = None, options: dict | None = None) -> tuple[np.ndarray, dict]: ...

    def step(self, action: np.ndarray) -> tuple[np.ndarray, float, bool, bool, dict]: ...

    def joint_positions(self) -> np.ndarray: ...

    def object_pose(self) -> tuple[np.ndarray, np.ndarray]: ...

    def link_poses(self) -> dict[str, tuple[tuple[float, ...], tuple[float, ...]]]: ...

    def grasp_state(self) -> GraspState: ...

    def close(self) -> None: ...


@dataclass
class EnvSnapshot:
    """One env's state for viewers."""

    task: str
    joint_positions: np.ndarray
    object_position: np.ndarray
    object_orientation: np.ndarray  # quaternion x, y, z, w
    grasp: GraspState
    lifted: bool  # lifted above the success height
    link_poses: dict[str, tuple[tuple[float, ...], tuple[float, ...]]]  # robot link -> world (position, xyzw)


def normalize_reset(
    num_envs: int, env_indices: Sequence[int], tasks: Sequence[str], seeds: Sequence[int], phase: int
) -> tuple[list[int], list[str | None], list[int]]:
    """Check a reset request; one task (None = keep) and one seed per reset env, in reset order."""
    indices = _indices(num_envs, env_indices)
    if len(seeds) == 1:
        # One base seed for the batch, as Gymnasium's vector envs do: env k of the reset gets seed + k.
        seeds = [int(seeds[0]) + k for k in range(len(indices))]
    per_env_tasks = _per_env(list(tasks), len(indices), "tasks", default=None)
    per_env_seeds = _per_env([int(s) for s in seeds], len(indices), "seeds", default=UNSEEDED)
    for task in per_env_tasks:
        if task is not None:
            check_task(task)
    _check_phase(phase)
    return indices, per_env_tasks, per_env_seeds


def normalize_step(
    num_envs: int, action_dim: int, actions: np.ndarray, next_tasks: Sequence[str], phase: int,
    env_indices: Sequence[int] = (),
) -> tuple[list[int], np.ndarray, list[str]]:
    """Check a step request; the envs it steps (all when ``env_indices`` is empty), their actions as
    ``(stepped, action_dim)`` in [-1, 1], and one next task per stepped env ("" = keep)."""
    indices = _indices(num_envs, env_indices)
    stepped = len(indices)
    actions = np.asarray(actions, dtype=np.float32)
    expected = stepped * action_dim
    if actions.size != expected:
        raise ValueError(f"expected {expected} action values ({stepped} envs x {action_dim}), got {actions.size}")
    if not np.all(np.isfinite(actions)):
        raise ValueError("actions contain NaN or inf")
    if np.any(np.abs(actions) > 1.0 + ACTION_TOLERANCE):
        raise ValueError("actions must lie in [-1, 1]")
    if len(next_tasks) not in (0, stepped):
        raise ValueError(f"next_tasks must be empty or have {stepped} entries, got {len(next_tasks)}")
    for task in next_tasks:
        if task:
            check_task(task)
    _check_phase(phase)
    return indices, np.clip(actions, -1.0, 1.0).reshape(stepped, action_dim), list(next_tasks) or [""] * stepped


def _indices(num_envs: int, env_indices: Sequence[int]) -> list[int]:
    """The envs a request names, checked (none named: all, in index order)."""
    indices = [int(i) for i in env_indices] if len(env_indices) else list(range(num_envs))
    for index in indices:
        if not 0 <= index < num_envs:
            raise ValueError(f"env index {index} out of range: this sim has {num_envs} envs")
    if len(set(indices)) != len(indices):
        raise ValueError(f"env indices repeat: {indices}")
    return indices


def _per_env(values: list, count: int, name: str, default) -> list:
    if not values:
        return [default] * count
    if len(values) == 1:
        return values * count
    if len(values) != count:
        raise ValueError(f"{name}: give one value, or one per reset env ({count}), not {len(values)}")
    return values


def _check_phase(phase: int) -> None:
    if phase not in PHASES:
        raise ValueError(f"phase must be {PHASE_TRAIN} (train) or {PHASE_EVAL} (eval), got {phase}")


class BatchedEnvs:
    """``num_envs`` envs made by ``make_env(index)``, all on task ``initial_task``.

    ``first_index`` numbers the envs from there in episode logs, for a batch
    that is one worker's share of a larger one (``sim_node.parallel``).
    ``seed``: env k's first episode gets ``seed + k``, and its later unseeded
    episodes continue that env's random stream, so the same calls give the
    same episodes; None leaves the envs to the OS's entropy.
    """

    def __init__(
        self, make_env: Callable[[int], BatchEnv], num_envs: int, initial_task: str = "A0", first_index: int = 0,
        seed: int | None = None,
    ):
        if num_envs < 1:
            raise ValueError(f"num_envs must be at least 1, got {num_envs}")
        check_task(initial_task)
        self.first_index = first_index
        self.envs = [make_env(first_index + i) for i in range(num_envs)]
        self.obs_dim = int(np.prod(self.envs[0].observation_space.shape))
        self.action_dim = int(np.prod(self.envs[0].action_space.shape))
        self.tasks = [initial_task] * num_envs
        # Every env starts in an (unseeded) episode, so viewers have a scene and
        # step works at once; a reset before any step records nothing of it.
        self._logs: dict[int, EpisodeLog] = {}
        for i in range(num_envs):
            self._begin_episode(i, UNSEEDED if seed is None else seed + first_index + i, PHASE_TRAIN, "")

    @property
    def num_envs(self) -> int:
        return len(self.envs)

    @property
    def joint_names(self) -> list[str]:
        return list(self.envs[0].joint_names)

    def reset(
        self,
        env_indices: Sequence[int] = (),
        tasks: Sequence[str] = (),
        seeds: Sequence[int] = (),
        phase: int = PHASE_TRAIN,
        policy_name: str = "",
    ) -> tuple[np.ndarray, list[EpisodeLog]]:
        """Start new episodes; returns their first observations and any episode cut short.

        An episode interrupted by a reset is returned too (``interrupted``),
        so that every step an env took is in the record.
        """
        indices, per_env_tasks, per_env_seeds = normalize_reset(self.num_envs, env_indices, tasks, seeds, phase)
        return self.apply_reset(indices, per_env_tasks, per_env_seeds, phase, policy_name)

    def step(
        self,
        actions: np.ndarray,
        next_tasks: Sequence[str] = (),
        phase: int = PHASE_TRAIN,
        policy_name: str = "",
        global_step: int = 0,
        env_indices: Sequence[int] = (),
    ) -> StepBatch:
        """Step every env (or those of ``env_indices``) once with its row of ``actions`` (shape
        ``(stepped, action_dim)`` or flat)."""
        indices, actions, next_tasks = normalize_step(self.num_envs, self.action_dim, actions, next_tasks, phase,
                                                      env_indices)
        return self.apply_step(actions, next_tasks, phase, policy_name, global_step, indices)

    def start_step(
        self,
        actions: np.ndarray,
        next_tasks: Sequence[str] = (),
        phase: int = PHASE_TRAIN,
        policy_name: str = "",
        global_step: int = 0,
        env_indices: Sequence[int] = (),
    ) -> FinishStep:
        """``step``, run when the returned function is called: these envs step in the caller's thread."""
        return functools.partial(self.step, actions, next_tasks, phase, policy_name, global_step, env_indices)

    def apply_reset(
        self, indices: list[int], tasks: list[str | None], seeds: list[int], phase: int, policy_name: str
    ) -> tuple[np.ndarray, list[EpisodeLog]]:
        """``reset`` of a request already checked by ``normalize_reset``."""
        interrupted = []
        observations = np.empty((len(indices), self.obs_dim), dtype=np.float32)
        for row, (index, task, seed) in enumerate(zip(indices, tasks, seeds)):
            log = self._logs[index]
            if log.length > 0:
                log.interrupted = True
                interrupted.append(log)
            if task is not None:
                self.tasks[index] = task
            observations[row] = self._begin_episode(index, seed, phase, policy_name)
        return observations, interrupted

    def apply_step(
        self, actions: np.ndarray, next_tasks: list[str], phase: int, policy_name: str, global_step: int,
        indices: Sequence[int] | None = None,
    ) -> StepBatch:
        """``step`` of a request already checked by ``normalize_step``: row r of each array is env
        ``indices[r]``'s (None: every env, in index order)."""
        indices = range(self.num_envs) if indices is None else indices
        stepped = len(indices)
        observations = np.empty((stepped, self.obs_dim), dtype=np.float32)
        terminal = np.zeros((stepped, self.obs_dim), dtype=np.float32)
        rewards = np.empty(stepped, dtype=np.float32)
        terminated = np.zeros(stepped, dtype=bool)
        truncated = np.zeros(stepped, dtype=bool)
        is_success = np.zeros(stepped, dtype=bool)
        finished = []
        for row, i in enumerate(indices):
            env = self.envs[i]
            obs, reward, term, trunc, info = env.step(actions[row])
            log = self._logs[i]
            log.phase, log.policy_name = phase, policy_name
            log.add_step(actions[row].copy(), np.asarray(obs, dtype=np.float32), float(reward), env.joint_positions())
            rewards[row], terminated[row], truncated[row] = reward, term, trunc
            is_success[row] = bool(info.get("is_success", False))
            if term or trunc:
                log.success, log.truncated, log.global_step = bool(is_success[row]), bool(trunc and not term), \
                    global_step
                finished.append(log)
                terminal[row] = obs
                if next_tasks[row]:
                    self.tasks[i] = next_tasks[row]
                obs = self._begin_episode(i, UNSEEDED, phase, policy_name)
            observations[row] = obs
        return StepBatch(observations, rewards, terminated, truncated, is_success, terminal,
                         [self.tasks[i] for i in indices], finished)

    def snapshot(self, index: int) -> EnvSnapshot:
        env = self.envs[index].unwrapped
        position, orientation = env.object_pose()
        grasp = env.grasp_state()
        return EnvSnapshot(self.tasks[index], env.joint_positions(), position, orientation, grasp,
                           grasp.object_lift > env.config.success_height, env.link_poses())

    def close(self) -> None:
        for env in self.envs:
            env.close()

    def _begin_episode(self, index: int, seed: int, phase: int, policy_name: str) -> np.ndarray:
        env = self.envs[index]
        obs, _ = env.reset(seed=None if seed == UNSEEDED else seed, options={"task": self.tasks[index]})
        obs = np.asarray(obs, dtype=np.float32)
        log = EpisodeLog(self.tasks[index], self.first_index + index, seed, phase, policy_name)
        log.start(obs, env.joint_positions())
        self._logs[index] = log
        return obs

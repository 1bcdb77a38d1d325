"""N grasp envs stepped in lockstep, with automatic reset and episode logs.

This is the sim node without ROS: ``reset`` and ``step`` take and return
whole batches, validate their input (``ValueError`` with a message a user can
act on), and hand back every episode that finished so that the node can
publish it. Envs reset automatically when their episode ends, as in a
stable-baselines3 VecEnv; the last observation comes back separately.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, Protocol, Sequence

import numpy as np

from glocal_ros.tasks import task_index
from sim_node.episode import PHASE_EVAL, PHASE_TRAIN, UNSEEDED, EpisodeLog

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

    def close(self) -> None: ...


@dataclass
class StepBatch:
    observations: np.ndarray  # (N, obs_dim) after automatic resets
    rewards: np.ndarray  # (N,)
    terminated: np.ndarray  # (N,) bool
    truncated: np.ndarray  # (N,) bool
    is_success: np.ndarray  # (N,) bool
    terminal_observations: np.ndarray  # (N, obs_dim), zero rows where no episode ended
    tasks: list[str]
    finished: list[EpisodeLog]


class BatchedEnvs:
    """``num_envs`` envs made by ``make_env(index)``, all on task ``initial_task``."""

    def __init__(self, make_env: Callable[[int], BatchEnv], num_envs: int, initial_task: str = "A0"):
        if num_envs < 1:
            raise ValueError(f"num_envs must be at least 1, got {num_envs}")
        task_index(initial_task)
        self.envs = [make_env(i) for i in range(num_envs)]
        self.obs_dim = int(np.prod(self.envs[0].observation_space.shape))
        self.action_dim = int(np.prod(self.envs[0].action_space.shape))
        self.tasks = [initial_task] * num_envs
        # Every env starts in an (unseeded) episode, so viewers have a scene and
        # step works at once; a reset before any step records nothing of it.
        self._logs: dict[int, EpisodeLog] = {}
        for i in range(num_envs):
            self._begin_episode(i, UNSEEDED, PHASE_TRAIN, "")

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
        indices = list(env_indices) if len(env_indices) else list(range(self.num_envs))
        for index in indices:
            if not 0 <= index < self.num_envs:
                raise ValueError(f"env index {index} out of range: this sim has {self.num_envs} envs")
        if len(set(indices)) != len(indices):
            raise ValueError(f"env indices repeat: {indices}")
        new_tasks = self._per_env(list(tasks), indices, "tasks", default=None)
        if len(seeds) == 1:
            # One base seed for the batch, as Gymnasium's vector envs do: env k of the reset gets seed + k.
            seeds = [int(seeds[0]) + k for k in range(len(indices))]
        new_seeds = self._per_env([int(s) for s in seeds], indices, "seeds", default=UNSEEDED)
        for task in new_tasks:
            if task is not None:
                task_index(task)
        self._check_phase(phase)

        interrupted = []
        observations = np.empty((len(indices), self.obs_dim), dtype=np.float32)
        for row, (index, task, seed) in enumerate(zip(indices, new_tasks, new_seeds)):
            log = self._logs[index]
            if log.length > 0:
                log.interrupted = True
                interrupted.append(log)
            if task is not None:
                self.tasks[index] = task
            observations[row] = self._begin_episode(index, seed, phase, policy_name)
        return observations, interrupted

    def step(
        self,
        actions: np.ndarray,
        next_tasks: Sequence[str] = (),
        phase: int = PHASE_TRAIN,
        policy_name: str = "",
        global_step: int = 0,
    ) -> StepBatch:
        """Step every env once with its row of ``actions`` (shape ``(N, action_dim)`` or flat)."""
        actions = np.asarray(actions, dtype=np.float32)
        expected = self.num_envs * self.action_dim
        if actions.size != expected:
            raise ValueError(
                f"expected {expected} action values ({self.num_envs} envs x {self.action_dim}), got {actions.size}"
            )
        if not np.all(np.isfinite(actions)):
            raise ValueError("actions contain NaN or inf")
        if np.any(np.abs(actions) > 1.0 + ACTION_TOLERANCE):
            raise ValueError("actions must lie in [-1, 1]")
        actions = np.clip(actions, -1.0, 1.0).reshape(self.num_envs, self.action_dim)
        if len(next_tasks) not in (0, self.num_envs):
            raise ValueError(f"next_tasks must be empty or have {self.num_envs} entries, got {len(next_tasks)}")
        for task in next_tasks:
            if task:
                task_index(task)
        self._check_phase(phase)

        observations = np.empty((self.num_envs, self.obs_dim), dtype=np.float32)
        terminal = np.zeros((self.num_envs, self.obs_dim), dtype=np.float32)
        rewards = np.empty(self.num_envs, dtype=np.float32)
        terminated = np.zeros(self.num_envs, dtype=bool)
        truncated = np.zeros(self.num_envs, dtype=bool)
        is_success = np.zeros(self.num_envs, dtype=bool)
        finished = []
        for i, env in enumerate(self.envs):
            obs, reward, term, trunc, info = env.step(actions[i])
            log = self._logs[i]
            log.phase, log.policy_name = phase, policy_name
            log.add_step(actions[i].copy(), np.asarray(obs, dtype=np.float32), float(reward), env.joint_positions())
            rewards[i], terminated[i], truncated[i] = reward, term, trunc
            is_success[i] = bool(info.get("is_success", False))
            if term or trunc:
                log.success, log.truncated, log.global_step = bool(is_success[i]), bool(trunc and not term), global_step
                finished.append(log)
                terminal[i] = obs
                if next_tasks and next_tasks[i]:
                    self.tasks[i] = next_tasks[i]
                obs = self._begin_episode(i, UNSEEDED, phase, policy_name)
            observations[i] = obs
        return StepBatch(observations, rewards, terminated, truncated, is_success, terminal, list(self.tasks), finished)

    def close(self) -> None:
        for env in self.envs:
            env.close()

    def _begin_episode(self, index: int, seed: int, phase: int, policy_name: str) -> np.ndarray:
        env = self.envs[index]
        obs, _ = env.reset(seed=None if seed == UNSEEDED else seed, options={"task": self.tasks[index]})
        obs = np.asarray(obs, dtype=np.float32)
        log = EpisodeLog(self.tasks[index], index, seed, phase, policy_name)
        log.start(obs, env.joint_positions())
        self._logs[index] = log
        return obs

    def _per_env(self, values: list, indices: list[int], name: str, default):
        if not values:
            return [default] * len(indices)
        if len(values) == 1:
            return values * len(indices)
        if len(values) != len(indices):
            raise ValueError(f"{name}: give one value, or one per reset env ({len(indices)}), not {len(values)}")
        return values

    @staticmethod
    def _check_phase(phase: int) -> None:
        if phase not in (PHASE_TRAIN, PHASE_EVAL):
            raise ValueError(f"phase must be {PHASE_TRAIN} (train) or {PHASE_EVAL} (eval), got {phase}")

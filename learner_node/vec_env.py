"""A stable-baselines3 VecEnv over a lockstep batch of grasp envs.

The batch is the sim node's, through ROS (``SimClient``), or an in-process
``BatchedEnvs``: both step all N envs in one call, so SAC pays one round trip
per batch. The sim resets an env itself when its episode ends, as a VecEnv
does, and starts it on the task this VecEnv reserved for it.

Between two steps, ``between_steps`` may use the same envs for something else
(an evaluation); it returns True when it did. Every env's episode is then
gone, so the VecEnv starts new ones and reports the cut episodes as
truncated, with the true last observation as ``terminal_observation``: SAC
bootstraps from it as it does at a time limit, and no transition is made up.
With ``time_limit_terminal`` (the ``paper`` learner profile) the sim's own
time-limit ends are reported as terminal instead, so SAC does not bootstrap
from them; the cuts above still bootstrap.

``while_stepping`` runs during every step, between ``start_step`` and its
finish: after the batch was sent to the sim node, so the learner's own work
overlaps the sim's; just before the step for in-process envs (they step in
this thread). The learner puts its gradient steps there.
"""

from __future__ import annotations

from collections import deque
from typing import Any, Callable, Iterable, Sequence

import numpy as np
from gymnasium import spaces
from stable_baselines3.common.vec_env import VecEnv

from glocal_ros.curriculum.learner import EpisodeSummary
from glocal_ros.sim_contract import PHASE_TRAIN, BatchStepper


class TaskCycle:
    """The tasks of successive training episodes: ``tasks`` in order, over and over."""

    def __init__(self, tasks: Sequence[str]):
        if not tasks:
            raise ValueError("no training task")
        self._tasks = list(tasks)
        self.position = 0  # tasks drawn so far: a checkpoint keeps it

    def __next__(self) -> str:
        task = self._tasks[self.position % len(self._tasks)]
        self.position += 1
        return task

    def __iter__(self):
        return self


class BatchVecEnv(VecEnv):
    """SB3's VecEnv interface over ``envs``, one batch call per step."""

    def __init__(
        self,
        envs: BatchStepper,
        observation_space: spaces.Box,
        action_space: spaces.Box,
        tasks: Iterable[str],
        policy_name: str = "",
        global_step: Callable[[], int] = lambda: 0,
        between_steps: Callable[[], bool] = lambda: False,
        while_stepping: Callable[[], None] = lambda: None,
        time_limit_terminal: bool = False,
    ):
        self.envs = envs
        self.time_limit_terminal = time_limit_terminal
        self.tasks = iter(tasks)
        self.policy_name = policy_name
        self.global_step = global_step
        self.between_steps = between_steps
        self.while_stepping = while_stepping
        # The batch size is known once the envs answer a reset.
        first_task = next(self.tasks)
        observations, _ = envs.reset((), [first_task], (), PHASE_TRAIN, policy_name)
        super().__init__(len(observations), observation_space, action_space)
        obs_dim = int(np.prod(observation_space.shape))
        if observations.shape[1] != obs_dim:
            raise ValueError(f"the envs observe {observations.shape[1]} values, the policy expects {obs_dim}")
        self._running = [first_task] * self.num_envs
        self._reserved = [first_task] * self.num_envs
        self._returns = np.zeros(self.num_envs)
        self._lengths = np.zeros(self.num_envs, dtype=int)
        self._actions: np.ndarray | None = None
        self.finished: deque[EpisodeSummary] = deque()  # drained by the trainer

    def reset(self) -> np.ndarray:
        self._running = [next(self.tasks) for _ in range(self.num_envs)]
        # SB3's ``seed(s)`` asks for env k's next episode to get s + k: the batch's base seed.
        seeds = [self._seeds[0]] if self._seeds and self._seeds[0] is not None else []
        self._reset_seeds()
        observations, _ = self.envs.reset((), self._running, seeds, PHASE_TRAIN, self.policy_name)
        self._reserved = [next(self.tasks) for _ in range(self.num_envs)]
        self._returns[:] = 0.0
        self._lengths[:] = 0
        return observations

    def step_async(self, actions: np.ndarray) -> None:
        self._actions = actions

    def step_wait(self):
        request = (self._actions, self._reserved, PHASE_TRAIN, self.policy_name, self.global_step())
        finish_step = self.envs.start_step(*request)
        self.while_stepping()
        batch = finish_step()
        self._returns += batch.rewards
        self._lengths += 1
        dones = batch.terminated | batch.truncated
        infos: list[dict[str, Any]] = [{} for _ in range(self.num_envs)]
        for i in np.flatnonzero(dones):
            self.finished.append(EpisodeSummary(self._running[i], float(self._returns[i]), int(self._lengths[i]),
                                                 bool(batch.is_success[i])))
            time_limit = bool(batch.truncated[i] and not batch.terminated[i]) and not self.time_limit_terminal
            infos[i] = self._end_info(batch.terminal_observations[i], time_limit, bool(batch.is_success[i]))
            self._running[i], self._reserved[i] = self._reserved[i], next(self.tasks)
            self._returns[i], self._lengths[i] = 0.0, 0
        observations = batch.observations
        if self.between_steps():
            # The envs' episodes are gone: cut the running ones as at a time limit.
            for i in np.flatnonzero(~dones):
                infos[i] = self._end_info(batch.observations[i], truncated=True, success=False)
            dones = np.ones(self.num_envs, dtype=bool)
            observations = self.reset()
        return observations, batch.rewards.astype(np.float32), dones, infos

    @staticmethod
    def _end_info(terminal_observation: np.ndarray, truncated: bool, success: bool) -> dict[str, Any]:
        return {"terminal_observation": terminal_observation, "TimeLimit.truncated": truncated,
                "is_success": success}

    def close(self) -> None:
        """The envs belong to the caller (the sim node): nothing to close here."""

    # The rest of VecEnv's interface reaches into single envs, which a batch
    # behind a service does not expose.
    def get_attr(self, attr_name: str, indices=None) -> list[Any]:
        if attr_name == "render_mode":
            return [None] * self.num_envs
        raise AttributeError(f"{type(self).__name__} has no per-env attribute {attr_name!r}")

    def set_attr(self, attr_name: str, value: Any, indices=None) -> None:
        raise AttributeError(f"{type(self).__name__} cannot set per-env attributes")

    def env_method(self, method_name: str, *method_args, indices=None, **method_kwargs) -> list[Any]:
        raise AttributeError(f"{type(self).__name__} cannot call per-env methods")

    def env_is_wrapped(self, wrapper_class, indices=None) -> list[bool]:
        return [False] * self.num_envs

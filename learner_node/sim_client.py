"""The sim node's batched reset/step, called over ROS with numpy in and out.

``SimClient`` is a ``glocal_ros.sim_contract.BatchStepper``, as the sim's
in-process batch is, so the learner's evaluation and training code cannot
tell the graph from an in-process batch. Calls block: use it from a thread other than the one
spinning its node's executor.
"""

from __future__ import annotations

from typing import Sequence

import numpy as np
from glocal_interfaces.srv import ResetEnvs, StepEnvs
from rclpy.callback_groups import ReentrantCallbackGroup
from rclpy.node import Node

from glocal_ros.sim_contract import PHASE_TRAIN, EpisodeLog, FinishStep, StepBatch
from node_common import names
from node_common.arrays import from_float32_field, to_float32_field
from node_common.calls import call_checked, start_call, wait_for_service


class SimClient:
    def __init__(self, node: Node, timeout_sec: float = 60.0, namespace: str = ""):
        """``namespace``: the sim node's, when it differs from ``node``'s (e.g. ``/robot1``)."""
        group = ReentrantCallbackGroup()
        prefix = namespace.rstrip("/") + "/" if namespace else ""
        self._reset = node.create_client(ResetEnvs, prefix + names.SIM_RESET, callback_group=group)
        self._step = node.create_client(StepEnvs, prefix + names.SIM_STEP, callback_group=group)
        self.timeout_sec = timeout_sec
        self.num_envs = 0
        self.obs_dim = 0
        self.action_dim = 0

    def ready(self) -> bool:
        return self._reset.service_is_ready() and self._step.service_is_ready()

    def wait_for_sim(self, timeout_sec: float) -> None:
        """Wait for the sim node's services; sizes are known after the first reset."""
        wait_for_service(self._reset, timeout_sec)
        wait_for_service(self._step, timeout_sec)

    def reset(
        self, env_indices: Sequence[int] = (), tasks: Sequence[str] = (), seeds: Sequence[int] = (),
        phase: int = PHASE_TRAIN, policy_name: str = "",
    ) -> tuple[np.ndarray, list[EpisodeLog]]:
        request = ResetEnvs.Request(
            env_indices=[int(i) for i in env_indices], tasks=list(tasks), seeds=[int(s) for s in seeds],
            phase=phase, policy_name=policy_name,
        )
        response = call_checked(self._reset, request, self.timeout_sec)
        self.num_envs, self.obs_dim, self.action_dim = response.num_envs, response.obs_dim, response.action_dim
        observations = from_float32_field(response.observations).reshape(-1, self.obs_dim)
        # Interrupted episodes go to the record, not to the caller.
        return observations, []

    def step(
        self, actions: np.ndarray, next_tasks: Sequence[str] = (), phase: int = PHASE_TRAIN, policy_name: str = "",
        global_step: int = 0, env_indices: Sequence[int] = (),
    ) -> StepBatch:
        return self.start_step(actions, next_tasks, phase, policy_name, global_step, env_indices)()

    def start_step(
        self, actions: np.ndarray, next_tasks: Sequence[str] = (), phase: int = PHASE_TRAIN, policy_name: str = "",
        global_step: int = 0, env_indices: Sequence[int] = (),
    ) -> FinishStep:
        """Send the step now; the returned function waits for its batch (the learner trains meanwhile)."""
        request = StepEnvs.Request(
            env_indices=[int(i) for i in env_indices], actions=to_float32_field(actions),
            next_tasks=list(next_tasks), phase=phase, policy_name=policy_name, global_step=int(global_step),
        )
        wait = start_call(self._step, request, self.timeout_sec, checked=True)

        def finish() -> StepBatch:
            response = wait()
            obs_dim = response.obs_dim
            return StepBatch(
                observations=from_float32_field(response.observations).reshape(-1, obs_dim),
                rewards=from_float32_field(response.rewards),
                terminated=np.asarray(response.terminated, dtype=bool),
                truncated=np.asarray(response.truncated, dtype=bool),
                is_success=np.asarray(response.is_success, dtype=bool),
                terminal_observations=from_float32_field(response.terminal_observations).reshape(-1, obs_dim),
                tasks=list(response.tasks),
                finished=[],
            )

        return finish

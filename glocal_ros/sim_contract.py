"""What crosses the sim <-> learner boundary, ROS-free: phases, batches, episode logs.

The sim's in-process batch (``sim_node.batch.BatchedEnvs``), its worker-process
batch (``sim_node.parallel.ProcessBatchedEnvs``) and the sim node's ROS client
(``learner_node.sim_client.SimClient``) all are a ``BatchStepper``: the
learner's evaluation and training code is written against this protocol and
cannot tell the graph from an in-process batch. Both sides import this module;
neither imports the other.

The values mirror glocal_interfaces: ``PHASE_*`` are EpisodeRecord.PHASE_*,
``UNSEEDED`` is the ``-1`` of EpisodeRecord.seed (test_rooms checks both
against msg_schemas/).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable, Protocol, Sequence, runtime_checkable

import numpy as np

#: EpisodeRecord.PHASE_*: what the episodes that follow a reset or step are for.
PHASE_TRAIN = 0
PHASE_EVAL = 1
PHASES = (PHASE_TRAIN, PHASE_EVAL)
#: EpisodeRecord.seed of an episode no reset seeded (it continues its env's random stream).
UNSEEDED = -1
#: T: an episode's steps before it is truncated, unless the sim is told otherwise (sim_node ``max_steps``;
#: curriculum_node's ``max_episode_steps`` must say the same).
DEFAULT_EPISODE_STEPS = 50
#: The Gymnasium id of sim_node's ``GraspEnv``, registered when ``sim_node.grasp_env`` is imported.
GRASP_ENV_ID = "glocal_ros/Grasp-v0"
#: The sim's envs of evaluation (sim_node ``eval_envs``): eight a worker on two cores, where a step's physics
#: outweighs its round trip (``glocal-ros bench eval``).
DEFAULT_EVAL_ENVS = 16


@dataclass
class EpisodeLog:
    """The trajectory of one env's episode, grown step by step."""

    task: str
    env_index: int
    seed: int
    phase: int
    policy_name: str
    observations: list[np.ndarray] = field(default_factory=list)
    actions: list[np.ndarray] = field(default_factory=list)
    rewards: list[float] = field(default_factory=list)
    joint_positions: list[np.ndarray] = field(default_factory=list)
    global_step: int = 0
    success: bool = False
    truncated: bool = False
    interrupted: bool = False

    @property
    def length(self) -> int:
        return len(self.actions)

    def start(self, observation: np.ndarray, joint_positions: np.ndarray) -> None:
        self.observations.append(observation)
        self.joint_positions.append(joint_positions)

    def add_step(
        self, action: np.ndarray, observation: np.ndarray, reward: float, joint_positions: np.ndarray
    ) -> None:
        self.actions.append(action)
        self.observations.append(observation)
        self.rewards.append(reward)
        self.joint_positions.append(joint_positions)


@dataclass
class StepBatch:
    """What one lockstep step of the N envs (or of those it named) returns (StepEnvs' response, as numpy): one
    row per stepped env, in the request's order."""

    observations: np.ndarray  # (stepped, obs_dim) after automatic resets
    rewards: np.ndarray  # (stepped,)
    terminated: np.ndarray  # (stepped,) bool
    truncated: np.ndarray  # (stepped,) bool
    is_success: np.ndarray  # (stepped,) bool
    terminal_observations: np.ndarray  # (stepped, obs_dim), zero rows where no episode ended
    tasks: list[str]
    finished: list[EpisodeLog]  # episodes that ended; empty through ROS (they go to the record instead)


#: Waits for a step that ``BatchStepper.start_step`` sent and returns its batch.
FinishStep = Callable[[], StepBatch]


@runtime_checkable
class BatchStepper(Protocol):
    """N envs reset and stepped in lockstep, one call per batch (see ResetEnvs.srv, StepEnvs.srv)."""

    def reset(
        self, env_indices: Sequence[int] = (), tasks: Sequence[str] = (), seeds: Sequence[int] = (),
        phase: int = PHASE_TRAIN, policy_name: str = "",
    ) -> tuple[np.ndarray, list[EpisodeLog]]:
        """Start new episodes; their first observations, and the episodes the reset cut short."""

    def step(
        self, actions: np.ndarray, next_tasks: Sequence[str] = (), phase: int = PHASE_TRAIN,
        policy_name: str = "", global_step: int = 0, env_indices: Sequence[int] = (),
    ) -> StepBatch:
        """Step every env (or those of ``env_indices``; the others wait) once with its row of ``actions``."""

    def start_step(
        self, actions: np.ndarray, next_tasks: Sequence[str] = (), phase: int = PHASE_TRAIN,
        policy_name: str = "", global_step: int = 0, env_indices: Sequence[int] = (),
    ) -> FinishStep:
        """``step`` in two halves, so that the caller works while the envs step.

        Envs in another process (the sim node) step from the moment this
        returns; envs in the caller's thread step when the returned function
        is called. Either way, calling it gives what ``step`` would have.
        """

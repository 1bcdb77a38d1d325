"""Episodes as the sim node records them: every step of one env, ROS-free."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

PHASE_TRAIN = 0
PHASE_EVAL = 1
UNSEEDED = -1


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

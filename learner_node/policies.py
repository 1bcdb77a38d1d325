"""Policies the learner can act with, by name.

Issue "Learner" adds the SAC policy store (named stable-baselines3 policies on
disk); until then the learner knows one built-in policy, ``random``: uniform
random actions, the chance level every learned policy must beat.
"""

from __future__ import annotations

import numpy as np

from glocal_ros.spaces import ACTION_DIM
from learner_node.evaluation import BatchPolicy

RANDOM_POLICY = "random"


class UnknownPolicyError(KeyError):
    def __str__(self) -> str:
        return f"unknown policy {self.args[0]!r}"


class PolicyRegistry:
    def __init__(self, seed: int | None = None):
        self._rng = np.random.default_rng(seed)

    def names(self) -> list[str]:
        return [RANDOM_POLICY]

    def load(self, name: str) -> BatchPolicy:
        if name != RANDOM_POLICY:
            raise UnknownPolicyError(name)
        return lambda observations: self._rng.uniform(
            -1.0, 1.0, size=(len(observations), ACTION_DIM)
        ).astype(np.float32)

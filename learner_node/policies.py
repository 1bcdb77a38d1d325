"""Policies the learner can act with, by name.

Names resolve, in order, to the built-in ``random`` (uniform random actions,
the chance level every learned policy must beat), the learner's own policy
store, then the read-only stores shipped with the package (``assets/priors``:
the A0 ``prior``). Stored policies are SAC models (SBX's) acting
deterministically; each name keeps its loaded model until its file changes.
"""

from __future__ import annotations

from pathlib import Path
from typing import Sequence

import numpy as np

from glocal_ros.spaces import ACTION_DIM
from learner_node.evaluation import BatchPolicy
from learner_node.policy_store import PolicyRecord, PolicyStore, UnknownPolicyError, check_name
from learner_node.replay_buffer import Experience

RANDOM_POLICY = "random"


def deterministic_actions(policy) -> BatchPolicy:
    """The SAC ``policy``'s deterministic actions, the numbers SB3's ``predict`` gives, from one compiled call.

    ``predict`` checks and converts its input and output around the network, which on a batch of a few
    envs costs more than the network itself; here the actor's mode is computed and then clipped and
    scaled to the action space as ``predict`` does. The actor is read at each call, so a policy that
    trains acts with its newest weights.
    """
    from sbx.common.policies import BaseJaxPolicy

    shape = policy.action_space.shape

    def act(observations: np.ndarray) -> np.ndarray:
        actions = np.asarray(BaseJaxPolicy.select_action(policy.actor_state, observations)).reshape((-1, *shape))
        return policy.unscale_action(np.clip(actions, -1, 1))

    return act


class PolicyExists(ValueError):
    """A policy of that name exists already: nothing was written."""


class PolicyRegistry:
    def __init__(self, store: PolicyStore, read_only: Sequence[PolicyStore] = (), seed: int | None = None):
        self.store = store
        self.read_only = list(read_only)
        self._rng = np.random.default_rng(seed)
        self._models: dict[str, tuple[Path, object]] = {}  # name -> (model file, model)

    def names(self) -> list[str]:
        names = {RANDOM_POLICY, *self.store.names()}
        for store in self.read_only:
            names.update(store.names())
        return sorted(names)

    def records(self) -> list[PolicyRecord]:
        return [self.record(name) for name in self.names()]

    def record(self, name: str) -> PolicyRecord:
        if name == RANDOM_POLICY:
            return PolicyRecord(name=RANDOM_POLICY)
        return self._store_of(name).record(name)

    def load(self, name: str, seed: int | None = None) -> BatchPolicy:
        """``name`` as a batch policy; ``seed`` seeds the random policy's actions (else the registry's stream)."""
        if name == RANDOM_POLICY:
            rng = self._rng if seed is None else np.random.default_rng(seed)
            return lambda observations: rng.uniform(
                -1.0, 1.0, size=(len(observations), ACTION_DIM)
            ).astype(np.float32)
        return deterministic_actions(self.model(name).policy)

    def model(self, name: str):
        """The SAC model of a stored policy, loaded again only when its file changed."""
        path = self.model_path(name)
        if self._models.get(name, (None,))[0] != path:
            self._models[name] = (path, self._store_of(name).load(name))
        return self._models[name][1]

    def model_path(self, name: str) -> Path:
        if name == RANDOM_POLICY:
            raise ValueError(f"{RANDOM_POLICY!r} is built in and has no model")
        return self._store_of(name).model_path(name)

    def experience(self, name: str) -> Experience | None:
        """The transitions a stored policy keeps (None: none; the built-in ``random`` keeps none)."""
        return None if name == RANDOM_POLICY else self._store_of(name).experience(name)

    def check_writable(self, name: str) -> None:
        """Raise ``ValueError`` unless a goal may write ``name``: a policy of the learner's own store, or new.

        A written ``prior`` would hide the shipped one (the learner's store is looked in first).
        """
        if name not in self.store and any(name in store for store in self.read_only):
            raise ValueError(f"policy {name!r} is shipped read-only: write another name")

    def copy(self, source: str, destination: str) -> PolicyRecord:
        """Copy a stored policy into the learner's own store under a new name."""
        if destination == RANDOM_POLICY or destination in self.names():
            raise PolicyExists(f"policy {destination!r} exists already")
        if source == RANDOM_POLICY:
            raise ValueError(f"{RANDOM_POLICY!r} is built in and has no model to copy")
        return self.store.add_copy(self._store_of(source), source, destination)

    def record_score(self, name: str, task: str, successes: int) -> None:
        """Remember the latest score of a policy of the learner's own store."""
        if name in self.store:
            self.store.update(name, last_score=float(successes), last_score_task=task)

    def _store_of(self, name: str) -> PolicyStore:
        check_name(name)
        for store in (self.store, *self.read_only):
            if name in store:
                return store
        raise UnknownPolicyError(name)

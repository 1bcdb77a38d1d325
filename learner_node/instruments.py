"""A goal's instruments: what fine-tuning does to the parent's policy, measured at each evaluation.

A goal that starts from a stored policy (its parent) and scores below B
often first loses what the parent knew (the dip). Its score alone cannot
say why. The instruments, measured on a fixed set of probe states each time
the goal is evaluated, tell the causes apart:

- ``q_parent_action`` and ``q_current_action``: the critics' value (the
  minimum of SAC's two Q heads, as the actor's loss takes it) of the
  parent's deterministic action and of the current policy's, averaged over
  the probes. A critic that rates the parent's actions below the current
  policy's while the score falls is miscalibrated;
- ``action_distance``: the mean Euclidean distance between the current
  policy's deterministic action and the parent's, in the actor's [-1, 1]
  range (forgetting shows as a distance that grows while the score falls);
- ``policy_entropy``: the policy's entropy, estimated as -log pi(a|s) of one
  action drawn per probe (a fixed key: the same policy gives the same
  estimate); a large entropy coefficient (``train/ent_coef``) driving up
  the entropy of a policy whose Q is flat shows here.

Choices the issue leaves open:

- Probe states: ``PROBE_STATES`` observations spread evenly over the
  parent's stored experience (``PolicyRegistry.experience``: the transitions
  it kept, the same for every goal from it and after a resume). A parent
  without experience (a policy stored without it): evenly over the goal's own
  replay buffer, taken the first time it holds ``PROBE_STATES`` transitions
  and kept for the rest of the session (a resumed goal takes them again from
  its restored buffer); NaN until then.
- The parent is the stored initial policy as the store holds it, before a
  recipe edits the goal's copy (``new_task_inputs``): at the goal's first
  check its distance can already differ from 0.
- Deterministic actions are the actor's mode (SBX's ``predict(deterministic=True)``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import jax
import jax.numpy as jnp
import numpy as np

from learner_node.replay_buffer import Experience
from learner_node.updates import TransitionRing

#: Probe states of a goal's instruments.
PROBE_STATES = 256
#: The key of the entropy estimate's draws (fixed: the same policy, the same estimate).
ENTROPY_KEY = 0


@dataclass(frozen=True)
class Instruments:
    """A goal's instruments at one evaluation (NaN: not measured, no probe states yet)."""

    q_parent_action: float = math.nan
    q_current_action: float = math.nan
    action_distance: float = math.nan
    policy_entropy: float = math.nan

    def scalars(self) -> dict[str, float]:
        """The instruments as ``learner_node.scalars`` tags them."""
        return {"instruments/q_parent_action": self.q_parent_action,
                "instruments/q_current_action": self.q_current_action,
                "instruments/action_distance": self.action_distance,
                "instruments/policy_entropy": self.policy_entropy}


@jax.jit
def _measure(parent_params, actor_state, qf_state, probes, key):
    parent = actor_state.apply_fn(parent_params, probes).mode()
    policy = actor_state.apply_fn(actor_state.params, probes)
    current = policy.mode()

    def value(actions):
        return jnp.min(qf_state.apply_fn(qf_state.params, probes, actions, rngs={"dropout": key}), axis=0).mean()

    drawn = policy.sample(seed=key)
    return (value(parent), value(current), jnp.linalg.norm(current - parent, axis=-1).mean(),
            -policy.log_prob(drawn).mean())


def evenly_spread(observations: np.ndarray, count: int = PROBE_STATES) -> np.ndarray:
    """``count`` rows of ``observations`` spread evenly over them (all of them when fewer)."""
    rows = len(observations)
    index = np.unique(np.linspace(0, rows - 1, min(count, rows)).round().astype(int)) if rows else []
    return np.asarray(observations[index], np.float32)


class GoalInstruments:
    """The instruments of one goal from ``parent_model`` (the stored initial policy, an SBX SAC model)."""

    def __init__(self, parent_model, parent_experience: Experience | None):
        self.parent_params = parent_model.policy.actor_state.params
        self.probes: np.ndarray | None = None
        if parent_experience is not None and len(parent_experience["observations"]) >= PROBE_STATES:
            self.probes = evenly_spread(parent_experience["observations"])
        self.key = jax.random.PRNGKey(ENTROPY_KEY)

    def measure(self, model, ring: TransitionRing) -> Instruments:
        """The instruments of ``model`` (the goal's, its owed updates paid) on the probe states."""
        if self.probes is None and ring.size >= PROBE_STATES:
            self.probes = evenly_spread(np.asarray(ring.arrays["observations"][:ring.size]))
        if self.probes is None:
            return Instruments()
        policy = model.policy
        values = _measure(self.parent_params, policy.actor_state, policy.qf_state, jnp.asarray(self.probes), self.key)
        return Instruments(*(float(value) for value in values))


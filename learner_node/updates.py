"""SAC's replay buffer and gradient steps as compiled code, run while the sim computes the next step.

What this replaces in stable-baselines3's ``learn`` (SBX's SAC on it), and why:
per vector step SB3 stored the transition in a numpy buffer, then drew each
minibatch on the host (numpy indices, torch tensors, numpy again) and handed
the batches to SBX's jitted ``_train``, around a chain of callbacks. On this
machine kind that host work cost as much as the gradient steps themselves,
and more than the physics it trained on (``bench/results/learner.md``).

Here a goal's replay buffer is a ``TransitionRing``: JAX arrays of the last
``capacity`` transitions, one row per transition. One compiled call per
vector step (``OverlappedUpdates.pay``) writes the step's transitions into
the ring and runs its gradient steps, each drawing its minibatch inside the
compiled code; the arrays are donated, so the ring is updated in place. The
call is dispatched after the step's actions went to the sim (``BatchVecEnv``'s
``while_stepping``), so the sim computes step t+1 while the learner does step
t's updates, and the action of step t+1 comes from a policy without them (a
lag of one vector step; SB3's loop, in-process, has none). The owed updates
are paid before anything looks at the model (evaluation, checkpoint, store),
so the saved models and the goal's outcome are those of the plain order.

The gradient step is SBX's own (``update_critic``, ``soft_update``,
``update_actor_and_temperature``: SAC-v2, critics first, then the actor and
the entropy coefficient), at the model's settings. What differs from SB3 +
SBX, and nothing else:
- a minibatch is drawn by ``jax.random.randint`` from the goal's JAX key
  (``model.key``), uniform over the stored transitions with replacement, as
  SB3 and Stable Baselines 2 draw it; SB3 drew it from numpy's global
  generator, so a seeded goal draws other (equally distributed) batches;
- the rows are transitions, not rows of N envs: a buffer holds exactly its
  ``capacity`` transitions whatever N (SB3 rounds it down to a multiple of N);
- the number of gradient steps owed and when they start are SB3's
  (``owe``); the critic-only steps of ``FineTuning.critic_warmup`` skip the
  actor and entropy update inside the same compiled loop (SBX's
  ``policy_delay`` trick before).
A goal with ``FineTuning.parent_anchor`` (an ``Anchor``) updates its actor
with ``_anchored_actor_update``: SBX's ``update_actor`` with the anchor's
term added to the loss, the same noise and dropout keys, then SBX's
``update_temperature``; once the anchor's weight has decayed to 0 the goal
goes back to SBX's own update.
"""

from __future__ import annotations

import math
from contextlib import contextmanager
from functools import partial
from typing import BinaryIO, Iterator, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from learner_node.replay_buffer import TRANSITION_ARRAYS, Experience, read_arrays


class Anchor(NamedTuple):
    """``FineTuning.parent_anchor`` of one goal: the starting actor's parameters, the weight at the goal's
    start, the training steps over which it falls to 0, and the model's step count at the goal's start."""

    params: object
    weight: float
    decay_steps: int
    start_timesteps: int

    def weight_at(self, num_timesteps: int) -> float:
        return self.weight * max(0.0, 1.0 - (num_timesteps - self.start_timesteps) / self.decay_steps)


class UpdateInfo(NamedTuple):
    """The last gradient step's losses and entropy coefficient."""

    actor_loss: float
    critic_loss: float
    entropy_coefficient_loss: float
    entropy_coefficient: float


def _row_shapes(obs_dim: int, action_dim: int) -> dict[str, tuple[int, ...]]:
    return {"observations": (obs_dim,), "next_observations": (obs_dim,), "actions": (action_dim,),
            "rewards": (), "dones": (), "timeouts": ()}


def _write_rows(arrays: dict, rows: dict, position: jax.Array) -> dict:
    """``rows`` written into the ring ``arrays`` from row ``position`` on, going round at the end."""
    capacity = arrays["observations"].shape[0]
    index = (position + jnp.arange(rows["observations"].shape[0])) % capacity
    return {name: arrays[name].at[index].set(rows[name]) for name in arrays}


_insert = jax.jit(_write_rows, donate_argnums=0)


class TransitionRing:
    """A goal's replay buffer: the newest ``capacity`` transitions in JAX arrays, one row each.

    Host-side it keeps only where the next row goes (``pos``) and whether the
    ring went round (``full``); rows reach it through ``add`` (host arrays)
    or inside ``OverlappedUpdates.pay``'s compiled call.
    """

    def __init__(self, capacity: int, obs_dim: int, action_dim: int):
        if capacity < 1:
            raise ValueError(f"a replay buffer needs room for a transition, got capacity {capacity}")
        self.capacity, self.obs_dim, self.action_dim = capacity, obs_dim, action_dim
        self.arrays = {name: jnp.zeros((capacity, *shape), jnp.float32)
                       for name, shape in _row_shapes(obs_dim, action_dim).items()}
        self.pos, self.full = 0, False

    @classmethod
    def for_model(cls, model) -> "TransitionRing":
        """An empty ring of ``model``'s buffer size and spaces."""
        return cls(int(model.buffer_size), int(np.prod(model.observation_space.shape)),
                   int(np.prod(model.action_space.shape)))

    @property
    def size(self) -> int:
        """Transitions stored."""
        return self.capacity if self.full else self.pos

    def check(self, transitions: Experience) -> int:
        """How many ``transitions`` there are; ``ValueError`` naming both shapes unless they are rows of this
        ring's shapes."""
        shapes = _row_shapes(self.obs_dim, self.action_dim)
        count = len(transitions["observations"])
        for name, shape in shapes.items():
            if transitions[name].shape != (count, *shape):
                raise ValueError(f"transitions of {name} {transitions[name].shape[1:]} (and {count} "
                                 f"observations) do not fit a buffer of {name} {shape}")
        return count

    def advance(self, count: int) -> None:
        self.full = self.full or self.pos + count >= self.capacity
        self.pos = (self.pos + count) % self.capacity

    def add(self, transitions: Experience) -> int:
        """Append host ``transitions`` (the newest ``capacity`` of them when more); returns how many."""
        count = self.check(transitions)
        keep = min(count, self.capacity)
        if keep:
            rows = {name: jnp.asarray(np.asarray(transitions[name][count - keep:], np.float32))
                    for name in TRANSITION_ARRAYS}
            self.arrays = _insert(self.arrays, rows, np.int32(self.pos))
            self.advance(keep)
        return keep

    def recent(self, count: int) -> Experience:
        """The newest ``count`` transitions (fewer when fewer are in), oldest first, as numpy arrays."""
        count = min(count, self.size)
        index = (self.pos - count + np.arange(count)) % self.capacity
        return {name: np.asarray(self.arrays[name])[index] for name in TRANSITION_ARRAYS}

    def save(self, stream: BinaryIO) -> None:
        """The stored rows where they lie (a minibatch index names the same transition after ``load``), and
        where the next one goes (``np.savez``)."""
        rows = {name: np.asarray(self.arrays[name][:self.size]) for name in TRANSITION_ARRAYS}
        np.savez(stream, capacity=self.capacity, pos=self.pos, full=self.full, **rows)

    def load(self, path) -> bool:
        """The empty ring as ``save`` wrote it to ``path``; False (left empty) when that ring was of another
        capacity or observation size. ``ValueError`` naming ``path`` when it is not a whole buffer file."""
        saved = read_arrays(path, (*TRANSITION_ARRAYS, "capacity", "pos", "full"))
        observations = saved["observations"]
        if saved["capacity"].shape != () or int(saved["capacity"]) != self.capacity \
                or observations.ndim != 2 or observations.shape[1] != self.obs_dim:
            return False
        try:
            count = self.check(saved)
            pos, full = int(saved["pos"]), bool(saved["full"])
            if saved["pos"].shape != () or not 0 <= pos < self.capacity or count != (self.capacity if full else pos):
                raise ValueError(f"{count} transitions do not fill a ring of {self.capacity} up to row {pos}")
        except (ValueError, TypeError) as error:
            raise ValueError(f"{path}: {error}") from error
        if count:
            rows = {name: jnp.asarray(saved[name], jnp.float32) for name in TRANSITION_ARRAYS}
            self.arrays = _insert(self.arrays, rows, np.int32(0))
        self.pos, self.full = pos, full
        return True


def _anchored_actor_update(anchor_params, weight, actor_state, qf_state, ent_coef_state, observations,
                           target_entropy, key):
    """SBX's ``update_actor_and_temperature`` with the anchor's term in the actor's loss (see
    ``FineTuning.parent_anchor``): ``weight x mean|Q| x ||mode - anchor's mode||^2``, |Q| without gradient."""
    from sbx import SAC

    key, dropout_key, noise_key = jax.random.split(key, 3)
    anchor_actions = actor_state.apply_fn(anchor_params, observations).mode()

    def actor_loss(params):
        dist = actor_state.apply_fn(params, observations)
        actor_actions = dist.sample(seed=noise_key)
        log_prob = dist.log_prob(actor_actions).reshape(-1, 1)
        qf_pi = qf_state.apply_fn(qf_state.params, observations, actor_actions, rngs={"dropout": dropout_key})
        min_qf_pi = jnp.min(qf_pi, axis=0)
        ent_coef_value = ent_coef_state.apply_fn({"params": ent_coef_state.params})
        distance = jnp.sum((dist.mode() - anchor_actions) ** 2, axis=-1).mean()
        scale = jax.lax.stop_gradient(jnp.abs(min_qf_pi).mean())
        return (ent_coef_value * log_prob - min_qf_pi).mean() + weight * scale * distance, -log_prob.mean()

    (actor_loss_value, entropy), grads = jax.value_and_grad(actor_loss, has_aux=True)(actor_state.params)
    actor_state = actor_state.apply_gradients(grads=grads)
    ent_coef_state, ent_coef_loss_value = SAC.update_temperature(target_entropy, ent_coef_state, entropy)
    return actor_state, qf_state, ent_coef_state, actor_loss_value, ent_coef_loss_value, key


def _gradient_steps(qf_state, actor_state, ent_coef_state, key, arrays, size, steps, critic_only, constants,
                    anchor, batch_size: int):
    """``steps`` of SBX's SAC gradient step on minibatches drawn from the first ``size`` rows of ``arrays``;
    the first ``critic_only`` of them leave the actor and the entropy coefficient as they are. ``anchor``:
    None, or (the anchor's actor parameters, its weight now) for ``_anchored_actor_update``."""
    from sbx import SAC

    tau, gamma, target_entropy = constants
    zero = jnp.zeros((), jnp.float32)
    update_actor = SAC.update_actor_and_temperature if anchor is None else partial(_anchored_actor_update, *anchor)

    def one_step(i, carry):
        qf_state, actor_state, ent_coef_state, key, info = carry
        key, draw = jax.random.split(key)
        index = jax.random.randint(draw, (batch_size,), 0, size)
        batch = {name: arrays[name][index] for name in arrays}
        dones = batch["dones"] * (1.0 - batch["timeouts"])  # a time limit bootstraps (SB3's timeout handling)
        discounts = jnp.full((batch_size,), gamma, jnp.float32)
        qf_state, (critic_loss, ent_coef_value), key = SAC.update_critic(
            actor_state, qf_state, ent_coef_state, batch["observations"], batch["actions"],
            batch["next_observations"], batch["rewards"], dones, discounts, key)
        qf_state = SAC.soft_update(tau, qf_state)
        actor_state, qf_state, ent_coef_state, actor_loss, ent_coef_loss, key = jax.lax.cond(
            i >= critic_only, update_actor,
            lambda *_: (actor_state, qf_state, ent_coef_state, info[0], info[2], key),
            actor_state, qf_state, ent_coef_state, batch["observations"], target_entropy, key)
        return qf_state, actor_state, ent_coef_state, key, (actor_loss, critic_loss, ent_coef_loss, ent_coef_value)

    carry = (qf_state, actor_state, ent_coef_state, key, (zero, zero, zero, zero))
    return jax.lax.fori_loop(0, steps, one_step, carry)


@partial(jax.jit, static_argnames="batch_size", donate_argnums=0)
def _insert_and_update(arrays, rows, position, size, qf_state, actor_state, ent_coef_state, key, steps, critic_only,
                       constants, anchor, batch_size: int):
    arrays = _write_rows(arrays, rows, position)
    return arrays, _gradient_steps(qf_state, actor_state, ent_coef_state, key, arrays, size, steps, critic_only,
                                   constants, anchor, batch_size)


@partial(jax.jit, static_argnames="batch_size")
def _update(arrays, size, qf_state, actor_state, ent_coef_state, key, steps, critic_only, constants, anchor,
            batch_size: int):
    return _gradient_steps(qf_state, actor_state, ent_coef_state, key, arrays, size, steps, critic_only, constants,
                           anchor, batch_size)


@jax.jit
def _sample_actions(actor_state, observations, key):
    """SBX's ``predict(deterministic=False)`` in one call: a new noise key split from ``key``, then actions."""
    key, noise_key = jax.random.split(key)
    return key, noise_key, actor_state.apply_fn(actor_state.params, observations).sample(seed=noise_key)


def sample_actions(policy, observations: np.ndarray) -> np.ndarray:
    """Actions of the SBX SAC ``policy`` for ``observations``, drawn as its ``predict`` draws them (the same
    keys: ``reset_noise``, then ``sample_action``), in the actor's range [-1, 1]."""
    policy.key, policy.noise_key, actions = _sample_actions(policy.actor_state, observations, policy.key)
    return np.asarray(actions)


class OverlappedUpdates:
    """A goal's transitions waiting for the ring, and the gradient steps it owes; ``pay`` runs both at once."""

    def __init__(self, model, ring: TransitionRing, inclusive_start: bool = False, anchor: Anchor | None = None):
        self.model = model
        self.ring = ring
        self.anchor = anchor
        # SB3 updates from the step after the one that reaches learning_starts; Stable Baselines 2 from
        # that very step (its first gradient step follows the learning_starts-th transition).
        self.inclusive_start = inclusive_start
        self.owed = 0
        self.owed_critic_only = 0
        self.pending: list[Experience] = []
        self.info = UpdateInfo(0.0, 0.0, 0.0, 0.0)
        self._info_arrays = None
        self.gradient_steps = 0  # paid by this goal
        self.actor_steps = 0  # of them, those that updated the actor too (not critic-only)

    def __enter__(self) -> "OverlappedUpdates":
        return self

    def __exit__(self, *exc_info) -> None:
        self.pay()

    def store(self, transitions: Experience) -> None:
        """Transitions of the last vector step, written to the ring with the next ``pay``."""
        self.pending.append(transitions)

    def owe(self, env_steps: int, critic_only: bool = False) -> None:
        """After a vector step of ``env_steps`` (before its transitions are stored), the gradient steps SB3
        would run after it: one per env step once learning started and a batch is in the buffer.

        SB3 starts updating after ``learning_starts`` (SB2, ``inclusive_start``: at it); a goal that acts with its
        policy from the first step (``learning_starts`` at the goal's start) also
        waits until the buffer holds a batch: SB3 would sample one from fewer rows.
        ``critic_only``: these gradient steps leave the actor as it is.
        """
        stored = self.ring.size + sum(len(rows["observations"]) for rows in self.pending)
        started = self.model.num_timesteps - self.model.learning_starts >= (0 if self.inclusive_start else 1)
        if started and stored >= self.model.batch_size:
            if critic_only:
                self.owed_critic_only += env_steps
            else:
                self.owed += env_steps

    def pay(self) -> None:
        """Write the pending transitions and run the owed gradient steps (critic-only ones first) in one
        compiled call; dispatched asynchronously: the model's states are JAX's futures until read."""
        steps = self.owed_critic_only + self.owed
        if not self.pending and not steps:
            return
        model, ring = self.model, self.ring
        rows = None
        if self.pending:
            rows = {name: np.concatenate([each[name] for each in self.pending]).astype(np.float32, copy=False)
                    for name in TRANSITION_ARRAYS}
            ring.check(rows)
            self.pending = []
        critic_only, self.owed_critic_only, self.owed = self.owed_critic_only, 0, 0
        if rows is not None and len(rows["observations"]) > ring.capacity:
            ring.add(rows)  # more than the ring holds at once (a tiny buffer): the newest only
            rows = None
        policy = model.policy
        # numpy scalars, not jnp's: each jnp scalar is a dispatch of its own
        constants = (np.float32(model.tau), np.float32(model.gamma), np.float32(model.target_entropy))
        states = (policy.qf_state, policy.actor_state, model.ent_coef_state, model.key)
        weight = 0.0 if self.anchor is None else self.anchor.weight_at(model.num_timesteps)
        anchor = (self.anchor.params, np.float32(weight)) if weight > 0 else None
        if rows is not None:
            count = len(rows["observations"])
            size = min(ring.size + count, ring.capacity)
            ring.arrays, result = _insert_and_update(
                ring.arrays, rows, np.int32(ring.pos), np.int32(size), *states, np.int32(steps),
                np.int32(critic_only), constants, anchor, batch_size=int(model.batch_size))
            ring.advance(count)
        elif steps:
            result = _update(ring.arrays, np.int32(ring.size), *states, np.int32(steps), np.int32(critic_only),
                             constants, anchor, batch_size=int(model.batch_size))
        else:
            return
        policy.qf_state, policy.actor_state, model.ent_coef_state, model.key, self._info_arrays = result
        model._n_updates += steps
        self.gradient_steps += steps
        self.actor_steps += steps - critic_only

    def last_info(self) -> UpdateInfo:
        """The last paid gradient step's losses and entropy coefficient, NaN where this goal has none yet:
        everything before its first gradient step, the actor's and the coefficient's losses before its first
        step that was not critic-only. Waits for the last call to finish."""
        if self._info_arrays is not None:
            self.info = UpdateInfo(*(float(value) for value in self._info_arrays))
            self._info_arrays = None
        if not self.gradient_steps:
            return UpdateInfo(math.nan, math.nan, math.nan, math.nan)
        if not self.actor_steps:
            return self.info._replace(actor_loss=math.nan, entropy_coefficient_loss=math.nan)
        return self.info

    @contextmanager
    def settled(self) -> Iterator[None]:
        """Pay, so that what is saved inside holds every step so far."""
        self.pay()
        yield

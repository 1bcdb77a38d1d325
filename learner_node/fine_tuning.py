"""What a Train goal does to the stored model it loads, before its first step (``FineTuning``).

SB3 (and SBX) load a model as it was saved: weights, and Adam's moments with
the step count of the model's whole training. A stored prior has trained on
one task, so the first-layer weights of the 48 other one-hot task bits are
still at their initial values and their Adam moments are exactly zero.
These functions give a goal's model the start its ``FineTuning`` names
(``learner_node.sac_settings`` says why each exists and what it measured).

"Trained" inputs are read from the optimiser: a task bit whose first-layer
weights ever had a gradient has a non-zero second moment; no record of which
tasks a policy trained on is needed, and a policy trained on a cluster of
tasks knows all of them.

The model is SBX's: the actor and the critics are flax ``TrainState``s
(``model.policy.actor_state``, ``qf_state``) whose optimiser is optax's Adam
inside ``inject_hyperparams``. A Dense kernel is (inputs, units); the
critics are vectorised, so each critic kernel has a leading axis of
critics, and each critic is treated on its own, as separate networks are.
JAX arrays are immutable: the functions edit numpy copies and give the
model new states.
"""

from __future__ import annotations

import copy
from dataclasses import dataclass
from typing import Callable, Sequence

import jax
import jax.numpy as jnp
import numpy as np
from flax.traverse_util import flatten_dict, unflatten_dict

from glocal_ros.tasks import NUM_TASKS, one_hot_bit
from learner_node.sac_settings import FineTuning

#: A flattened parameter tree: path (("params", "Dense_0", "kernel"), ...) -> array.
Arrays = dict[tuple[str, ...], np.ndarray]


@dataclass(frozen=True)
class InputLayer:
    """A layer that reads the observation, one-hot task bits first, with its Adam moments; (inputs, units) each."""

    weights: np.ndarray
    first_moments: np.ndarray
    second_moments: np.ndarray


def start_fine_tuning(model, tuning: FineTuning, tasks: Sequence[str]) -> None:
    """Give the freshly loaded SAC ``model`` the start ``tuning`` names for a goal on ``tasks``."""
    for name in ("actor_state", "qf_state"):
        state = _with_task_inputs(getattr(model.policy, name), tuning, tasks)
        if tuning.optimizers in ("fresh", "fresh-all"):
            state = _fresh(state)
        elif tuning.optimizers == "unseen-as-bias":
            state = _edited(state, unseen_inputs_as_bias)
        setattr(model.policy, name, state)
    if not hasattr(model, "ent_coef_state"):
        return
    if tuning.entropy_coefficient == "initial":
        # SBX's coefficient module sets its one parameter to its initial value, whatever the key.
        initial = model.ent_coef.init(jax.random.PRNGKey(0))["params"]
        model.ent_coef_state = model.ent_coef_state.replace(params=initial)
    if tuning.optimizers == "fresh-all":
        model.ent_coef_state = _fresh(model.ent_coef_state)


def goal_start_actor(model, tuning: FineTuning, tasks: Sequence[str]):
    """A copy of ``model``'s policy whose actor is the one a goal on any of ``tasks`` starts with (its task
    inputs as ``tuning`` sets them); ``model`` is unchanged. Editing the bits of all ``tasks`` at once is
    editing each on its own: a one-hot bit's first-layer weights act only on its task's observations."""
    policy = copy.copy(model.policy)
    policy.actor_state = _with_task_inputs(model.policy.actor_state, tuning, tasks)
    return policy


def _with_task_inputs(state, tuning: FineTuning, tasks: Sequence[str]):
    if tuning.new_task_inputs != "trained-mean":
        return state
    bits = [one_hot_bit(task) for task in tasks]
    return _edited(state, lambda params, mu, nu: inherit_task_inputs(params, mu, nu, bits))


def _fresh(state):
    """``state`` with its optimiser at its start: moments at zero, step 0."""
    return state.replace(opt_state=state.tx.init(state.params))


def input_layers(model) -> list[InputLayer]:
    """Copies of the layers that read the observation: the actor's, then each critic's."""
    layers = []
    for state in (model.policy.actor_state, model.policy.qf_state):
        params, mu, nu = (_flat(tree) for tree in (state.params, *_moments(state)))
        path = _input_kernel(params)
        layers += [InputLayer(*views) for views in zip(*(_per_network(arrays[path]) for arrays in (params, mu, nu)))]
    return layers


def inherit_task_inputs(params: Arrays, mu: Arrays, nu: Arrays, bits: Sequence[int]) -> None:
    """Each of ``bits`` the input layer never trained on starts as the mean of the task bits it did train on:
    weights and Adam second moments, no momentum. Nothing happens where it trained on none."""
    path = _input_kernel(params)
    for weights, first, second in zip(*(_per_network(arrays[path]) for arrays in (params, mu, nu))):
        trained = [bit for bit in range(NUM_TASKS) if second[bit].any()]
        new = [bit for bit in dict.fromkeys(bits) if bit not in trained]
        if trained and new:
            weights[new] = weights[trained].mean(axis=0)
            second[new] = second[trained].mean(axis=0)
            first[new] = 0.0


def unseen_inputs_as_bias(params: Arrays, mu: Arrays, nu: Arrays) -> None:
    """In every layer, an input whose weights never had a gradient gets the second moments of the layer's bias
    (a one-hot bit that is on is a bias), so that its weights move at the pace of the rest."""
    for path in [path for path in nu if path[-1] == "kernel"]:
        bias = path[:-1] + ("bias",)
        if bias not in nu:
            continue
        for kernel_moments, bias_moments in zip(_per_network(nu[path]), _per_network(nu[bias][..., None, :])):
            unseen = (kernel_moments == 0).all(axis=1)
            kernel_moments[unseen] = bias_moments


def _edited(state, edit: Callable[[Arrays, Arrays, Arrays], None]):
    """``state`` with ``edit(params, mu, nu)``'s in-place changes to numpy copies of its weights and Adam moments."""
    params, mu, nu = (_flat(tree) for tree in (state.params, *_moments(state)))
    edit(params, mu, nu)
    adam, *rest = state.opt_state.inner_state
    adam = adam._replace(mu=_tree(mu), nu=_tree(nu))
    return state.replace(params=_tree(params), opt_state=state.opt_state._replace(inner_state=(adam, *rest)))


def _moments(state):
    """Adam's first and second moments of a TrainState (optax's ``inject_hyperparams(adam)``: Adam comes first)."""
    adam = state.opt_state.inner_state[0]
    return adam.mu, adam.nu


def _input_kernel(params: Arrays) -> tuple[str, ...]:
    """The path of the kernel that reads the observation: flax names a network's first Dense ``Dense_0``."""
    (path,) = [path for path in params if path[-2:] == ("Dense_0", "kernel")]
    return path


def _per_network(array: np.ndarray) -> list[np.ndarray]:
    """Views of one (inputs, units) array per network: the actor's own, or each of the vectorised critics'."""
    return [array] if array.ndim == 2 else list(array)


def _flat(tree) -> Arrays:
    return {path: np.array(leaf) for path, leaf in flatten_dict(tree).items()}


def _tree(arrays: Arrays):
    return unflatten_dict({path: jnp.asarray(array) for path, array in arrays.items()})

"""Learner profiles: everything that decides how a policy learns and is scored, as one named bundle.

A profile is a parameter of learner_node (``learner_profile``), of the presets,
of ``glocal-ros launch`` / ``experiment`` / ``train-prior`` / ``bench *`` and
of the launch file. It fixes:

- the model a prior is made as (``new_model``): network, gamma, replay
  buffer, initialisation;
- how a Train goal starts from a stored policy (``fine_tuning``);
- how a time-limit end is stored (``time_limit_terminal``);
- the shipped priors the learner sees (``prior_store``): each profile has its
  own A0 ``prior`` (``glocal-ros train-prior --profile``; every profile's is
  trained the same way, ``learner_node.prior``), and a goal refuses a policy
  of another profile;
- how ``learner/evaluate`` scores a policy: as a Train goal from it would
  start, so that Evaluate and a goal's check before its first step agree on
  the same episodes (``glocal_ros``: inherited task inputs; ``paper``: the
  raw network, as Stable Baselines 2 and the paper score it).

Two profiles:

``glocal_ros``, this project's default: SBX SAC-v2, gamma 0.95 (T = 50 steps
of reward -1), a 200k buffer, and the fine-tuning measured by ``glocal-ros
bench transfer`` (parent experience, inherited task inputs:
``learner_node.sac_settings``). Its fine-tuning may be swapped for another
recipe of ``FINE_TUNING_RECIPES`` (that is what bench transfer compares).

``paper``, Stable Baselines 2's SAC with its defaults, as the paper ran it:
the paper (section "Robot Environment Setup") used "the implementation from
Stable Baselines", the SAC of hill-a/stable-baselines (here SB2), and sets
none of its hyperparameters, so the profile follows that SAC's defaults and
behaviour:
- gamma 0.99, buffer 50k, batch 64, [64, 64] ReLU, Glorot-uniform kernels
  and zero biases, learning rate 3e-4, tau 0.005, entropy coefficient
  learned from 1.0 towards a target entropy of -5;
- a goal from a stored policy starts as SB2's ``load`` + ``learn``: an empty
  buffer, 100 uniform random actions and the first gradient step right after
  the 100th transition, fresh Adam moments for the actor, the critics and
  the entropy coefficient (SB2 saves none of them; the coefficient itself is
  saved and restored), and raw task inputs: a task the policy never trained
  on is an input whose first-layer weights are still at their initial values;
- time-limit ends are terminal (SB2 has no time-limit handling). The
  project's own episode cuts (an evaluation or a checkpoint between two
  steps) still bootstrap, as the cut at the end of an SB2 ``learn()`` call
  does: SB2 stores that last transition as not done;
- one gradient step per env step: N lockstep envs take N gradient steps per
  vector step (SB3's ``gradient_steps=-1``), the same number of updates per
  sample as SB2's single env, with the policy lagging at most one vector step;
- the baselines' single policy, which SB2 would train by calling ``learn()``
  on it again, re-arms the 100 random steps at each chunk (``rearm_warm``):
  SB2's default ``reset_num_timesteps=True``, since the paper does not say
  it changed it. Its buffer, Adam moments and entropy coefficient persist,
  as in SB2.

What ``paper`` does not reproduce, and why: SB2's SAC is SAC-v1 (a V network
and its target, the actor loss on Q1 only, the update order actor, values,
entropy coefficient). This profile runs SBX's SAC-v2 (twin target Q with the
entropy term in the target, min(Q1, Q2) in the actor loss, critic first).
A SAC-v1 in SBX is a new algorithm class with its own jitted update; the
profile's other differences (buffer, random start, optimisers, task inputs,
gamma, terminal time limits) decide what a goal from a prior does in its
first thousand steps, where the paper's and this project's learners part,
and those it reproduces item by item. The variant is named here so that a
comparison can say so.

Each item, checked against SB2's source (hill-a/stable-baselines at
259f27868f0d, 2.10.2a1; ``sac`` is ``stable_baselines/sac``, ``common`` is
``stable_baselines/common``):
- time limits: ``learn`` stores the env's ``done`` as it is
  (``sac/sac.py:410,429``, ``common/base_class.py:1005``) and the target
  is ``r + (1 - done) * gamma * V_target`` (``sac/sac.py:216-219``); nothing
  in SAC or its buffer looks at a time limit;
- the 100 random actions: ``learning_starts=100`` (``sac/sac.py:61``);
  uniform random actions while ``num_timesteps < learning_starts``
  (``:394-398``), the first gradient step right after the 100th transition
  is stored (``:412,429,447,455-457``); ``learn(reset_num_timesteps=True)``
  sets ``num_timesteps`` to 0 (``common/base_class.py:173-174``), so each
  ``learn()`` call acts at random again, with the buffer kept;
- the entropy coefficient: ``log_ent_coef`` starts at log(1.0) for
  ``"auto"`` (``sac/sac.py:191-198``), is a trainable variable of the
  model and so saved and restored with the weights
  (``sac/sac.py:306-307,540-542,572-574``); Adam's moments are not
  (``common/base_class.py:448-450``);
- the one-hot inputs: the MLP's layers are ``tf.layers.dense`` with TF's
  defaults, Glorot-uniform kernels and zero biases
  (``common/tf_layers.py:55-61``, ``sac/policies.py:198-256``), [64, 64]
  ReLU (``sac/policies.py:165,175-176``), observations not scaled
  (``:167``): a task bit never on keeps its initial weights;
- SAC-v1: a V network and its target (``sac/policies.py:238-242``,
  ``sac/sac.py:205-209``), the actor's loss on Q1 alone (``:236``), one
  training step's order actor, then critics and V, then the coefficient
  (``:277-291``), the targets moved by Polyak after it (``:465-467``).

A profile with departures, ``base+departure[+departure...]`` (for example
``paper+time-limit-bootstrap``), is ``base`` with each named item changed
(``DEPARTURES``): what ``bench transfer --profiles`` ablates, one item at a
time, to find what in the paper's regime keeps goals from learning. It trains
and scores the base profile's policies (its shipped prior among them) and
its own; the policies it stores carry its full name, so the base profile
refuses them. Departures are applied in ``DEPARTURES``' order whatever order
the name gives, and the name is written in that order.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from pathlib import Path
from types import MappingProxyType
from typing import Any, Mapping

from learner_node.sac_settings import (DEFAULT_FINE_TUNING, DEFAULT_NETWORK, FINE_TUNING_RECIPES, NETWORKS,
                                       SAC_KWARGS, FineTuning, Network, fine_tuning_recipe,
                                       network)

#: SB2's ``learning_starts``: uniform random actions before the first gradient step.
SB2_LEARNING_STARTS = 100


@dataclass(frozen=True)
class LearnerProfile:
    """How a policy learns and is scored (see the module docstring for the two profiles)."""

    name: str
    network: str  # of ``learner_node.sac_settings.NETWORKS``, for new models
    sac_kwargs: Mapping[str, Any]  # of new models, on top of the network's
    glorot_init: bool  # new models' kernels Glorot-uniform (SB2, TF's default) instead of flax's lecun-normal
    fine_tuning: FineTuning  # how a goal starts from a stored policy
    time_limit_terminal: bool  # a time-limit end is stored as terminal (no bootstrap)
    prior_store: str  # the folder of assets/ holding the profile's shipped priors
    recipes: tuple[str, ...] = field(default=())  # other fine-tuning recipes it may run with
    networks: tuple[str, ...] = field(default=())  # other networks a new model may have
    base: str = ""  # a profile with departures: the profile it departs from ("": none)

    def trains_policies_of(self, profile: str) -> bool:
        """Whether a goal of this profile may start from a policy stored under ``profile``."""
        return profile in (self.name, self.base)

    def network_of(self, name: str = "") -> Network:
        """The network ``name`` where the profile allows it ("": the profile's own)."""
        if name and name != self.network and name not in self.networks:
            allowed = ", ".join(dict.fromkeys((self.network, *self.networks)))
            raise ValueError(f"network {name!r} contradicts learner profile {self.name!r} (networks it allows: "
                             f"{allowed})")
        return network(name or self.network)

    def model_kwargs(self, network_name: str = "") -> dict[str, Any]:
        """The keyword arguments of SBX's ``SAC`` for a new model of this profile."""
        return dict(self.network_of(network_name).sac_kwargs(), **self.sac_kwargs)

    def new_model(self, env, seed: int, network_name: str = ""):
        """A new SAC model of this profile on ``env`` (the prior's start)."""
        model = self.network_of(network_name).new_model(env, seed, **self.sac_kwargs)
        if self.glorot_init:
            glorot_initialise(model, seed)
        return model

    def with_recipe(self, recipe: str) -> FineTuning:
        """This profile's fine-tuning, or the recipe ``recipe`` where the profile allows it ("": its own)."""
        if not recipe:
            return self.fine_tuning
        fine_tuning_recipe(recipe)  # ValueError naming the known recipes
        if recipe not in self.recipes:
            allowed = ", ".join(self.recipes) if self.recipes else "none: it fine-tunes as SB2 does"
            raise ValueError(f"fine-tuning recipe {recipe!r} contradicts learner profile {self.name!r} "
                             f"(recipes it allows: {allowed})")
        return FINE_TUNING_RECIPES[recipe]

    def shipped_priors(self) -> Path:
        from glocal_ros.paths import assets_dir

        return assets_dir() / self.prior_store


PROFILES: dict[str, LearnerProfile] = {
    "glocal_ros": LearnerProfile(
        name="glocal_ros", network=DEFAULT_NETWORK, sac_kwargs=MappingProxyType({}), glorot_init=False,
        fine_tuning=DEFAULT_FINE_TUNING, time_limit_terminal=False, prior_store="priors",
        recipes=tuple(FINE_TUNING_RECIPES), networks=tuple(NETWORKS)),
    "paper": LearnerProfile(
        name="paper", network="64x64",
        sac_kwargs=MappingProxyType(dict(gamma=0.99, buffer_size=50_000, learning_rate=3e-4, tau=0.005,
                                         ent_coef="auto", target_entropy="auto")),
        glorot_init=True,
        fine_tuning=FineTuning(first_actions="random", random_steps=SB2_LEARNING_STARTS, rearm_warm=True,
                               optimizers="fresh-all", new_task_inputs="initial"),
        time_limit_terminal=True, prior_store="priors-paper"),
}
DEFAULT_PROFILE = "glocal_ros"


@dataclass(frozen=True)
class Departure:
    """One item of a profile changed, named: what it changes to, and what the base does instead."""

    profile_fields: Mapping[str, Any]  # fields of ``LearnerProfile`` replaced
    fine_tuning_fields: Mapping[str, Any]  # fields of its ``FineTuning`` replaced
    description: str


#: Departures from ``paper``, each one of the items in which it follows Stable Baselines 2 (the module docstring).
DEPARTURES: dict[str, dict[str, Departure]] = {
    "paper": {
        "time-limit-bootstrap": Departure(
            MappingProxyType(dict(time_limit_terminal=False)), MappingProxyType({}),
            "time-limit ends bootstrap from the next state (SB2: stored as terminal)"),
        "policy-first": Departure(
            MappingProxyType({}), MappingProxyType(dict(first_actions="policy", random_steps=None, rearm_warm=False)),
            "a goal acts with the loaded policy from its first step (SB2: 100 uniform random actions first)"),
        "initial-entropy": Departure(
            MappingProxyType({}), MappingProxyType(dict(entropy_coefficient="initial")),
            "a goal's entropy coefficient starts at a new model's 1.0 (SB2: restored from the stored policy)"),
        "trained-mean-inputs": Departure(
            MappingProxyType({}), MappingProxyType(dict(new_task_inputs="trained-mean")),
            "an untrained task bit starts as the mean of the trained ones (SB2: its initial weights)"),
    },
}
assert SAC_KWARGS["gradient_steps"] == -1  # one gradient step per env step, whatever N: both profiles rely on it


def learner_profile(name: str) -> LearnerProfile:
    """The profile called ``name``, a profile of ``PROFILES`` or one with departures (``base+departure...``);
    ``ValueError`` naming the known ones otherwise."""
    base_name, *wanted = name.split("+")
    if base_name not in PROFILES:
        raise ValueError(f"unknown learner profile {base_name!r}: choose from {', '.join(PROFILES)}")
    base = PROFILES[base_name]
    if not wanted:
        return base
    known = DEPARTURES.get(base_name, {})
    unknown = [item for item in wanted if item not in known]
    if unknown or len(set(wanted)) != len(wanted):
        choices = ", ".join(known) if known else "none"
        problem = f"unknown departure {unknown[0]!r}" if unknown else "a departure named twice"
        raise ValueError(f"learner profile {name!r}: {problem} from {base_name!r} (departures it has: {choices})")
    ordered = [item for item in known if item in wanted]
    profile_fields, tuning_fields = {}, {}
    for item in ordered:
        profile_fields.update(known[item].profile_fields)
        tuning_fields.update(known[item].fine_tuning_fields)
    return replace(base, name="+".join([base_name, *ordered]), base=base_name,
                   fine_tuning=replace(base.fine_tuning, **tuning_fields), **profile_fields)


def profile_departures(profile: LearnerProfile) -> list[str]:
    """What ``profile`` changes from its base, in words, one line per departure (none for a base profile)."""
    known = DEPARTURES.get(profile.base, {})
    return [f"{item}: {known[item].description}" for item in profile.name.split("+")[1:]]


def glorot_initialise(model, seed: int) -> None:
    """Every Dense kernel of ``model``'s actor and critics Glorot-uniform, biases zero, targets equal to the
    critics, Adam at its start: a new model as SB2 (TF's ``dense`` defaults) makes it.

    The critics are vectorised (a leading axis of critics): each critic's kernel is drawn on its own, with
    the fan-in and fan-out of one critic's layer.
    """
    import jax
    import jax.numpy as jnp
    from flax.traverse_util import flatten_dict, unflatten_dict

    key = jax.random.PRNGKey(seed)
    policy = model.policy
    for name in ("actor_state", "qf_state"):
        state = getattr(policy, name)
        flat = flatten_dict(state.params)
        for path, leaf in flat.items():
            key, draw = jax.random.split(key)
            if path[-1] == "kernel":
                fan_in, fan_out = leaf.shape[-2:]
                limit = (6.0 / (fan_in + fan_out)) ** 0.5
                flat[path] = jax.random.uniform(draw, leaf.shape, leaf.dtype, -limit, limit)
            elif path[-1] == "bias":
                flat[path] = jnp.zeros_like(leaf)
        params = unflatten_dict(flat)
        state = state.replace(params=params, opt_state=state.tx.init(params))
        if name == "qf_state":
            state = state.replace(target_params=params)
        setattr(policy, name, state)

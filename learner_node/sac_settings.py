"""SAC settings of the project, chosen for wall-clock on a 2-core CPU.

The backend is SBX (``sbx-rl``): stable-baselines3's SAC, its API, loop and
replay buffers, with the networks and gradient steps in JAX, jitted. Side by
side on this machine kind (new models learning on the grasp env with
physics, [64, 64] / 64, one thread) it trained 2.4x as many env steps per
second as stable-baselines3 on torch with 4 envs and 1.6x with one
(``glocal-ros bench backends``, ``bench/results/backends.md``). Stored
models are SBX's, as arrays and JSON (``learner_node.model_files``).

One compute thread was fastest on 2 cores (the other core steps physics);
one gradient step per env step (UTD 1) as in the paper; gamma 0.95 suits
T = 50 step episodes with a -1 per step reward. ``gradient_steps=-1`` is
SB3's "as many as env steps collected": one per env step whatever the
number of envs N, so N changes wall-clock, not sample efficiency.

A ``Network`` (hidden layers of actor and critics, and the batch) is chosen
when a model is made, that is when ``glocal-ros train-prior`` trains a
prior: ``NETWORKS`` has the paper's Stable Baselines (SB2) defaults [64, 64]
/ 64, the default since ``bench learner`` and ``bench transfer`` measured it
(a gradient step of a few ms, against 13-16 ms for [256, 256] on one
thread; as good a prior), and [256, 256] / 256, what the grasp probe of
ENVIRONMENT.md learned with. A Train goal continues a stored model, whose
network, batch, gamma and learning rate are its own; ``FineTuning`` is
what the goal chooses on top (SB3 leaves it to whoever loads a model): the
batch, the learning rate, what its replay buffer starts with (SB3: nothing)
and what the goal acts with while it fills. ``FINE_TUNING_RECIPES`` are the
recipes ``glocal-ros bench transfer`` compares.
"""

from __future__ import annotations

import os
from dataclasses import asdict, dataclass
from typing import Any, Literal

#: Compute threads of the learner's process: XLA's (JAX) and torch's (stable-baselines3's buffers).
COMPUTE_THREADS = 1
#: XLA's CPU flags for ``COMPUTE_THREADS`` = 1; XLA reads them once, when JAX makes its CPU backend.
XLA_ONE_THREAD_FLAGS = "--xla_cpu_multi_thread_eigen=false intra_op_parallelism_threads=1"


def sac_algorithm():
    """The SAC class of the learner's backend (``sbx.SAC``), its process set to ``COMPUTE_THREADS``.

    Imported on first use: JAX takes a second to import, which every
    ``glocal-ros`` command and node would pay. Besides speed, one thread
    makes a seeded evaluation a function of its seed: on two threads a
    matrix product's sums can round differently from run to run, and a long
    contact-rich episode can end otherwise (the torch prior on G6 with the
    same seeded episodes: 14 or 15 of 20 from run to run on 2 threads, 16
    every time on one). Whoever acts with or trains a model gets the class
    here first; JAX must not have made its backend before.
    """
    flags = os.environ.get("XLA_FLAGS", "")
    if XLA_ONE_THREAD_FLAGS not in flags:
        os.environ["XLA_FLAGS"] = f"{flags} {XLA_ONE_THREAD_FLAGS}".strip()
    import torch
    from sbx import SAC

    torch.set_num_threads(COMPUTE_THREADS)
    return SAC


#: (train state, its network, the optimiser's settings) -> (apply_fn, tx) of the first model loaded with them.
_SHARED_STATICS: dict[tuple, tuple] = {}


def share_compiled_code(model) -> None:
    """Give ``model``'s train states the apply functions and optimisers of the first model loaded with the same
    network and optimiser settings, so that it runs the code JAX compiled for that one.

    JAX caches compiled code by the static part of the arguments' pytrees, and a flax TrainState's static
    part is its ``apply_fn`` (a bound method of the network's Module) and ``tx`` (optax closures): every
    loaded model has new ones, so every Train goal from a stored policy compiled SBX's action and update
    functions again, about 20 s of a 40-step goal on a loaded 2-core machine. Models whose Modules and
    optimiser settings are equal compute the same functions with either. The entropy coefficient's Adam has
    its rate inside the closure (``entropy_learning_rate``), so its rate is part of its settings.
    """
    policy = model.policy
    settings = (repr(policy.optimizer_class), repr(sorted(policy.optimizer_kwargs.items())),
                float(model.lr_schedule(1)), model.initial_qf_learning_rate)
    for owner, name in ((policy, "actor_state"), (policy, "qf_state"), (model, "ent_coef_state")):
        state = getattr(owner, name)
        own = (entropy_learning_rate(model),) if name == "ent_coef_state" else ()
        key = (name, repr(state.apply_fn.__self__), settings, own)
        apply_fn, tx = _SHARED_STATICS.setdefault(key, (state.apply_fn, state.tx))
        setattr(owner, name, state.replace(apply_fn=apply_fn, tx=tx))


def entropy_learning_rate(model) -> float:
    """The learning rate of the Adam that trains ``model``'s entropy coefficient, as float32 computes with it.

    SBX makes that optimiser ``optax.adam(rate)`` with the model's rate when it builds the model, inside a
    closure, and keeps it when the model's ``learning_rate`` changes later (a goal's
    ``FineTuning.learning_rate`` moves the actor's and critics' rates, whose Adams take the rate from their
    state). The rate is read from what the optimiser does: from a state whose moments and bias corrections
    are 1, a gradient of 1 moves by exactly -rate in float32. The model's own ``learning_rate`` is returned
    when it is that number in float32 (the usual case). ``ValueError`` unless ``optax.adam`` of the rate steps
    exactly as the model's optimiser on a probe.
    """
    import jax.numpy as jnp
    import numpy as np
    import optax

    tx = model.ent_coef_state.tx
    one = jnp.ones((), jnp.float32)
    adam, *rest = tx.init(one)
    warm = (adam._replace(count=jnp.asarray(2**30, jnp.int32), mu=one, nu=one), *rest)
    rate = -float(tx.update(one, warm)[0])
    own = float(model.lr_schedule(1))
    rate = own if np.float32(own) == np.float32(rate) else rate
    probe, rebuilt = jnp.asarray([0.3, -2.0, 5e-3], jnp.float32), optax.adam(rate)
    if not np.array_equal(*(_adam_steps(optimiser, probe) for optimiser in (tx, rebuilt))):
        raise ValueError("the entropy coefficient's optimiser steps otherwise than optax's Adam of one rate")
    return rate


def _adam_steps(optimiser, probe):
    """Two steps of ``optimiser`` from its start on gradients made of ``probe``, as numpy arrays."""
    import numpy as np

    state, moves = optimiser.init(probe), []
    for gradient in (probe, -3.0 * probe):
        move, state = optimiser.update(gradient, state)
        moves.append(np.asarray(move))
    return np.stack(moves)


def seed_keys(model, seed: int) -> None:
    """Seed both of an SBX model's JAX keys: its gradient steps' and its policy's, which samples the actions.

    SBX's ``set_random_seed`` seeds the first only (and its load seeds it
    with the model's first seed): a loaded model would otherwise act with
    the noise its file left off with.
    """
    import jax

    model.key, model.policy.key = jax.random.split(jax.random.PRNGKey(seed))


#: Everything of a new model but its ``Network``.
SAC_KWARGS: dict[str, Any] = dict(
    learning_rate=3e-4,
    buffer_size=200_000,
    gamma=0.95,
    tau=0.005,
    train_freq=1,
    gradient_steps=-1,
    ent_coef="auto",
)


@dataclass(frozen=True)
class Network:
    """The hidden layers of the actor and of each critic, and the batch of a gradient step."""

    hidden: tuple[int, ...]
    batch_size: int

    def sac_kwargs(self) -> dict[str, Any]:
        """Keyword arguments of ``stable_baselines3.SAC`` for a new model with this network."""
        return dict(SAC_KWARGS, batch_size=self.batch_size, policy_kwargs=dict(net_arch=list(self.hidden)))

    def new_model(self, env, seed: int, **overrides):
        """A new SAC model of the learner's backend with this network on ``env`` (``overrides``: other kwargs)."""
        return sac_algorithm()("MlpPolicy", env, seed=seed, device="cpu", **dict(self.sac_kwargs(), **overrides))


NETWORKS: dict[str, Network] = {
    "256x256": Network(hidden=(256, 256), batch_size=256),
    "64x64": Network(hidden=(64, 64), batch_size=64),  # SB2's SAC defaults, which the paper ran
}
DEFAULT_NETWORK = "64x64"


def network(name: str) -> Network:
    """The network called ``name``; ``ValueError`` naming the known ones otherwise."""
    if name not in NETWORKS:
        raise ValueError(f"unknown network {name!r}: choose from {', '.join(NETWORKS)}")
    return NETWORKS[name]

#: Transitions a policy keeps for the goals that fine-tune it, when it keeps any (``FineTuning.experience``);
#: ``glocal-ros train-prior`` keeps this many of the prior.
EXPERIENCE_TRANSITIONS = 10_000

#: What a goal's model acts with until its first batch of transitions is in the replay buffer.
FirstActions = Literal["random", "policy"]
#: The Adam moments a goal's actor and critics (and entropy coefficient) start with (``FineTuning.optimizers``).
Optimizers = Literal["stored", "fresh", "fresh-all", "unseen-as-bias"]
#: Where the first-layer weights of a task bit the stored model never trained on start (``FineTuning``).
NewTaskInputs = Literal["initial", "trained-mean"]
#: Where a learned entropy coefficient starts (``FineTuning.entropy_coefficient``).
EntropyStart = Literal["stored", "initial"]


@dataclass(frozen=True)
class FineTuning:
    """How a Train goal trains the stored model it starts from.

    ``first_actions``: ``"random"`` is SB3's warm-up (uniform random actions
    while ``num_timesteps < learning_starts``), so a goal's first
    ``random_steps`` env steps ignore the loaded policy; ``"policy"`` acts with
    the loaded (stochastic) policy from the first step. Either way gradient
    steps start once a batch of transitions is in the buffer.

    ``random_steps``: with ``"random"``, None is one batch, SB3's way (its
    first gradient steps come with the env step after the batch); a count n
    is Stable Baselines 2's ``learning_starts``: n uniform random actions,
    and the first gradient steps right after the n-th transition.

    ``rearm_warm``: a goal that continues the previous goal's model
    (``keep_replay_buffer``) starts with ``random_steps`` random actions
    again, as each ``learn()`` call of Stable Baselines 2 does with its
    default ``reset_num_timesteps=True``; False: it goes on acting with the
    policy, SB3's ``reset_num_timesteps=False``.

    ``experience``: the goal's buffer starts with the (up to) this many
    transitions its initial policy keeps, and the policy it stores keeps the
    last this many of its buffer (``learner_node.replay_buffer``), so that a
    fine-tuned critic still sees the data its parent learned from; 0: an
    empty buffer and nothing kept, SB3's way.

    ``critic_warmup``: the gradient steps owed for a goal's first this many
    training steps update the critics (and the entropy coefficient) but not
    the actor, so that the actor's first updates follow a critic fitted to
    the new task: a task the stored model never trained on is a one-hot input
    whose first-layer weights are still at their initial values, and its Q
    there is arbitrary. Only for a model loaded from the store: a warm model
    (``keep_replay_buffer``) goes on with the critic it has. 0: SB3's way.

    ``optimizers``: the actor's and critics' Adam moments at the goal's
    start. ``"stored"``: SB3's way, the stored model's. Those carry the step
    count of the model's whole training, so Adam no longer corrects its
    moments for their start, and they are exactly zero for the weights of
    inputs the model never saw (a stored prior: every one-hot bit but its
    task's). On a new task those weights then move by about 3 to 6 times the
    learning rate per gradient step for hundreds of steps (first step
    m / sqrt(v) = 0.1 / sqrt(0.001)). ``"fresh"``: new moments for every
    weight, at step 0, as a new model's. ``"fresh-all"``: the same, and for the
    entropy coefficient's Adam too (Stable Baselines 2 saves none of the
    three). ``"unseen-as-bias"``: the stored
    moments, and an input that never had a gradient gets, in each layer, the
    second moments of that layer's bias (a one-hot bit that is on is a bias),
    so its weights start moving at the pace of the rest. Only for a model
    loaded from the store, as ``critic_warmup``.

    ``new_task_inputs``: the first-layer weights (actor and critics) of the
    goal's task bits that the stored model never trained on. ``"initial"``:
    SB3's way, their initial values, so a new task is an input the networks
    never saw and the critic's Q there is arbitrary. ``"trained-mean"``: the
    mean of the task bits it trained on, weights and Adam second moments (no
    momentum), so the model meets the new task as one it knows, and what
    differs is the object (``learner_node.fine_tuning``). The goal's check
    before its first step scores this model, not the stored one.

    ``entropy_coefficient``: where a learned entropy coefficient starts.
    ``"stored"``: the stored model's, as SB3 and Stable Baselines 2 load it.
    ``"initial"``: a new model's (1.0 for ``ent_coef="auto"``), so a goal
    explores as a new model does. Only for a model loaded from the store.

    The three below are the published remedies for a fine-tuned policy that
    first forgets its parent (the dip, in the README's glossary), each off
    by default:

    ``actor_learning_rate``: the actor's own Adam step size, the critics
    keeping the goal's ``learning_rate`` (None: the same as theirs), so the
    critics fit the new task before the actor has moved far.

    ``warm_start_steps``: WSRL's warm start (Zhou et al. 2024): the goal's
    first this many env steps act with the loaded policy and run no
    gradient step, so that the first updates see the new task's
    transitions of the policy being tuned. Needs ``first_actions="policy"``;
    with ``experience`` 0 it is WSRL's "no retained data". Only for a model
    loaded from the store.

    ``parent_anchor`` and ``anchor_decay_steps``: a behaviour-cloning term
    to the goal's starting actor (kickstarting, Schmitt et al. 2018; the
    BC-regularised fine-tuning of Wolczyk et al. 2024). The actor's loss
    gains ``weight x mean|Q(s, pi(s))| x ||mu(s) - mu_start(s)||^2`` on each
    minibatch, mu the actor's deterministic action (its mode) and |Q|
    without gradient: TD3+BC's balance of the two terms with its alpha at
    ``1 / weight`` (its 2.5 is a weight of 0.4). The
    weight falls linearly from ``parent_anchor`` at the goal's first step to
    0 at ``anchor_decay_steps`` training steps. The start is the actor the
    goal starts with (its task inputs as ``new_task_inputs`` sets them), so
    the anchor holds the starting score. Only for a model loaded from the
    store; 0: no anchor (SBX's actor update, untouched).
    """

    first_actions: FirstActions = "random"
    random_steps: int | None = None  # None: one batch
    rearm_warm: bool = False
    batch_size: int | None = None  # None: the stored model's own
    learning_rate: float | None = None  # None: the stored model's own
    experience: int = 0
    critic_warmup: int = 0
    optimizers: Optimizers = "stored"
    new_task_inputs: NewTaskInputs = "initial"
    entropy_coefficient: EntropyStart = "stored"
    actor_learning_rate: float | None = None  # None: the critics' (``learning_rate``)
    warm_start_steps: int = 0
    parent_anchor: float = 0.0
    anchor_decay_steps: int = 0

    def __post_init__(self) -> None:
        if self.first_actions not in ("random", "policy"):
            raise ValueError(f"first_actions must be 'random' or 'policy', got {self.first_actions!r}")
        if self.random_steps is not None and (self.random_steps < 1 or self.first_actions != "random"):
            raise ValueError(f"random_steps must be at least 1, and only with first_actions 'random', "
                             f"got {self.random_steps} with {self.first_actions!r}")
        if self.rearm_warm and self.random_steps is None:
            raise ValueError("rearm_warm needs random_steps")
        if self.batch_size is not None and self.batch_size < 1:
            raise ValueError(f"batch_size must be at least 1, got {self.batch_size}")
        if self.learning_rate is not None and not self.learning_rate > 0:
            raise ValueError(f"learning_rate must be positive, got {self.learning_rate}")
        if self.experience < 0:
            raise ValueError(f"experience must not be negative, got {self.experience}")
        if self.optimizers not in ("stored", "fresh", "fresh-all", "unseen-as-bias"):
            raise ValueError("optimizers must be 'stored', 'fresh', 'fresh-all' or 'unseen-as-bias', "
                             f"got {self.optimizers!r}")
        if self.new_task_inputs not in ("initial", "trained-mean"):
            raise ValueError(f"new_task_inputs must be 'initial' or 'trained-mean', got {self.new_task_inputs!r}")
        if self.entropy_coefficient not in ("stored", "initial"):
            raise ValueError(f"entropy_coefficient must be 'stored' or 'initial', got {self.entropy_coefficient!r}")
        if self.critic_warmup < 0:
            raise ValueError(f"critic_warmup must not be negative, got {self.critic_warmup}")
        if self.actor_learning_rate is not None and not self.actor_learning_rate > 0:
            raise ValueError(f"actor_learning_rate must be positive, got {self.actor_learning_rate}")
        if self.warm_start_steps < 0 or (self.warm_start_steps and self.first_actions != "policy"):
            raise ValueError(f"warm_start_steps must not be negative, and acts with the policy: it needs "
                             f"first_actions 'policy', got {self.warm_start_steps} with {self.first_actions!r}")
        if self.parent_anchor < 0 or (self.parent_anchor > 0) != (self.anchor_decay_steps > 0):
            raise ValueError(f"parent_anchor must not be negative, and an anchor needs anchor_decay_steps of at "
                             f"least 1 (and only an anchor has them), got {self.parent_anchor} over "
                             f"{self.anchor_decay_steps} steps")

    def key(self) -> dict:
        """The recipe as checkpoints and finished goals record it: the fields added after the first
        checkpoints were written appear only when set, so that those goals still resume."""
        recorded = asdict(self)
        for name, default in _ADDED_LATER.items():
            if recorded[name] == default:
                del recorded[name]
        return recorded


#: FineTuning's fields that checkpoints written before them lack, at their defaults.
_ADDED_LATER = {"actor_learning_rate": None, "warm_start_steps": 0, "parent_anchor": 0.0, "anchor_decay_steps": 0}


#: The recipes ``glocal-ros bench transfer`` measured (``bench/results/transfer*.md``). The learner's default is
#: ``parent-experience-task-inputs``: from the same prior, tasks and seeds, 24 of 24 goals of 3k steps passed B
#: (median steps to B 500; 2 collapses) where ``parent-experience`` passed 19 (2000; 12 collapses)
#: (``transfer-task-inputs.md``); the other candidates did not stop the early dip (``transfer-screening.md``).
FINE_TUNING_RECIPES: dict[str, FineTuning] = {
    "random-first": FineTuning(),  # SB3's way: an empty buffer, a batch of random actions first
    "policy-first": FineTuning(first_actions="policy"),
    "policy-first-lr1e-4": FineTuning(first_actions="policy", learning_rate=1e-4),
    "parent-experience": FineTuning(first_actions="policy", experience=EXPERIENCE_TRANSITIONS),
    "parent-experience-critic-warmup-500": FineTuning(first_actions="policy", experience=EXPERIENCE_TRANSITIONS,
                                                      critic_warmup=500),
    "parent-experience-critic-warmup-1000": FineTuning(first_actions="policy", experience=EXPERIENCE_TRANSITIONS,
                                                       critic_warmup=1000),
    "parent-experience-lr1e-4": FineTuning(first_actions="policy", experience=EXPERIENCE_TRANSITIONS,
                                           learning_rate=1e-4),
    "parent-experience-fresh-adam": FineTuning(first_actions="policy", experience=EXPERIENCE_TRANSITIONS,
                                               optimizers="fresh"),
    "parent-experience-unseen-moments": FineTuning(first_actions="policy", experience=EXPERIENCE_TRANSITIONS,
                                                   optimizers="unseen-as-bias"),
    "parent-experience-task-inputs": FineTuning(first_actions="policy", experience=EXPERIENCE_TRANSITIONS,
                                                new_task_inputs="trained-mean"),
    # The default, slowed where it dips on objects the prior fails (bench/results/transfer-wide-dip.md):
    "parent-experience-task-inputs-critic-warmup-2000": FineTuning(
        first_actions="policy", experience=EXPERIENCE_TRANSITIONS, new_task_inputs="trained-mean",
        critic_warmup=2000),
    "parent-experience-task-inputs-lr1e-4": FineTuning(
        first_actions="policy", experience=EXPERIENCE_TRANSITIONS, new_task_inputs="trained-mean",
        learning_rate=1e-4),
    # The remedies for the dip, each the default and one change (bench/results/transfer-remedies.md): a
    # decaying anchor to the starting actor (TD3+BC's alpha 2.5, gone by half of a 24,000-step screen),
    # an actor ten times slower than the critics (with and without critic warm-up), and WSRL's start
    # (2,000 steps with the policy and no update, no parent experience).
    "parent-experience-task-inputs-anchor": FineTuning(
        first_actions="policy", experience=EXPERIENCE_TRANSITIONS, new_task_inputs="trained-mean",
        parent_anchor=0.4, anchor_decay_steps=12_000),
    "parent-experience-task-inputs-slow-actor": FineTuning(
        first_actions="policy", experience=EXPERIENCE_TRANSITIONS, new_task_inputs="trained-mean",
        actor_learning_rate=3e-5),
    "parent-experience-task-inputs-slow-actor-critic-warmup-2000": FineTuning(
        first_actions="policy", experience=EXPERIENCE_TRANSITIONS, new_task_inputs="trained-mean",
        actor_learning_rate=3e-5, critic_warmup=2000),
    "task-inputs-wsrl-2000": FineTuning(first_actions="policy", new_task_inputs="trained-mean",
                                        warm_start_steps=2000),
}
DEFAULT_RECIPE = "parent-experience-task-inputs"
DEFAULT_FINE_TUNING = FINE_TUNING_RECIPES[DEFAULT_RECIPE]


def fine_tuning_recipe(name: str) -> FineTuning:
    """The recipe called ``name``; ``ValueError`` naming the known ones otherwise."""
    if name not in FINE_TUNING_RECIPES:
        raise ValueError(f"unknown fine-tuning recipe {name!r}: choose from {', '.join(FINE_TUNING_RECIPES)}")
    return FINE_TUNING_RECIPES[name]

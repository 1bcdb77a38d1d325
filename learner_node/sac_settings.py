"""SAC settings of the project, chosen for wall-clock on a 2-core CPU.

One torch thread was fastest on 2 cores (the other core steps physics);
one gradient step per env step (UTD 1) as in the paper; gamma 0.95 suits
T = 50 step episodes with a -1 per step reward. ``gradient_steps=-1`` is
SB3's "as many as env steps collected": one per env step whatever the
number of envs N, so N changes wall-clock, not sample efficiency.

A ``Network`` (hidden layers of actor and critics, and the batch) is chosen
when a model is made, that is when ``glocal-ros train-prior`` trains a
prior: ``NETWORKS`` has the project's [256, 256] / 256 (what the grasp probe
of ENVIRONMENT.md learned with) and the paper's Stable Baselines (SB2)
defaults [64, 64] / 64. A Train goal continues a stored model, whose
network, batch, gamma and learning rate are its own; ``FineTuning`` is
what the goal chooses on top (SB3 leaves it to whoever loads a model): the
batch, the learning rate, what its replay buffer starts with (SB3: nothing)
and what the goal acts with while it fills. ``FINE_TUNING_RECIPES`` are the
recipes ``glocal-ros bench transfer`` compares.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Literal

TORCH_THREADS = 1

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


NETWORKS: dict[str, Network] = {
    "256x256": Network(hidden=(256, 256), batch_size=256),
    "64x64": Network(hidden=(64, 64), batch_size=64),  # SB2's SAC defaults, which the paper ran
}
DEFAULT_NETWORK = "256x256"


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


@dataclass(frozen=True)
class FineTuning:
    """How a Train goal trains the stored model it starts from.

    ``first_actions``: ``"random"`` is SB3's warm-up (uniform random actions
    while ``num_timesteps < learning_starts``), so a goal's first batch of
    env steps ignores the loaded policy; ``"policy"`` acts with
    the loaded (stochastic) policy from the first step. Either way gradient
    steps start once a batch of transitions is in the buffer.

    ``experience``: the goal's buffer starts with the (up to) this many
    transitions its initial policy keeps, and the policy it stores keeps the
    last this many of its buffer (``learner_node.replay_buffer``), so that a
    fine-tuned critic still sees the data its parent learned from; 0: an
    empty buffer and nothing kept, SB3's way.
    """

    first_actions: FirstActions = "random"
    batch_size: int | None = None  # None: the stored model's own
    learning_rate: float | None = None  # None: the stored model's own
    experience: int = 0

    def __post_init__(self) -> None:
        if self.first_actions not in ("random", "policy"):
            raise ValueError(f"first_actions must be 'random' or 'policy', got {self.first_actions!r}")
        if self.batch_size is not None and self.batch_size < 1:
            raise ValueError(f"batch_size must be at least 1, got {self.batch_size}")
        if self.learning_rate is not None and not self.learning_rate > 0:
            raise ValueError(f"learning_rate must be positive, got {self.learning_rate}")
        if self.experience < 0:
            raise ValueError(f"experience must not be negative, got {self.experience}")


#: The recipes ``glocal-ros bench transfer`` measured (``bench/results/transfer*.md``); the learner's default is
#: ``parent-experience``: from the same prior, tasks and seeds, 14 of 24 goals of 3k steps ended above B
#: (median final score 16/20) where SB3's way (``random-first``) ended 6 of 24 above it (10.5/20).
FINE_TUNING_RECIPES: dict[str, FineTuning] = {
    "random-first": FineTuning(),  # SB3's way: an empty buffer, a batch of random actions first
    "policy-first": FineTuning(first_actions="policy"),
    "policy-first-lr1e-4": FineTuning(first_actions="policy", learning_rate=1e-4),
    "parent-experience": FineTuning(first_actions="policy", experience=EXPERIENCE_TRANSITIONS),
}
DEFAULT_RECIPE = "parent-experience"
DEFAULT_FINE_TUNING = FINE_TUNING_RECIPES[DEFAULT_RECIPE]


def fine_tuning_recipe(name: str) -> FineTuning:
    """The recipe called ``name``; ``ValueError`` naming the known ones otherwise."""
    if name not in FINE_TUNING_RECIPES:
        raise ValueError(f"unknown fine-tuning recipe {name!r}: choose from {', '.join(FINE_TUNING_RECIPES)}")
    return FINE_TUNING_RECIPES[name]

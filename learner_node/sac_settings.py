"""SAC settings of the project, chosen for wall-clock on a 2-core CPU.

One torch thread was fastest on 2 cores (the other core steps physics);
[256, 256] networks, batch 256 and one gradient step per env step (UTD 1)
are what the grasp probe of ENVIRONMENT.md learned with; gamma 0.95 suits
T = 50 step episodes with a -1 per step reward. ``gradient_steps=-1`` is
SB3's "as many as env steps collected": one per env step whatever the
number of envs N, so N changes wall-clock, not sample efficiency.

A Train goal continues a stored model, whose network, gamma and learning
rate are its own; ``FineTuning`` is what the goal chooses on top (SB3 leaves
it to whoever loads a model): the batch, the learning rate, and what the
goal does while its empty replay buffer fills. ``FINE_TUNING_RECIPES`` are
the recipes ``glocal-ros bench transfer`` compares.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Literal

TORCH_THREADS = 1

SAC_KWARGS: dict[str, Any] = dict(
    learning_rate=3e-4,
    buffer_size=200_000,
    batch_size=256,
    gamma=0.95,
    tau=0.005,
    train_freq=1,
    gradient_steps=-1,
    ent_coef="auto",
    policy_kwargs=dict(net_arch=[256, 256]),
)

#: What a goal's model acts with until its first batch of transitions is in the replay buffer.
FirstActions = Literal["random", "policy"]


@dataclass(frozen=True)
class FineTuning:
    """How a Train goal trains the stored model it starts from.

    ``first_actions``: ``"random"`` is SB3's warm-up (uniform random actions
    while ``num_timesteps < learning_starts``), so a goal's first
    ``batch_size`` env steps ignore the loaded policy; ``"policy"`` acts with
    the loaded (stochastic) policy from the first step. Either way gradient
    steps start once a batch of the goal's transitions is in the buffer.
    """

    first_actions: FirstActions = "random"
    batch_size: int = SAC_KWARGS["batch_size"]
    learning_rate: float | None = None  # None: the stored model's own

    def __post_init__(self) -> None:
        if self.first_actions not in ("random", "policy"):
            raise ValueError(f"first_actions must be 'random' or 'policy', got {self.first_actions!r}")
        if self.batch_size < 1:
            raise ValueError(f"batch_size must be at least 1, got {self.batch_size}")
        if self.learning_rate is not None and not self.learning_rate > 0:
            raise ValueError(f"learning_rate must be positive, got {self.learning_rate}")


#: The project's recipe (the learner's default) and the candidates measured against it.
FINE_TUNING_RECIPES: dict[str, FineTuning] = {
    "random-first": FineTuning(),
    "policy-first": FineTuning(first_actions="policy"),
    "policy-first-lr1e-4": FineTuning(first_actions="policy", learning_rate=1e-4),
}
DEFAULT_RECIPE = "random-first"
DEFAULT_FINE_TUNING = FINE_TUNING_RECIPES[DEFAULT_RECIPE]


def fine_tuning_recipe(name: str) -> FineTuning:
    """The recipe called ``name``; ``ValueError`` naming the known ones otherwise."""
    if name not in FINE_TUNING_RECIPES:
        raise ValueError(f"unknown fine-tuning recipe {name!r}: choose from {', '.join(FINE_TUNING_RECIPES)}")
    return FINE_TUNING_RECIPES[name]

"""SAC's gradient steps run during the next env step, where a remote sim leaves the learner idle.

stable-baselines3's off-policy loop alternates: collect a vector step (N env
steps), then do its gradient steps. With the envs in sim_node a step is a
round trip during which the learner only waits, while the gradient steps
are the learner's own work. ``OverlappedUpdates`` takes the loop's gradient
steps out of it and pays them during the next step (``BatchVecEnv``'s
``while_stepping``): the sim computes step t+1 while the learner does step
t's updates.

What changes for SAC: the action of step t+1 comes from a policy without the
updates of step t (a lag of one vector step); the number of gradient steps,
their batches and when learning starts are SB3's. The owed steps are paid
before anything looks at the model (evaluation, checkpoint, store), so the
saved models and the goal's outcome are those of the plain loop's order.

A goal may owe some gradient steps as critic-only (``FineTuning.critic_warmup``):
SBX's own ``train`` with its actor updates delayed past them, so the critics
and their targets update, and the actor and the entropy coefficient (which
SBX updates with the actor) do not.
"""

from __future__ import annotations

from contextlib import contextmanager
from typing import Iterator


class OverlappedUpdates:
    """Within ``with``, ``model.learn`` collects only; ``pay`` runs the gradient steps it owes."""

    def __init__(self, model, inclusive_start: bool = False):
        self.model = model
        # SB3 updates from the step after the one that reaches learning_starts; Stable Baselines 2 from
        # that very step (its first gradient step follows the learning_starts-th transition).
        self.inclusive_start = inclusive_start
        self.owed = 0
        self.owed_critic_only = 0
        self._gradient_steps = model.gradient_steps  # the model's own setting, restored on exit

    def __enter__(self) -> "OverlappedUpdates":
        self.model.gradient_steps = 0  # SB3's loop skips its own updates at 0
        return self

    def __exit__(self, *exc_info) -> None:
        try:
            self.pay()
        finally:
            self.model.gradient_steps = self._gradient_steps

    def owe(self, env_steps: int, critic_only: bool = False) -> None:
        """After a vector step of ``env_steps`` that SB3 would follow with updates: what it would do.

        SB3 starts updating after ``learning_starts`` (SB2, ``inclusive_start``: at it); a goal that acts with its
        policy from the first step (``learning_starts`` at the goal's start) also
        waits until the buffer holds a batch: SB3 would sample one from fewer rows.
        ``critic_only``: these gradient steps leave the actor as it is.
        """
        buffer = self.model.replay_buffer
        batch_in = buffer.size() * buffer.n_envs >= self.model.batch_size  # size(): rows of n_envs transitions
        started = self.model.num_timesteps - self.model.learning_starts >= (0 if self.inclusive_start else 1)
        if started and batch_in:
            steps = self._gradient_steps if self._gradient_steps >= 0 else env_steps
            if critic_only:
                self.owed_critic_only += steps
            else:
                self.owed += steps

    def pay(self) -> None:
        """Run the owed gradient steps now, in the order they were owed (critic-only ones come first)."""
        if self.owed_critic_only > 0:
            owed, self.owed_critic_only = self.owed_critic_only, 0
            with actor_paused(self.model, owed):
                self.model.train(gradient_steps=owed, batch_size=self.model.batch_size)
        if self.owed > 0:
            owed, self.owed = self.owed, 0
            self.model.train(gradient_steps=owed, batch_size=self.model.batch_size)

    @contextmanager
    def settled(self) -> Iterator[None]:
        """Pay, and show the model's own settings while it is saved."""
        self.pay()
        overlapping = self.model.gradient_steps
        self.model.gradient_steps = self._gradient_steps
        try:
            yield
        finally:
            self.model.gradient_steps = overlapping


@contextmanager
def actor_paused(model, gradient_steps: int) -> Iterator[None]:
    """SBX's next ``gradient_steps`` update the critics only.

    SBX updates the actor at the i-th gradient step of a ``train`` call when
    ``(offset + i) % policy_delay == 0``, with ``offset = (n_updates + 1) %
    policy_delay``: a delay longer than the call and an offset of 1 leave no
    such step. The model's own delay and update count are back on exit.
    """
    policy_delay, updates = model.policy_delay, model._n_updates
    model.policy_delay, model._n_updates = gradient_steps + 1, 0
    try:
        yield
    finally:
        model.policy_delay, model._n_updates = policy_delay, updates + gradient_steps

"""What a Train goal does to the stored model it loads, before its first step (``FineTuning``).

SB3 loads a model as it was saved: weights, and Adam's moments with the step
count of the model's whole training. A stored prior has trained on one task,
so the first-layer weights of the 48 other one-hot task bits are still at
their initial values and their Adam moments are exactly zero. These
functions give a goal's model, in place, the start its ``FineTuning`` names
(``learner_node.sac_settings`` says why each exists and what it measured).

"Trained" inputs are read from the optimiser: a task bit whose first-layer
weights ever had a gradient has a non-zero second moment; no record of which
tasks a policy trained on is needed, and a policy trained on a cluster of
tasks knows all of them.
"""

from __future__ import annotations

from typing import Sequence

import torch

from glocal_ros.tasks import NUM_TASKS, task_index
from learner_node.sac_settings import FineTuning


def start_fine_tuning(model, tuning: FineTuning, tasks: Sequence[str]) -> None:
    """Give the freshly loaded SAC ``model`` the start ``tuning`` names for a goal on ``tasks``."""
    if tuning.new_task_inputs == "trained-mean":
        for layer, optimizer in first_layers(model):
            inherit_task_inputs(layer, optimizer, [task_index(task) for task in tasks])
    for network in (model.actor, model.critic):
        start_moments(network, tuning.optimizers)


def first_layers(model) -> list[tuple[torch.nn.Linear, torch.optim.Optimizer]]:
    """The layers that read the observation, one-hot task bits first: the actor's and each critic's."""
    return ([(model.actor.latent_pi[0], model.actor.optimizer)]
            + [(q_network[0], model.critic.optimizer) for q_network in model.critic.q_networks])


def inherit_task_inputs(layer: torch.nn.Linear, optimizer: torch.optim.Optimizer, bits: Sequence[int]) -> None:
    """Each of ``bits`` the layer never trained on starts as the mean of the task bits it did train on:
    weights and Adam second moments, no momentum. Nothing happens when it trained on none."""
    state = optimizer.state.get(layer.weight)
    if not state:
        return
    second = state["exp_avg_sq"]
    trained = [bit for bit in range(NUM_TASKS) if second[:, bit].any()]
    new = [bit for bit in dict.fromkeys(bits) if bit not in trained]
    if not trained or not new:
        return
    with torch.no_grad():
        layer.weight[:, new] = layer.weight[:, trained].mean(dim=1, keepdim=True)
    second[:, new] = second[:, trained].mean(dim=1, keepdim=True)
    state["exp_avg"][:, new] = 0.0


def start_moments(network, optimizers: str) -> None:
    """Give ``network``'s Adam the moments ``FineTuning.optimizers`` names."""
    state = network.optimizer.state
    if optimizers == "fresh":
        state.clear()  # Adam makes new moments, step 0, at its next step
    elif optimizers == "unseen-as-bias":
        for layer in network.modules():
            if isinstance(layer, torch.nn.Linear) and layer.bias is not None and layer.weight in state:
                weight_moments, bias_moments = state[layer.weight]["exp_avg_sq"], state[layer.bias]["exp_avg_sq"]
                unseen = (weight_moments == 0).all(dim=0)
                weight_moments[:, unseen] = bias_moments[:, None]

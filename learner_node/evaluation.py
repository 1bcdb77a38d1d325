"""The paper's score, computed over a batch of envs: successes out of S-bar episodes.

ROS-free: ``evaluate`` drives any ``glocal_ros.sim_contract.BatchStepper``
(the sim's in-process batch, or the sim node's client), so it is tested
against real envs in-process and runs over the graph unchanged.

Every requested episode is one job. The envs take the jobs in turn: a
sim step carries only the envs that run a job (``env_indices``), so envs
beyond the jobs wait and cost nothing, and each env holds the job it starts
when its current episode ends (the sim starts it at once). The envs of the
first jobs are spread over the batch (``spread``), so that an evaluation of
fewer episodes than envs still keeps each worker process of a sim busy.

Seeds: with ``seed`` s, the first reset puts every env on the first task
and env k's episode gets s + k; the envs whose first job is of another task
are reset to it, the k-th of them with s + N + k (N envs); later episodes
continue each env's random stream. So a seeded evaluation is the same
episodes on the same sim, whoever runs it.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass
from typing import Callable, Sequence

import numpy as np

from glocal_ros.sim_contract import PHASE_EVAL, BatchStepper

#: ``policy(observations (N, obs_dim)) -> actions (N, action_dim)``.
BatchPolicy = Callable[[np.ndarray], np.ndarray]


@dataclass(frozen=True)
class Score:
    task: str
    successes: int
    episodes: int


def evaluate(
    envs: BatchStepper,
    policy: BatchPolicy,
    tasks: Sequence[str],
    episodes: int,
    policy_name: str = "",
    seed: int | None = None,
    global_step: int = 0,
) -> list[Score]:
    """Run ``episodes`` episodes of ``policy`` on each task; scores in the order of ``tasks``."""
    if episodes < 1:
        raise ValueError(f"episodes must be at least 1, got {episodes}")
    if not tasks:
        raise ValueError("no task to evaluate")
    jobs = deque(task for task in tasks for _ in range(episodes))
    successes = {task: 0 for task in tasks}
    seeds = [] if seed is None else [seed]
    observations, _ = envs.reset((), [tasks[0]], seeds, PHASE_EVAL, policy_name)
    num_envs = len(observations)
    running: dict[int, str] = {}  # env -> task of the counted episode it runs
    for env in spread(num_envs)[:len(jobs)]:
        running[env] = jobs.popleft()
    other_task = sorted(env for env, task in running.items() if task != tasks[0])
    if other_task:
        restarted, _ = envs.reset(other_task, [running[env] for env in other_task],
                                  [] if seed is None else [seed + num_envs], PHASE_EVAL, policy_name)
        observations[other_task] = restarted
    reserved = {env: jobs.popleft() if jobs else "" for env in sorted(running)}  # the job after this one

    while running:
        stepped = sorted(running)
        result = envs.step(policy(observations[stepped]), [reserved[env] for env in stepped], PHASE_EVAL,
                           policy_name, global_step, stepped)
        observations[stepped] = result.observations
        for row in np.flatnonzero(result.terminated | result.truncated):
            env = stepped[row]
            successes[running[env]] += int(result.is_success[row])
            if reserved[env]:
                running[env], reserved[env] = reserved[env], jobs.popleft() if jobs else ""
            else:
                del running[env]
    return [Score(task, successes[task], episodes) for task in tasks]


def spread(num_envs: int) -> list[int]:
    """The env indices in an order that spreads any first k of them over the batch: by their bit-reversed
    value (16 envs: 0, 8, 4, 12, 2, ...), so that k envs of a batch split into consecutive shares fall
    into different shares."""
    bits = max(1, (num_envs - 1).bit_length())
    return sorted(range(num_envs), key=lambda index: int(f"{index:0{bits}b}"[::-1], 2))

"""The paper's score, computed over a batch of envs: successes out of S-bar episodes.

ROS-free: ``evaluate`` drives any ``glocal_ros.sim_contract.BatchStepper``
(the sim's in-process batch, or the sim node's client), so it is tested
against real envs in-process and runs over the graph unchanged.

Every requested episode is one job; all envs work through the job queue at
once, each env holding the job it will start when its current episode ends.
Episodes started after the queue ran dry are left running and reach the
record as ``interrupted`` at the next reset: they are never counted.
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
    remaining = len(jobs)

    # Every env starts on the first task (the batch size is known from the reset);
    # an env beyond that task's jobs runs one uncounted episode before its first job.
    observations, _ = envs.reset((), [tasks[0]], [] if seed is None else [seed], PHASE_EVAL, policy_name)
    num_envs = len(observations)
    running = [tasks[0]] * num_envs
    counted = []
    for _ in range(num_envs):
        counted.append(bool(jobs) and jobs[0] == tasks[0])
        if counted[-1]:
            jobs.popleft()
    # The job each env starts when its current episode ends ("" = none left: an uncounted extra).
    reserved = [jobs.popleft() if jobs else "" for _ in range(num_envs)]

    while remaining > 0:
        result = envs.step(policy(observations), reserved, PHASE_EVAL, policy_name, global_step)
        ended = np.flatnonzero(result.terminated | result.truncated)
        for i in ended:
            if counted[i]:
                remaining -= 1
                successes[running[i]] += int(result.is_success[i])
            counted[i] = bool(reserved[i])
            running[i] = reserved[i] or running[i]
            reserved[i] = jobs.popleft() if jobs else ""
        observations = result.observations
    return [Score(task, successes[task], episodes) for task in tasks]

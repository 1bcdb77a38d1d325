"""The paper's baselines: one policy trained on tasks drawn by a sampler.

``random`` draws each episode's task uniformly; ``alp_gmm_250`` and
``alp_gmm_10`` draw them with ALP-GMM refitted every 250 or 10 episodes
(``glocal_ros.curriculum.alp_gmm``). The policy trains through a series of
Train goals, each a chunk of episodes whose tasks the sampler drew, and
keeps its replay buffer across them, so it is one continuous SAC run.

The paper's fairness rule: every ``baseline_eval_interval`` training steps
(and when the budget is spent) the policy is evaluated on every unlearned
task, and a copy is saved for each task whose score passes B.

Choices:
- A chunk is ``baseline_chunk_episodes`` episodes for ``random`` and
  ``fit_rate`` episodes for ALP-GMM (so the GMM sees every chunk's returns
  before it draws the next), with the budget of that many full-length
  episodes; the learner cycles through the drawn tasks if episodes end early.
- Samplers draw from every task of the run, learned or not, as the original
  single-policy methods do.
"""

from __future__ import annotations

from typing import Protocol

import numpy as np

from glocal_ros.curriculum.alp_gmm import AlpGmmSampler
from glocal_ros.curriculum.learner import TrainRequest, passes_threshold
from glocal_ros.curriculum.codes import ROLE_SAMPLED
from glocal_ros.curriculum.run import Run


class TaskSampler(Protocol):
    def sample(self) -> str: ...

    def update(self, task: str, episode_return: float) -> None: ...


class UniformSampler:
    def __init__(self, tasks: list[str], seed: int):
        self.tasks = list(tasks)
        self._rng = np.random.default_rng(seed)

    def sample(self) -> str:
        return self.tasks[int(self._rng.integers(len(self.tasks)))]

    def update(self, task: str, episode_return: float) -> None:
        pass


def run_random(run: Run, max_episode_steps: int) -> None:
    sampler = UniformSampler(list(run.config.tasks), run.config.seed)
    run_sampled(run, sampler, run.config.baseline_chunk_episodes, max_episode_steps)


def run_alp_gmm(run: Run, fit_rate: int, max_episode_steps: int) -> None:
    sampler = AlpGmmSampler(list(run.config.tasks), fit_rate=fit_rate, seed=run.config.seed)
    run_sampled(run, sampler, fit_rate, max_episode_steps)


def run_sampled(run: Run, sampler: TaskSampler, chunk_episodes: int, max_episode_steps: int) -> None:
    """Train one policy on sampled tasks until the budget is spent or every task is learned."""
    config = run.config
    policy = config.policy_name("policy")
    initial = config.initial_policy
    next_evaluation = config.baseline_eval_interval
    run.begin_iteration(1)
    while not run.over:
        tasks = tuple(sampler.sample() for _ in range(chunk_episodes))
        result = run.train(ROLE_SAMPLED, TrainRequest(
            task="", episode_tasks=tasks, initial_policy=initial, output_policy=policy,
            step_budget=chunk_episodes * max_episode_steps, stop_when_learned=False, keep_replay_buffer=True,
        ))
        initial = policy
        run.set_current_policy(policy)
        for episode in result.episodes:
            sampler.update(episode.task, episode.episode_return)
        if run.state.total_steps >= next_evaluation or run.steps_left == 0:
            next_evaluation = run.state.total_steps + config.baseline_eval_interval
            _save_passing_tasks(run, policy)
    run.finish()


def _save_passing_tasks(run: Run, policy: str) -> None:
    """The fairness rule: a copy of the policy for each unlearned task whose score passes B."""
    remaining = list(run.state.remaining_tasks)
    for task, score in run.evaluate(policy, remaining).items():
        if passes_threshold(score, run.config.threshold):
            copy = run.config.policy_name(task)
            run.learner.copy(policy, copy)
            run.mark_learned(task, copy)

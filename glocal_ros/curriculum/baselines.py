"""The paper's baselines: one policy trained on tasks drawn by a sampler.

``random`` draws each episode's task uniformly; ``alp_gmm_250`` and
``alp_gmm_10`` draw them with ALP-GMM refitted every 250 or 10 episodes
(``glocal_ros.curriculum.alp_gmm``). The policy trains through a series of
Train goals, each a chunk of episodes whose tasks the sampler drew, and
keeps its replay buffer across them, so it is one continuous SAC run.

The paper's fairness rule: the policy is evaluated on every unlearned task
at step 0 (GloCAL too credits the tasks its prior already passes), every
``baseline_eval_interval`` training steps on a fixed schedule, and when the
budget is spent; a copy is saved for each task whose score passes B.

Choices:
- A goal ends after a chunk of finished episodes (``episode_limit``), not
  after a number of steps: ``baseline_chunk_episodes`` for ``random``, and
  for ALP-GMM the episodes until its next refit; or at the next scheduled
  evaluation, when that comes first, so that the policy is evaluated at
  k x ``baseline_eval_interval`` steps exactly (a lockstep learner may stop
  up to N - 1 steps short of it), not at the end of the goal past it. Left
  so, an ALP-GMM-250 goal (250 episodes, up to 12,500 steps at T = 50) ran
  past several evaluations of a small budget. The next goal finishes the
  chunk: ALP-GMM then refits after the same number of episodes. So ALP-GMM-10 refits every
  10 episodes and the next episodes are fresh draws from the refitted GMM:
  draws from one fixed GMM are independent, so drawing a chunk's tasks at
  once is drawing each episode's task from the current GMM, as the original
  does. A goal lists ``TASKS_AHEAD`` draws beyond its chunk: with N
  lockstep envs the learner takes 1 + 2N tasks before the first episode
  ends (a probe reset, N running, N queued for the sim's auto-reset), and up
  to N - 1 episodes are still running when the chunk's last one ends (cut
  at the goal's end, they train but report no return). With more than 16
  envs the listed tasks would cycle. Its step budget is the chunk's
  full-length episodes, and at least ``MAX_LOCKSTEP_ENVS`` of them: N
  lockstep envs finish k full-length episodes only after N x ceil(k / N) x T
  steps, so a chunk of k steps' worth ends up to N - 1 episodes short, and a
  remainder below N would finish none; ALP-GMM, whose next chunk is the
  remainder, then never refitted (with N = 4 it drew from its first GMM, or
  uniformly, for the rest of a run, each goal 100 steps long).
- ``baseline_tasks`` (default ``all``): the samplers draw from every task of
  the run, learned or not. The paper describes random as "randomly selecting
  objects for training" with "a single policy", and for ALP-GMM changes the
  original only by saving the above-threshold policies; neither says a
  learned object leaves the pool, and a single policy that stops seeing the
  objects it learned can forget them. ``unlearned`` drops a task from the
  sampler once a copy has learned it, which spends the budget on what is
  left: a stronger baseline than the paper ran, for those who want it.
"""

from __future__ import annotations

from typing import Callable, Protocol

import numpy as np

from glocal_ros.curriculum.alp_gmm import AlpGmmSampler
from glocal_ros.curriculum.learner import TrainGoal, passes_threshold
from glocal_ros.curriculum.codes import ROLE_SAMPLED
from glocal_ros.curriculum.run import Run


#: The most lockstep envs a baseline's goal is sized for (see the module doc).
MAX_LOCKSTEP_ENVS = 16
#: Draws listed beyond a goal's chunk of episodes: enough for N <= MAX_LOCKSTEP_ENVS.
TASKS_AHEAD = 1 + 2 * MAX_LOCKSTEP_ENVS


class TaskSampler(Protocol):
    def sample(self) -> str: ...

    def update(self, task: str, episode_return: float) -> None: ...

    def retire(self, task: str) -> None:
        """Draw ``task`` no more (it may still be updated with episodes drawn before)."""


class UniformSampler:
    def __init__(self, tasks: list[str], seed: int):
        self.tasks = list(tasks)
        self._rng = np.random.default_rng(seed)

    def sample(self) -> str:
        return self.tasks[int(self._rng.integers(len(self.tasks)))]

    def update(self, task: str, episode_return: float) -> None:
        pass

    def retire(self, task: str) -> None:
        if len(self.tasks) == 1:
            raise ValueError(f"{task!r} is the last task to draw")
        self.tasks.remove(task)


def run_random(run: Run, max_episode_steps: int) -> None:
    sampler = UniformSampler(list(run.config.tasks), run.config.seed)
    run_sampled(run, sampler, lambda: run.config.baseline_chunk_episodes, max_episode_steps)


def run_alp_gmm(run: Run, fit_rate: int, max_episode_steps: int) -> None:
    sampler = AlpGmmSampler(list(run.config.tasks), fit_rate=fit_rate, seed=run.config.seed)
    run_sampled(run, sampler, lambda: sampler.updates_before_refit, max_episode_steps)


def run_sampled(run: Run, sampler: TaskSampler, chunk_episodes: Callable[[], int], max_episode_steps: int) -> None:
    """Train one policy on sampled tasks until the budget is spent or every task is learned."""
    config = run.config
    policy = config.policy_name("policy")
    initial = config.initial_policy
    run.begin_iteration(1)
    _save_passing_tasks(run, sampler, initial)
    next_evaluation = config.baseline_eval_interval
    while not run.over:
        chunk = chunk_episodes()
        tasks = tuple(sampler.sample() for _ in range(chunk + TASKS_AHEAD))
        to_evaluation = next_evaluation - run.state.total_steps
        chunk_steps = max(chunk, MAX_LOCKSTEP_ENVS) * max_episode_steps
        result = run.train(ROLE_SAMPLED, TrainGoal(
            task="", episode_tasks=tasks, episode_limit=chunk, initial_policy=initial, output_policy=policy,
            step_budget=min(chunk_steps, to_evaluation), stop_when_learned=False,
            keep_replay_buffer=True,
        ))
        initial = policy
        run.set_current_policy(policy)
        for episode in result.episodes:
            sampler.update(episode.task, episode.episode_return)
        # A goal cut at the evaluation's step ends there, or up to N - 1 steps short of it (lockstep).
        cut_for_evaluation = chunk_steps > to_evaluation and len(result.episodes) < chunk
        if run.state.total_steps >= next_evaluation or cut_for_evaluation or run.steps_left == 0:
            next_evaluation += config.baseline_eval_interval
            while next_evaluation <= run.state.total_steps:
                next_evaluation += config.baseline_eval_interval
            _save_passing_tasks(run, sampler, policy)
    run.finish()


def _save_passing_tasks(run: Run, sampler: TaskSampler, policy: str) -> None:
    """The fairness rule: a copy of the policy for each unlearned task whose score passes B."""
    remaining = list(run.state.remaining_tasks)
    for task, score in run.evaluate(policy, remaining).items():
        if passes_threshold(score, run.config.threshold):
            copy = run.config.policy_name(task)
            run.copy(policy, copy)
            run.mark_learned(task, copy)
            if run.config.baseline_tasks == "unlearned" and not run.over:
                sampler.retire(task)

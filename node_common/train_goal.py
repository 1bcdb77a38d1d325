"""A Train goal as a message: the one translation between ``TrainGoal`` and ``Train.Goal``.

The message keeps ROS's defaults for what a caller may leave out, as
sentinels (glocal_interfaces/action/Train.action): ``threshold`` negative for
the paper's B (0.75 x S-bar), ``eval_episodes`` 0 for the paper's S-bar (100),
``seed`` -1 for the learner's own streams. ``TrainGoal`` holds what they
mean; the curriculum sends goals with ``goal_message`` and the learner reads
them with ``goal_from_message``, so a goal reaches the learner as the
curriculum made it (``test/test_train_goal.py``).
"""

from __future__ import annotations

import math

from glocal_interfaces.action import Train

from glocal_ros.curriculum.learner import PAPER_EVAL_EPISODES, TrainGoal, paper_threshold

#: ``Train.Goal.seed`` of a goal without a seed.
NO_SEED = -1


def goal_message(goal: TrainGoal) -> Train.Goal:
    """``goal`` as the Train action sends it (every field given: no sentinel but the seed's)."""
    return Train.Goal(
        task=goal.task, episode_tasks=list(goal.episode_tasks), episode_limit=goal.episode_limit,
        initial_policy=goal.initial_policy, output_policy=goal.output_policy, step_budget=goal.step_budget,
        threshold=float(goal.threshold), eval_episodes=goal.eval_episodes, eval_interval=goal.eval_interval,
        stop_when_learned=goal.stop_when_learned, keep_replay_buffer=goal.keep_replay_buffer,
        seed=NO_SEED if goal.seed is None else goal.seed,
    )


def goal_from_message(message: Train.Goal) -> TrainGoal:
    """The goal a Train message asks for, its sentinels resolved; ``ValueError`` for a NaN threshold
    (the learner's ``check_goal`` checks the rest)."""
    if math.isnan(message.threshold):
        raise ValueError("threshold is NaN: give B as a number of successes (negative: 0.75 x eval_episodes)")
    eval_episodes = message.eval_episodes or PAPER_EVAL_EPISODES
    return TrainGoal(
        task=message.task, initial_policy=message.initial_policy, output_policy=message.output_policy,
        step_budget=message.step_budget,
        threshold=message.threshold if message.threshold >= 0 else paper_threshold(eval_episodes),
        eval_episodes=eval_episodes, episode_tasks=tuple(message.episode_tasks),
        episode_limit=message.episode_limit, eval_interval=message.eval_interval,
        stop_when_learned=message.stop_when_learned, keep_replay_buffer=message.keep_replay_buffer,
        seed=None if message.seed < 0 else message.seed,
    )

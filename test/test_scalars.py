"""A Train goal's training curves (``learner_node.scalars``): what tensorboard reads is what the learner reported.

A real goal in-process (the shipped prior on A0, real SAC updates, real
physics), every vector step reported; its event files read back with
tensorboard's own reader, as ``tensorboard --logdir`` lists them, and its CSV.
The graph-level check (the bag's messages against the run's event files) is
in ``test_namespace.py``.
"""

from __future__ import annotations

import csv
import math

import numpy as np
import pytest
from tensorboard.backend.event_processing.event_multiplexer import EventMultiplexer

from glocal_ros.paths import assets_dir
from learner_node.policies import PolicyRegistry
from learner_node.policy_store import PolicyStore
from learner_node.scalars import CSV_COLUMNS, CSV_FILE, EVALUATION_TAGS, PROGRESS_TAGS, GoalScalars
from glocal_ros.curriculum.learner import TrainGoal
from learner_node.training import Trainer
from sim_node.batch import BatchedEnvs
from sim_node.grasp_env import GraspEnv, GraspEnvConfig


def read_runs(logdir) -> dict[str, dict[str, list[tuple[int, float]]]]:
    """{run: {tag: [(step, value), ...]}} as tensorboard lists a log directory."""
    runs = EventMultiplexer().AddRunsFromDirectory(str(logdir))
    runs.Reload()
    return {run: {tag: [(event.step, event.value) for event in runs.Scalars(run, tag)]
                  for tag in runs.Runs()[run]["scalars"]} for run in runs.Runs()}


@pytest.fixture(scope="module")
def goal(tmp_path_factory):
    """A 40-step goal reported at every vector step, evaluated every 20 steps; what it told its owner."""
    work = tmp_path_factory.mktemp("scalars")
    envs = BatchedEnvs(lambda i: GraspEnv("A0", config=GraspEnvConfig(max_steps=10)), 2, "A0")
    policies = PolicyRegistry(PolicyStore(work / "store"), [PolicyStore(assets_dir() / "priors")])
    reports, evaluations, told = [], [], []
    try:
        outcome = Trainer(envs, policies, work / "checkpoints", progress_interval_sec=0.0,
                          tensorboard_dir=work / "tensorboard").train(
            TrainGoal("A0", "prior", "a0-goal", step_budget=40, eval_episodes=2, eval_interval=20, seed=3),
            on_progress=lambda report: (reports.append(report), told.append(report)),
            on_evaluation=lambda score, steps: (evaluations.append((steps, score)), told.append("evaluation")))
    finally:
        envs.close()
    assert outcome.completed
    after_evaluations = [told[i + 1] for i, what in enumerate(told) if what == "evaluation"]
    return work, reports, evaluations, after_evaluations


def test_tensorboard_lists_the_goal_with_the_numbers_it_reported(goal):
    work, reports, evaluations, after_evaluations = goal
    runs = read_runs(work / "tensorboard")
    assert list(runs) == ["a0-goal"], "one run per goal, named after its output policy"
    scalars = runs["a0-goal"]
    assert set(scalars) == {*PROGRESS_TAGS, *EVALUATION_TAGS}
    assert len(reports) == 22  # every vector step of 2 envs, and one after each evaluation
    for tag in PROGRESS_TAGS:
        expected = [(report.steps, float(np.float32(report.scalars()[tag]))) for report in reports
                    if not math.isnan(report.scalars()[tag])]
        assert scalars[tag] == expected, tag
    # The losses start with the first gradient step, the returns with the first finished episode.
    assert 0 < len(scalars["train/actor_loss"]) < len(reports)
    first_episode = next(report.steps for report in reports if report.episodes)
    assert scalars["rollout/ep_rew_mean"][0][0] == first_episode and scalars["rollout/ep_rew_mean"][0][1] < 0
    assert [steps for steps, _ in scalars["train/ent_coef"]] == \
        [report.steps for report in reports if not math.isnan(report.entropy_coefficient)]
    assert scalars["eval/successes"] == [(steps, float(score.successes)) for steps, score in evaluations]
    assert [steps for steps, _ in evaluations] == [20, 40]
    assert scalars["eval/success_rate"] == [(steps, score.successes / 2) for steps, score in evaluations]
    # Each evaluation's instruments: in the report right after it (the prior keeps experience: probes from it).
    assert [report.steps for report in after_evaluations] == [20, 40]
    for tag, name in (("instruments/q_parent_action", "q_parent_action"),
                      ("instruments/action_distance", "action_distance"),
                      ("instruments/policy_entropy", "policy_entropy")):
        values = [getattr(report.instruments, name) for report in after_evaluations]
        assert all(math.isfinite(value) for value in values), tag
        assert scalars[tag] == [(report.steps, float(np.float32(value)))
                                for report, value in zip(after_evaluations, values)], tag
    assert after_evaluations[-1].instruments.action_distance > 0, "40 steps of SAC moved the actor"
    assert math.isnan(reports[0].instruments.action_distance), "nothing measured before the first evaluation"


def test_the_csv_beside_holds_the_same_rows(goal):
    work, reports, evaluations, _ = goal
    with (work / "tensorboard" / "a0-goal" / CSV_FILE).open() as stream:
        rows = list(csv.DictReader(stream))
    assert tuple(rows[0]) == CSV_COLUMNS
    progress_rows = [row for row in rows if row["time/fps"]]
    assert [int(row["goal_steps"]) for row in progress_rows] == [report.steps for report in reports]
    for row, report in zip(progress_rows, reports):
        for tag, value in report.scalars().items():
            assert row[tag] == ("" if math.isnan(value) else repr(float(np.float32(value)))), tag
    evaluation_rows = [row for row in rows if row["eval/successes"]]
    assert [(int(row["goal_steps"]), float(row["eval/successes"])) for row in evaluation_rows] == \
        [(steps, score.successes) for steps, score in evaluations]


def test_a_resumed_goal_appends_and_unknown_tags_are_refused(tmp_path):
    for steps in (10, 20):  # two sessions of the same goal, as after a resume
        scalars = GoalScalars(tmp_path / "goal")
        scalars.write(steps, {"time/fps": 100.0, "train/actor_loss": math.nan})
        scalars.close()
    rows = (tmp_path / "goal" / CSV_FILE).read_text().splitlines()
    assert rows[0] == ",".join(CSV_COLUMNS) and len(rows) == 3, "one header, a row per write"
    assert read_runs(tmp_path)["goal"] == {"time/fps": [(10, 100.0), (20, 100.0)]}, "NaN left out"
    scalars = GoalScalars(tmp_path / "goal")
    with pytest.raises(ValueError, match="no scalar tag \\['train/loss'\\]"):
        scalars.write(30, {"train/loss": 1.0})
    scalars.close()

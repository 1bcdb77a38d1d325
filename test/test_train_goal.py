"""``node_common.train_goal``: a goal reaches the learner as the curriculum made it, and the message's
sentinels mean what Train.action says."""

import math
import re
from dataclasses import MISSING, fields

import pytest
from glocal_interfaces.action import Train
from hypothesis import given, strategies as st

from glocal_ros.curriculum.learner import PAPER_EVAL_EPISODES, TrainGoal, paper_threshold
from conftest import REPO
from glocal_ros.seeds import MAX_SEED
from node_common.train_goal import NO_SEED, goal_from_message, goal_message

#: ``type name [default]  # comment`` of an action's field.
_FIELD = re.compile(r"^\s*([\w/]+(?:\[\d*\])?)\s+([a-z]\w*)(?:\s+([^#\s]+))?\s*(?:#.*)?$")
#: The message's field type -> the annotation of TrainGoal's field.
PYTHON_TYPES = {"string": "str", "string[]": "tuple[str, ...]", "uint32": "int", "uint64": "int", "float32": "float",
                "bool": "bool", "int64": "int | None"}


def goal_fields() -> dict[str, tuple[str, str | None]]:
    """``{field: (type, default)}`` of the Goal section of msg_schemas/action/Train.action."""
    goal_section = (REPO / "msg_schemas" / "action" / "Train.action").read_text().split("---")[0]
    return {match.group(2): (match.group(1), match.group(3))
            for match in map(_FIELD.match, goal_section.splitlines()) if match}

TASKS = st.sampled_from(["", "A0", "C4", "G6"])


@st.composite
def goals(draw) -> TrainGoal:
    eval_episodes = draw(st.integers(1, 1000))
    return TrainGoal(
        task=draw(TASKS), initial_policy=draw(st.sampled_from(["prior", "g1"])),
        output_policy=draw(st.sampled_from(["out", "l-1-2"])), step_budget=draw(st.integers(1, 10**9)),
        # B as a run gives it: a multiple of 1/4 episode, which a float32 field holds exactly
        threshold=draw(st.integers(0, 4 * eval_episodes - 1)) / 4, eval_episodes=eval_episodes,
        episode_tasks=tuple(draw(st.lists(TASKS.filter(bool), max_size=3))),
        episode_limit=draw(st.integers(0, 10**6)), eval_interval=draw(st.integers(0, 10**6)),
        stop_when_learned=draw(st.booleans()), keep_replay_buffer=draw(st.booleans()),
        seed=draw(st.none() | st.integers(0, MAX_SEED)),
    )


def test_the_goal_type_has_the_messages_fields_one_by_one():
    declared = goal_fields()
    ours = {field.name: field for field in fields(TrainGoal)}
    assert set(declared) == set(ours)
    for name, (message_type, default) in declared.items():
        assert ours[name].type == PYTHON_TYPES[message_type], name
        if default is not None:  # a sentinel default: what it means is TrainGoal's own default
            assert ours[name].default is not MISSING, name
    assert float(declared["threshold"][1]) < 0 and int(declared["seed"][1]) == NO_SEED
    required = {name for name, field in ours.items() if field.default is MISSING}
    assert required == {"task", "initial_policy", "output_policy", "step_budget"}


@given(goals())
def test_a_goal_survives_its_message(goal):
    assert goal_from_message(goal_message(goal)) == goal


def test_the_messages_defaults_are_the_papers_b_and_s_bar_and_no_seed():
    goal = goal_from_message(Train.Goal(task="A0", initial_policy="prior", output_policy="out", step_budget=10))
    assert (goal.threshold, goal.eval_episodes, goal.seed) == (paper_threshold(), PAPER_EVAL_EPISODES, None)
    assert goal == TrainGoal("A0", "prior", "out", 10), "the type's defaults are the message's"
    twenty = goal_from_message(Train.Goal(task="A0", initial_policy="prior", output_policy="out", step_budget=10,
                                          eval_episodes=20))
    assert twenty.threshold == 15


def test_a_nan_threshold_is_refused_by_name():
    with pytest.raises(ValueError, match="threshold is NaN"):
        goal_from_message(Train.Goal(task="A0", initial_policy="prior", output_policy="out", step_budget=10,
                                     threshold=math.nan))

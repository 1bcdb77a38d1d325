"""The library's constants are the messages' own: parsed from msg_schemas/, compared one by one.

The .msg files are the single source of truth; glocal_ros mirrors their
constants (and the values their comments document) as plain Python because
it may not import the generated classes. Each value is defined once there.
"""

import re
from dataclasses import fields

import pytest

from conftest import REPO
from glocal_ros import sim_contract, topics
from glocal_ros.curriculum import codes
from glocal_ros.curriculum.learner import EpisodeSummary
from glocal_ros.curriculum.strategies import STRATEGIES

MSG_DIR = REPO / "msg_schemas" / "msg"
_CONSTANT = re.compile(r"^\s*\w+\s+([A-Z][A-Z0-9_]*)\s*=\s*(-?\d+)")
_FIELD = re.compile(r"^\s*([\w/]+(?:\[\d*\])?)\s+([a-z]\w*)\s*(?:#\s*(.*))?$")


def msg_constants(name: str, prefix: str) -> dict[str, int]:
    """``{NAME: value}`` of the constants of ``name``.msg whose name starts with ``prefix``."""
    found = {}
    for line in (MSG_DIR / f"{name}.msg").read_text().splitlines():
        match = _CONSTANT.match(line)
        if match and match.group(1).startswith(prefix):
            found[match.group(1)] = int(match.group(2))
    return found


def msg_fields(name: str) -> dict[str, str]:
    """``{field: its comment}`` of ``name``.msg, in order."""
    found = {}
    for line in (MSG_DIR / f"{name}.msg").read_text().splitlines():
        match = _FIELD.match(line)
        if match and "=" not in line.split("#")[0]:
            found[match.group(2)] = match.group(3) or ""
    return found


def msg_header(name: str) -> str:
    """The comment block that opens ``name``.msg, as one line of text."""
    lines = []
    for line in (MSG_DIR / f"{name}.msg").read_text().splitlines():
        if not line.startswith("#"):
            break
        lines.append(line.lstrip("# "))
    return " ".join(lines)


def module_constants(module, prefix: str) -> dict[str, int]:
    return {name: value for name, value in vars(module).items() if name.startswith(prefix) and name.isupper()
            and isinstance(value, int)}


@pytest.mark.parametrize("module, msg, prefix", [
    (codes, "CurriculumState", "STATUS_"),
    (codes, "TaskAssignment", "ROLE_"),
    (sim_contract, "EpisodeRecord", "PHASE_"),
])
def test_constants_are_the_messages(module, msg, prefix):
    expected = msg_constants(msg, prefix)
    assert expected, f"{msg}.msg defines no {prefix}* constant: the parser is out of date"
    assert module_constants(module, prefix) == expected


def test_phases_are_every_phase_the_record_knows():
    assert sorted(sim_contract.PHASES) == sorted(msg_constants("EpisodeRecord", "PHASE_").values())


def test_the_unseeded_marker_is_the_records():
    comment = msg_fields("EpisodeRecord")["seed"]
    assert re.search(rf"(?<![\d-]){sim_contract.UNSEEDED} when not seeded", comment), comment


def test_strategy_names_are_those_the_state_lists_and_the_strategies_run():
    listed = tuple(name.strip() for name in msg_fields("CurriculumState")["strategy"].split(","))
    assert codes.STRATEGY_NAMES == listed
    assert tuple(STRATEGIES) == codes.STRATEGY_NAMES


def test_a_finished_episode_has_the_fields_of_episode_outcome():
    assert [f.name for f in fields(EpisodeSummary)] == list(msg_fields("EpisodeOutcome"))


OUR_TOPICS = [topic for topic in topics.GRAPH_TOPICS if topic.msgtype.startswith("glocal_interfaces/")]


@pytest.mark.parametrize("topic", OUR_TOPICS, ids=lambda topic: topic.name)
def test_the_topic_table_agrees_with_the_messages(topic):
    name = topic.msgtype.rpartition("/")[2]
    assert (MSG_DIR / f"{name}.msg").is_file()
    header = msg_header(name)
    # What a message's own comment says about its topic's QoS must hold.
    if "best effort" in header:
        assert not topic.qos.reliable
    elif "reliable" in header:
        assert topic.qos.reliable
    assert ("transient-local" in header) == topic.qos.transient_local


def test_the_topic_table_names_each_topic_once():
    names = [topic.name for topic in topics.GRAPH_TOPICS]
    assert len(names) == len(set(names)) and all(name.startswith("/") for name in names)
    assert topics.RECORDED_TOPICS == tuple(topic for topic in topics.GRAPH_TOPICS if topic.recorded)


def test_the_control_period_is_the_envs_default():
    from glocal_ros.spaces import ACTION_DIM, CONTROL_PERIOD, OBS_DIM
    from sim_node.grasp_env import GraspEnvConfig

    config = GraspEnvConfig()
    assert CONTROL_PERIOD == config.substeps * config.timestep
    assert (OBS_DIM, ACTION_DIM) == (63, 5)  # the paper's sizes (Section IV-A)

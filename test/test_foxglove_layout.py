"""assets/foxglove/glocal.json, the Foxglove layout of a run, checked against the graph so that it cannot rot.

The file is a layout as Foxglove exports it (``configById``, the panel tree in ``layout``, ``userNodes``
for user scripts). Every topic a panel names is a topic of the graph's table (or the output of one of
the layout's own scripts, whose inputs are in turn the graph's), and every message path's first field
is a field of that topic's type; the panel tree and ``configById`` name the same panels.
"""

from __future__ import annotations

import json
import re

import pytest

from conftest import REPO
from glocal_ros.recording import graph_typestore
from glocal_ros.topics import GRAPH_TOPICS

LAYOUT = REPO / "assets" / "foxglove" / "glocal.json"
SCRIPT_PREFIX = "/studio_script/"  # where Foxglove's user scripts publish


@pytest.fixture(scope="module")
def layout() -> dict:
    return json.loads(LAYOUT.read_text())


def panel_ids(node) -> list[str]:
    """The panels of a mosaic tree (a panel id, or a split of ``first`` and ``second``)."""
    if isinstance(node, str):
        return [node]
    return panel_ids(node["first"]) + panel_ids(node["second"])


def message_paths(config: dict) -> list[str]:
    """Every topic or message path a panel's configuration names."""
    paths = list(config.get("topics", {}))
    paths += [config[key] for key in ("topicPath", "path") if config.get(key)]
    paths += [series["value"] for series in config.get("paths", [])]
    if config.get("xAxisPath"):
        paths.append(config["xAxisPath"]["value"])
    return paths


def split_path(path: str, topics: set[str]) -> tuple[str, list[str]]:
    """``/glocal/curriculum_state.total_steps`` -> (the topic, its fields); the longest known topic wins."""
    for topic in sorted(topics, key=len, reverse=True):
        if path == topic or path.startswith(topic + "."):
            return topic, [re.sub(r"\[.*\]$", "", field) for field in path[len(topic) + 1:].split(".") if field]
    return path.split(".")[0], []


def test_the_layout_is_a_foxglove_layout_whose_panels_are_all_placed(layout):
    assert set(layout) >= {"configById", "layout", "globalVariables", "userNodes", "playbackConfig"}
    placed = panel_ids(layout["layout"])
    assert sorted(placed) == sorted(layout["configById"]), "each configured panel is placed, once"
    kinds = {panel.split("!")[0] for panel in placed}
    assert {"3D", "Plot", "Indicator", "RawMessages", "Table"} <= kinds


def test_every_topic_and_field_it_names_is_the_graphs(layout):
    table = {spec.name: spec.msgtype for spec in GRAPH_TOPICS}
    typestore = graph_typestore()
    scripts = {}
    for script in layout["userNodes"].values():
        source = script["sourceCode"]
        (output,) = re.findall(r'export const output = "([^"]+)"', source)
        (inputs,) = re.findall(r"export const inputs = \[([^\]]*)\]", source)
        inputs = re.findall(r'"([^"]+)"', inputs)
        assert output.startswith(SCRIPT_PREFIX) and set(inputs) <= set(table), (output, inputs)
        for topic in inputs:  # the script reads these fields of its input
            fields = {name for name, _ in typestore.fielddefs[table[topic]][1]}
            read = set(re.findall(r"state\.(\w+)", source))
            assert read <= fields, read - fields
        scripts[output] = set(re.findall(r"(\w+): \w+", source.split("type Output =")[1].split("}")[0]))
    named = set()
    for panel, config in layout["configById"].items():
        for path in message_paths(config):
            topic, fields = split_path(path, set(table) | set(scripts))
            named.add(topic)
            if topic in scripts:
                assert not fields or fields[0] in scripts[topic], f"{panel}: {path}"
                continue
            assert topic in table, f"{panel} names {topic}, which is not a topic of the graph"
            if fields:
                assert fields[0] in {name for name, _ in typestore.fielddefs[table[topic]][1]}, f"{panel}: {path}"
    assert {"/tf", "/robot_description", "/glocal/object_marker", "/glocal/curriculum_state",
            "/glocal/task_assignment", "/glocal/evaluations"} <= named

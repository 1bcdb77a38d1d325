"""assets/foxglove/glocal.json, the Foxglove layout of a run, checked against the graph so that it cannot rot.

The file is a layout as Foxglove exports it (``configById``, the panel tree in ``layout``, ``userNodes``
for user scripts). Every topic a panel names is a topic of the graph's table (or the output of one of
the layout's own scripts, whose inputs are in turn the graph's), and every message path's first field
is a field of that topic's type; the panel tree and ``configById`` name the same panels.

Every panel's configuration is one that foxglove-sdk's layout types (``foxglove.layouts``, the pinned
version's) describe: each key is one the type writes, each value of the type's kind, so that a setting
Foxglove ignores (a key in the wrong place) fails here. The robot model comes from a URDF layer on the
table's robot_description topic, so that ``glocal_ros.foxglove_layout`` can move it, with every other
topic, under a run's namespace.
"""

from __future__ import annotations

import json
import re
import types
import typing

import foxglove.layouts as fl
import pytest

from conftest import REPO
from glocal_ros.foxglove_layout import RUN_LAYOUT, layout_file, namespaced_layout, write_layout
from glocal_ros.recording import graph_typestore
from glocal_ros.topics import CURRICULUM_STATE, GRAPH_TOPICS, ROBOT_DESCRIPTION

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
    paths += [layer["topic"] for layer in config.get("layers", {}).values() if layer.get("topic")]
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


# --- against foxglove-sdk's layout types ---------------------------------------------------------------------

#: The exported layout's panel kinds (the part of a panel id before "!") -> their configuration's type.
PANEL_CONFIGS = {"3D": fl.ThreeDeeConfig, "Plot": fl.PlotConfig, "Indicator": fl.IndicatorConfig,
                 "RawMessages": fl.RawMessagesConfig, "Table": fl.TableConfig}
#: Where an exported layout keeps a panel's title (the SDK's panel ``title``).
TITLE_KEY = "foxglovePanelTitle"


class _Field:
    def __init__(self, name: str):
        self.name = name


def json_keys(model: type) -> tuple[dict[str, str], dict[str, object]]:
    """(JSON key -> attribute, JSON key -> the fixed value the type always writes) of a layout type, read from
    what its ``_to_dict`` writes."""
    hints = typing.get_type_hints(model)
    probe = object.__new__(model)
    for name in hints:
        object.__setattr__(probe, name, _Field(name))
    written = probe._to_dict()
    fields = {key: value.name for key, value in written.items() if isinstance(value, _Field)}
    fixed = {key: value for key, value in written.items() if not isinstance(value, _Field)}
    return fields, fixed


def sdk_errors(value, hint, where: str) -> list[str]:
    """Why ``value`` (JSON) is not a ``hint`` of foxglove.layouts; empty when it is."""
    origin, args = typing.get_origin(hint), typing.get_args(hint)
    if hint is typing.Any:
        return []
    if origin in (typing.Union, types.UnionType):
        if value is None and type(None) in args:
            return []
        tries = [sdk_errors(value, arg, where) for arg in args if arg is not type(None)]
        return [] if any(not errors for errors in tries) else min(tries, key=len)
    if origin is typing.Literal:
        return [] if value in args else [f"{where}: {value!r} is not one of {args}"]
    if origin is list:
        if not isinstance(value, list):
            return [f"{where}: expected a list"]
        return [error for i, item in enumerate(value) for error in sdk_errors(item, args[0], f"{where}[{i}]")]
    if origin is tuple:
        if not isinstance(value, list) or len(value) != len(args):
            return [f"{where}: expected {len(args)} values"]
        return [error for i, (item, arg) in enumerate(zip(value, args)) for error in sdk_errors(item, arg, where)]
    if origin is dict:
        if not isinstance(value, dict):
            return [f"{where}: expected an object"]
        return [error for key, item in value.items() for error in sdk_errors(item, args[1], f"{where}.{key}")]
    if isinstance(hint, type) and issubclass(hint, fl._BaseModel):
        if not isinstance(value, dict):
            return [f"{where}: expected an object ({hint.__name__})"]
        fields, fixed = json_keys(hint)
        hints = typing.get_type_hints(hint)
        errors = []
        for key, item in value.items():
            if key in fixed:
                errors += [] if item == fixed[key] else [f"{where}.{key}: {item!r}, {hint.__name__} has {fixed[key]!r}"]
            elif key in fields:
                errors += sdk_errors(item, hints[fields[key]], f"{where}.{key}")
            else:
                errors.append(f"{where}: {hint.__name__} has no setting {key!r}")
        return errors
    kinds = {bool: (bool,), float: (int, float), int: (int,), str: (str,)}
    ok = isinstance(value, kinds.get(hint, (hint,))) and not (hint in (float, int) and isinstance(value, bool))
    return [] if ok else [f"{where}: {value!r} is not a {getattr(hint, '__name__', hint)}"]


def test_the_checker_refuses_what_foxglove_ignores():
    misplaced = {"transforms": {"showLabel": False, "axisScale": 0.5}}  # the layout's old mistake
    assert sdk_errors(misplaced, fl.ThreeDeeConfig, "3D")
    assert sdk_errors({"scene": {"transforms": {"axisScale": 0.5}}}, fl.ThreeDeeConfig, "3D")
    assert not sdk_errors({"scene": {"transforms": {"showLabel": False, "axisSize": 0.5}}}, fl.ThreeDeeConfig, "3D")
    assert sdk_errors({"layers": {"urdf": {"layerId": "foxglove.Urdf", "sourceType": "ftp"}}}, fl.ThreeDeeConfig, "3D")
    assert sdk_errors({"paths": [{"value": "/a.b", "enabled": "yes"}]}, fl.PlotConfig, "Plot")


def test_every_panel_and_script_is_what_foxglove_sdk_layout_types_describe(layout):
    errors = []
    for panel, config in layout["configById"].items():
        kind = panel.split("!")[0]
        assert kind in PANEL_CONFIGS, f"{panel}: add its configuration type to PANEL_CONFIGS"
        settings = {key: value for key, value in config.items() if key != TITLE_KEY}
        errors += sdk_errors(settings, PANEL_CONFIGS[kind], panel)
    errors += sdk_errors(layout["userNodes"], dict[str, fl.UserScript], "userNodes")
    errors += sdk_errors(layout["globalVariables"], fl.Variables, "globalVariables")
    assert errors == []


def test_the_robot_model_is_a_urdf_layer_on_the_tables_robot_description(layout):
    (config,) = [config for panel, config in layout["configById"].items() if panel.startswith("3D!")]
    (urdf,) = [layer for layer in config["layers"].values() if layer["layerId"] == "foxglove.Urdf"]
    assert urdf["sourceType"] == "topic" and urdf["topic"] == ROBOT_DESCRIPTION.name and urdf["visible"]
    # Foxglove's own robot_description display listens on /robot_description only, whatever the namespace.
    assert ROBOT_DESCRIPTION.name not in config.get("topics", {})
    assert config["scene"]["transforms"] == {"showLabel": False, "axisSize": 0.5}
    assert "transforms" not in config, "panel-level transforms are settings per frame id"


# --- the layout of a namespaced run ----------------------------------------------------------------------------

def named_topics(layout: dict) -> list[str]:
    """Every topic the layout names: in panels (topics, paths, layers) and as user scripts' inputs."""
    table = {spec.name for spec in GRAPH_TOPICS}
    names = []
    for config in layout["configById"].values():
        names += [path for path in message_paths(config) if not path.startswith(SCRIPT_PREFIX)]
    for script in layout["userNodes"].values():
        (inputs,) = re.findall(r"export const inputs = \[([^\]]*)\]", script["sourceCode"])
        names += re.findall(r'"([^"]+)"', inputs)
        names += re.findall(r'Input<"([^"]+)">', script["sourceCode"])
    assert names and all(any(name.endswith(spec) or spec + "." in name for spec in table) for name in names), names
    return names


def test_the_root_namespace_layout_is_the_shipped_file(layout):
    assert namespaced_layout() == namespaced_layout("/") == layout
    assert layout_file() == LAYOUT


@pytest.mark.parametrize("namespace, pair, run_prefix, pair_prefix", [
    ("robot1", "", "/robot1", "/robot1"),
    ("/lab/robot1/", "", "/lab/robot1", "/lab/robot1"),
    ("robot1", "pair0", "/robot1", "/robot1/pair0"),
    ("", "pair0", "", "/pair0"),
])
def test_a_namespaced_layout_moves_every_topic_under_its_publishers_namespace(layout, namespace, pair,
                                                                              run_prefix, pair_prefix):
    moved = namespaced_layout(namespace, pair)
    by_spec = {spec.name: spec for spec in GRAPH_TOPICS}
    root_names, moved_names = named_topics(layout), named_topics(moved)
    assert len(root_names) == len(moved_names)
    for root, name in zip(root_names, moved_names):
        topic, _ = split_path(root, set(by_spec))
        prefix = pair_prefix if by_spec[topic].of_pair else run_prefix
        assert name == prefix + root, (root, name)
    (config,) = [config for panel, config in moved["configById"].items() if panel.startswith("3D!")]
    (urdf,) = [layer for layer in config["layers"].values() if layer["layerId"] == "foxglove.Urdf"]
    assert urdf["topic"] == f"{pair_prefix}{ROBOT_DESCRIPTION.name}"
    script = next(iter(moved["userNodes"].values()))["sourceCode"]
    assert f'"{run_prefix}{CURRICULUM_STATE.name}"' in script and f'"{SCRIPT_PREFIX}glocal_learned"' in script
    # Frames, titles and everything else stay as they are.
    assert config["followTf"] == "world" and moved["layout"] == layout["layout"]
    assert not sdk_errors({k: v for k, v in config.items() if k != TITLE_KEY}, fl.ThreeDeeConfig, "3D")


def test_write_layout_writes_a_layout_file_foxglove_imports(tmp_path):
    path = write_layout(tmp_path / "run" / RUN_LAYOUT, "robot1", "pair0")
    assert path == tmp_path / "run" / "foxglove-layout.json"
    assert json.loads(path.read_text()) == namespaced_layout("robot1", "pair0")


def test_the_command_writes_the_layout_of_a_namespace_and_refuses_a_bad_one(tmp_path, capsys):
    from glocal_app.cli import main

    out = tmp_path / "layout.json"
    assert main(["foxglove-layout", "--namespace", "robot1/", "--pairs", "2", "--out", str(out)]) == 0
    assert json.loads(out.read_text()) == namespaced_layout("/robot1", "pair0")
    assert str(out) in capsys.readouterr().out
    with pytest.raises(SystemExit):
        main(["foxglove-layout", "--namespace", "1robot", "--out", str(tmp_path / "bad.json")])
    assert "invalid namespace" in capsys.readouterr().err and not (tmp_path / "bad.json").exists()

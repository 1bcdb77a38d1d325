"""launch/glocal.launch.py, checked without ROS 2's launch (not installable here).

Statically: what it imports, declares and installs. Then executed:
``generate_launch_description()`` against the stand-ins of
``test/launch_standins.py`` (injected into ``sys.modules``), with the real
ament index of the venv, and the description evaluated for given arguments
as ``ros2 launch`` would: the nodes, their executables (in ``bin/`` and the
installed ``lib/glocal_ros``), parameters, namespace and remappings, and the
shutdown when the curriculum ends. A subprocess checks that it loads no
project dependency (the ``ros2`` command's interpreter need not have them).
"""

from __future__ import annotations

import ast
import json
import runpy
import socket
import subprocess
import sys
from pathlib import Path

import pytest
import yaml

import launch_standins
from conftest import REPO
from glocal_app.nodes import NODES
from glocal_app.processes import FOXGLOVE_NODE, RUN_NODES, FoxgloveEndpoint, RunOptions
from glocal_ros.curriculum.codes import STRATEGY_NAMES

LAUNCH_FILE = REPO / "launch" / "glocal.launch.py"
ARGUMENTS = {"strategy", "preset", "seed", "out", "namespace", "use_sim_time", "step_budget", "learner_profile",
             "foxglove", "foxglove_port", "foxglove_host", "pairs"}
#: What the launch file may import: ROS's launch API, the ament index and the stdlib-only plan.
ALLOWED_IMPORTS = {"__future__", "pathlib", "launch", "launch.actions", "launch.event_handlers", "launch.events",
                   "launch_ros.actions", "ament_index_python.packages", "glocal_app.processes"}
SHARE = Path(sys.prefix) / "share" / "glocal_ros"


@pytest.fixture
def launch_file(monkeypatch, tmp_path):
    """The launch file's globals, run against the stand-ins; ROS_HOME in tmp_path."""
    launch_standins.install(sys.modules, monkeypatch.setitem)
    monkeypatch.setenv("ROS_HOME", str(tmp_path / "ros_home"))
    return runpy.run_path(str(LAUNCH_FILE))


def evaluate(launch_file, **arguments: str) -> tuple[dict[str, launch_standins.Node], list]:
    """The Node actions by executable, and the other actions, for ``ros2 launch ... name:=value``."""
    actions = launch_standins.evaluate(launch_file["generate_launch_description"](), **arguments)
    nodes = {a.executable: a for a in actions if isinstance(a, launch_standins.Node)}
    bridge = [FOXGLOVE_NODE] if arguments.get("foxglove") == "true" else []
    assert list(nodes) == bridge + list(RUN_NODES), "(the bridge,) recorder, then sim, learner, curriculum"
    return nodes, [a for a in actions if not isinstance(a, launch_standins.Node)]


def parameters(node: launch_standins.Node) -> tuple[Path, dict]:
    """(the preset file, the run's parameters): a file first, so that the run's values win over it."""
    preset, plan = node.parameters
    return Path(preset), plan


# --- statically ---------------------------------------------------------------------------------------------

def test_the_file_imports_declares_and_is_installed_as_ros2_launch_expects():
    tree = ast.parse(LAUNCH_FILE.read_text(), str(LAUNCH_FILE))
    imports = {n.module for n in ast.walk(tree) if isinstance(n, ast.ImportFrom)} | \
        {alias.name for n in ast.walk(tree) if isinstance(n, ast.Import) for alias in n.names}
    assert imports <= ALLOWED_IMPORTS, imports - ALLOWED_IMPORTS
    functions = {n.name: n for n in tree.body if isinstance(n, ast.FunctionDef)}
    generate = functions["generate_launch_description"]
    assert not generate.args.args, "ros2 launch calls it without arguments"
    declared = {call.args[0].value for call in ast.walk(tree) if isinstance(call, ast.Call)
                and getattr(call.func, "id", None) == "DeclareLaunchArgument"}
    assert declared == ARGUMENTS
    # setup.py installs it where `ros2 launch glocal_ros glocal.launch.py` looks: share/glocal_ros/launch.
    assert 'f"share/{PACKAGE}/launch"' in (REPO / "setup.py").read_text()
    installed = SHARE / "launch" / LAUNCH_FILE.name
    assert installed.is_file() and installed.read_text() == LAUNCH_FILE.read_text(), \
        f"{installed} is missing or stale: run `make setup`"


def test_its_strategies_are_the_curriculums():
    tree = ast.parse(LAUNCH_FILE.read_text())
    strategies = next(ast.literal_eval(n.value) for n in tree.body if isinstance(n, ast.Assign)
                      and getattr(n.targets[0], "id", None) == "STRATEGIES")
    assert tuple(strategies) == tuple(STRATEGY_NAMES)


def test_its_learner_profiles_are_the_learners():
    from learner_node.profiles import PROFILES

    tree = ast.parse(LAUNCH_FILE.read_text())
    profiles = next(ast.literal_eval(n.value) for n in tree.body if isinstance(n, ast.Assign)
                    and getattr(n.targets[0], "id", None) == "LEARNER_PROFILES")
    assert tuple(profiles) == tuple(PROFILES)


def test_it_loads_no_project_dependency_and_no_ros_client(tmp_path):
    """Run in a fresh interpreter: the launch file and the plan it imports need only the standard library."""
    code = f"""
import json, runpy, sys
sys.path.insert(0, {str(REPO / 'test')!r})
import launch_standins
launch_standins.install(sys.modules)
before = set(sys.modules)
description = runpy.run_path({str(LAUNCH_FILE)!r})["generate_launch_description"]()
actions = launch_standins.evaluate(description, preset="smoke", out={str(tmp_path / 'run')!r})
print(json.dumps(sorted(set(sys.modules) - before)))
"""
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=tmp_path, check=True)
    loaded = {name.split(".")[0] for name in json.loads(result.stdout.splitlines()[-1])}
    assert loaded & {"glocal_ros", "gymnasium", "numpy", "rclpy", "torch", "pybullet", "yaml"} == set(), loaded


# --- executed against the stand-ins -------------------------------------------------------------------------

def test_the_issue_example_starts_the_graph_as_glocal_ros_launch_does(launch_file, tmp_path):
    """strategy:=glocal preset:=smoke seed:=0 namespace:=robot1 use_sim_time:=true out:=..."""
    out = tmp_path / "run"
    nodes, others = evaluate(launch_file, strategy="glocal", preset="smoke", seed="0", namespace="robot1",
                             use_sim_time="true", out=str(out))
    installed = Path(sys.prefix) / "lib" / "glocal_ros"
    for name, node in nodes.items():
        assert node.package == "glocal_ros" and node.executable in NODES
        assert (REPO / "bin" / name).is_file() and (installed / name).is_file(), f"no executable {name}"
        assert node.name is None, "the node names its own node, as with glocal-ros launch"
        assert node.namespace == "robot1", "relative: an including PushRosNamespace comes in front"
        assert node.remappings == [("/clock", "clock")], "each namespaced graph hears its own sim's clock"
        assert node.kwargs.get("output") == "screen"
        preset, _ = parameters(node)
        assert preset == SHARE / "assets" / "params" / "smoke.yaml"
        # The preset reaches a node in any namespace.
        assert f"/**/{name}" in yaml.safe_load(preset.read_text()) or name == "recorder_node"
    plan = {name: parameters(node)[1] for name, node in nodes.items()}
    assert plan == {
        "recorder_node": {"output": str(out / "bag"), "use_sim_time": True},
        "sim_node": {"seed": 0, "use_sim_time": True},
        "learner_node": {"seed": 0, "policy_dir": str(out / "policies"),
                         "tensorboard_dir": str(out / "tensorboard")},
        "curriculum_node": {"strategy": "glocal", "seed": 0, "state_dir": str(out / "curriculum")},
    }
    # What glocal-ros launch gives the same run (glocal_app.launch builds its processes from it).
    assert plan == RunOptions("smoke", use_sim_time=True).parameters("glocal", 0, out, out / "bag")
    assert json.loads((out / "run.json").read_text()) == {"strategy": "glocal", "preset": "smoke", "seed": 0}

    (handler,) = others
    assert isinstance(handler, launch_standins.RegisterEventHandler)
    assert isinstance(handler.event_handler, launch_standins.OnProcessExit)
    assert handler.event_handler.target_action is nodes["curriculum_node"]
    (shutdown,) = handler.event_handler.on_exit
    assert isinstance(shutdown, launch_standins.EmitEvent) and isinstance(shutdown.event, launch_standins.Shutdown)


def test_defaults_root_namespace_wall_clock_and_a_run_directory_under_ros_home(launch_file, tmp_path):
    nodes, _ = evaluate(launch_file)
    run_dir = tmp_path / "ros_home" / "glocal_ros" / "runs" / "glocal-seed0"
    for node in nodes.values():
        preset, plan = parameters(node)
        assert preset.name == "demo.yaml"
        assert node.namespace is None and node.remappings == []
        assert "use_sim_time" not in plan, "nothing given: each node keeps its preset's clock (wall-clock)"
    assert parameters(nodes["recorder_node"])[1]["output"] == str(run_dir / "bag")
    assert parameters(nodes["curriculum_node"])[1]["state_dir"] == str(run_dir / "curriculum")


def test_a_later_launch_records_a_new_bag_and_sim_time_reaches_only_sim_and_recorder(launch_file, tmp_path):
    out = tmp_path / "run"
    (out / "bag").mkdir(parents=True)
    nodes, _ = evaluate(launch_file, strategy="random", preset="smoke", seed="3", out=str(out),
                        use_sim_time="true", namespace="/lab/robot2/")
    assert parameters(nodes["recorder_node"])[1]["output"] == str(out / "bag.1")
    assert {name for name, node in nodes.items() if parameters(node)[1].get("use_sim_time")} == \
        {"sim_node", "recorder_node"}
    assert parameters(nodes["curriculum_node"])[1] == {"strategy": "random", "seed": 3,
                                                       "state_dir": str(out / "curriculum")}
    assert {node.namespace for node in nodes.values()} == {"lab/robot2"}


@pytest.mark.parametrize("arguments, error", [
    ({"seed": "-1"}, "non-negative integer"),
    ({"seed": "abc"}, "non-negative integer"),
    ({"namespace": "1robot"}, "invalid namespace"),
    ({"preset": "nope"}, "is not one of"),
    ({"strategy": "nope"}, "is not one of"),
    ({"use_sim_time": "yes"}, "is not one of"),
    ({"step_budget": "0"}, "expected training steps"),
    ({"step_budget": "many"}, "expected training steps"),
])
def test_bad_arguments_are_refused_before_anything_starts(launch_file, tmp_path, arguments, error):
    with pytest.raises((ValueError, RuntimeError), match=error):
        evaluate(launch_file, out=str(tmp_path / "run"), **arguments)
    assert not (tmp_path / "run").exists()


def test_a_step_budget_and_a_profile_reach_the_plan_and_the_run_file_as_glocal_ros_launch_gives_them(
        launch_file, tmp_path):
    out = tmp_path / "run"
    nodes, _ = evaluate(launch_file, preset="smoke", out=str(out), step_budget="300",
                        learner_profile="paper+time-limit-bootstrap")
    options = RunOptions("smoke", step_budget=300, learner_profile="paper+time-limit-bootstrap")
    assert {name: parameters(node)[1] for name, node in nodes.items()} == \
        options.parameters("glocal", 0, out, out / "bag")
    assert parameters(nodes["curriculum_node"])[1]["step_budget"] == 300
    assert json.loads((out / "run.json").read_text()) == options.settings("glocal", 0)


def test_a_directory_of_another_run_is_refused(launch_file, tmp_path):
    out = tmp_path / "run"
    evaluate(launch_file, preset="smoke", seed="1", out=str(out))
    with pytest.raises(ValueError, match="holds the run"):
        evaluate(launch_file, preset="smoke", seed="2", out=str(out))


def test_the_presets_offered_are_the_installed_ones(launch_file):
    description = launch_file["generate_launch_description"]()
    (preset,) = [e for e in description.entities if getattr(e, "name", None) == "preset"]
    assert preset.choices == sorted(p.stem for p in (SHARE / "assets" / "params").glob("*.yaml"))
    assert preset.choices == sorted(p.stem for p in (REPO / "assets" / "params").glob("*.yaml"))
    assert {"smoke", "demo", "paper"} <= set(preset.choices)


def test_foxglove_starts_the_bridge_first_with_the_plans_endpoint(launch_file, tmp_path):
    out = tmp_path / "run"
    with socket.socket() as free:  # a port nothing listens on
        free.bind(("127.0.0.1", 0))
        port = free.getsockname()[1]
    nodes, _ = evaluate(launch_file, preset="smoke", out=str(out), foxglove="true", foxglove_port=str(port),
                        namespace="robot1", use_sim_time="true")
    bridge = nodes[FOXGLOVE_NODE]
    assert bridge.namespace == "robot1" and bridge.remappings == [("/clock", "clock")]
    plan = {name: parameters(node)[1] for name, node in nodes.items()}
    assert plan[FOXGLOVE_NODE] == {"port": port, "address": "127.0.0.1", "use_sim_time": True}
    assert plan == RunOptions("smoke", namespace="/robot1", use_sim_time=True).parameters(
        "glocal", 0, out, out / "bag", FoxgloveEndpoint(port))
    assert {name for name, node in nodes.items() if "use_sim_time" in parameters(node)[1]} == \
        {"sim_node", "recorder_node", FOXGLOVE_NODE}


@pytest.mark.parametrize("port, error", [("abc", "expected a port number"), ("0", "expected 1..65535"),
                                         ("taken", "is in use")])
def test_a_bad_or_taken_foxglove_port_is_refused_before_anything_starts(launch_file, tmp_path, port, error):
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        if port == "taken":
            port = str(taken.getsockname()[1])
        with pytest.raises(ValueError, match=error):
            evaluate(launch_file, out=str(tmp_path / "run"), foxglove="true", foxglove_port=port)
    assert not (tmp_path / "run").exists()


def test_pairs_start_every_pair_in_its_namespace_as_glocal_ros_launch_plans_them(launch_file, tmp_path):
    """pairs:=2 namespace:=robot1: the recorder and curriculum in robot1, each pair's sim and learner in
    robot1/pair0 and robot1/pair1, with the plan's parameters (one policy directory, the pairs named to the
    recorder and the curriculum)."""
    out = tmp_path / "run"
    actions = launch_standins.evaluate(launch_file["generate_launch_description"](), preset="smoke", pairs="2",
                                       namespace="robot1", out=str(out))
    nodes = [a for a in actions if isinstance(a, launch_standins.Node)]
    paths = [f"{node.namespace.removeprefix('robot1').strip('/')}/{node.executable}".lstrip("/") for node in nodes]
    assert paths == ["recorder_node", "pair0/sim_node", "pair0/learner_node", "pair1/sim_node",
                     "pair1/learner_node", "curriculum_node"]
    assert all(node.remappings == [("/clock", "clock")] for node in nodes), "each hears its own namespace's clock"
    plan = {path: parameters(node)[1] for path, node in zip(paths, nodes)}
    assert plan == RunOptions("smoke", pairs=2, namespace="/robot1").parameters("glocal", 0, out, out / "bag")
    assert plan["curriculum_node"]["learner_namespaces"] == "pair0,pair1"
    assert plan["curriculum_node"]["parallel_locals"] is True
    assert plan["recorder_node"]["pair_namespaces"] == "pair0,pair1"
    assert {plan[f"pair{i}/learner_node"]["policy_dir"] for i in range(2)} == {str(out / "policies")}
    assert {plan[f"pair{i}/learner_node"]["tensorboard_dir"] for i in range(2)} == {str(out / "tensorboard")}
    assert json.loads((out / "run.json").read_text())["pairs"] == 2


@pytest.mark.parametrize("arguments, error", [
    ({"pairs": "0"}, "expected a number of sim/learner pairs"),
    ({"pairs": "two"}, "expected a number of sim/learner pairs"),
    ({"pairs": "2", "strategy": "random"}, "sequential"),
    ({"pairs": "2", "use_sim_time": "true"}, "clock of its own"),
])
def test_bad_pairs_are_refused_before_anything_starts(launch_file, tmp_path, arguments, error):
    with pytest.raises(ValueError, match=error):
        evaluate(launch_file, out=str(tmp_path / "run"), **arguments)
    assert not (tmp_path / "run").exists()

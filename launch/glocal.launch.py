"""``ros2 launch glocal_ros glocal.launch.py``: one run of the whole graph, on a full ROS 2 install.

    ros2 launch glocal_ros glocal.launch.py strategy:=glocal preset:=smoke seed:=0 \\
        namespace:=robot1 use_sim_time:=true out:=runs/smoke foxglove:=true
    ros2 launch glocal_ros glocal.launch.py preset:=smoke pairs:=2 out:=runs/pairs

Arguments (``ros2 launch glocal_ros glocal.launch.py --show-args`` lists them):
``strategy`` (default glocal), ``preset`` (a parameter file of
share/glocal_ros/assets/params: smoke, demo, paper; default demo), ``seed``
(default 0), ``out`` (the run directory; default
``$ROS_HOME/glocal_ros/runs/<strategy>-seed<seed>``), ``namespace`` (default
none; relative, so an including launch file's PushRosNamespace prefixes it)
``use_sim_time`` (default false), ``step_budget`` (training steps of the
run; default: the preset's), ``learner_profile`` (default: the preset's;
glocal_ros or paper, with departures or not, ``learner_node/profiles.py``)
and ``foxglove``
(default false; true also starts foxglove_bridge_node, first, serving the
graph's topics on ws://``foxglove_host``:``foxglove_port``, default
127.0.0.1:8765: another host is an explicit choice) and ``pairs`` (default 1:
the graph as it always was; K >= 2: K sim/learner pairs in ``pair0`` ..
``pairK-1`` under the namespace, training GloCAL's local tasks at once, as
``glocal-ros launch --pairs K`` starts them; refused with ``use_sim_time``
and with a sequential strategy, not checked against the machine's cores).

It starts recorder_node, sim_node, learner_node and curriculum_node with the
parameters ``glocal-ros launch`` gives them, from the one plan of both
(``glocal_app.processes.RunOptions``, built here from the arguments of the
same names): the preset's file, the seed, and
the run directory's ``bag/`` (``bag.1/``, ... on later launches),
``policies/`` and ``curriculum/``; ``use_sim_time`` goes to sim_node and
recorder_node only (the learner's and the curriculum's timeouts are
wall-clock). A directory that holds another run (strategy, preset, seed) is
refused, as ``glocal-ros launch`` refuses it. When the curriculum node ends
(its run finished, or it failed) the launch shuts down: the other nodes get
SIGINT, the recorder closes the bag, and the same command resumes an
interrupted run.

What ``glocal-ros launch`` adds and this file leaves to ROS: the domain is
the environment's ``ROS_DOMAIN_ID``, as for any ``ros2 launch``; the four
nodes start at once (the curriculum waits for the learner's services, the
learner for the sim's; the recorder, which loads no learning library, is up
long before the first episode, and logs the first episode's seq if it is
not 0); no progress bar, no watchdog, no report (``glocal-ros report OUT
--out OUT/report`` writes it).

Imports only launch, launch_ros, ament_index_python and the standard-library
module ``glocal_app.processes``: the ``ros2`` command's interpreter need not
have the project's Python dependencies. ``test/test_launch_file.py`` runs
``generate_launch_description`` against stand-ins of launch and launch_ros.
"""

from __future__ import annotations

from pathlib import Path

from ament_index_python.packages import get_package_share_directory
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument, EmitEvent, OpaqueFunction, RegisterEventHandler
from launch.event_handlers import OnProcessExit
from launch.events import Shutdown
from launch_ros.actions import Node

from glocal_app.processes import (FOXGLOVE_HOST, FOXGLOVE_PORT, FoxgloveEndpoint, check_foxglove_endpoint,
                                  RunOptions, check_pairs, claim_run_dir, default_run_dir, namespace_remappings,
                                  new_bag_path, node_namespace, normalize_namespace, preset_file,
                                  run_nodes as planned_nodes, split_node_path)

PACKAGE = "glocal_ros"
#: As glocal_ros.curriculum.codes.STRATEGY_NAMES (not imported: see the docstring; a test compares them).
STRATEGIES = ("glocal", "random", "alp_gmm_250", "alp_gmm_10", "glocal_no_global", "glocal_random_cluster")
#: As learner_node.profiles.PROFILES (not imported: see the docstring; a test compares them).
LEARNER_PROFILES = ("glocal_ros", "paper")
BOOLEANS = ("true", "false")


def params_dir() -> Path:
    return Path(get_package_share_directory(PACKAGE)) / "assets" / "params"


def seed_value(text: str) -> int:
    if not text.strip().isdigit():
        raise ValueError(f"seed:={text!r}: expected a non-negative integer")
    return int(text)


def step_budget_value(text: str) -> int | None:
    if not text.strip():
        return None
    if not text.strip().isdigit() or int(text) < 1:
        raise ValueError(f"step_budget:={text!r}: expected training steps, 1 or more (empty: the preset's)")
    return int(text)


def pairs_value(text: str) -> int:
    if not text.strip().isdigit() or int(text) < 1:
        raise ValueError(f"pairs:={text!r}: expected a number of sim/learner pairs, 1 or more")
    return int(text)


def foxglove_endpoint(arguments) -> FoxgloveEndpoint | None:
    """Where the bridge serves (None: no bridge); ``ValueError`` for a port that is invalid or taken."""
    if arguments["foxglove"].strip().lower() != "true":
        return None
    port = arguments["foxglove_port"].strip()
    if not port.isdigit():
        raise ValueError(f"foxglove_port:={port!r}: expected a port number, 1..65535")
    endpoint = FoxgloveEndpoint(int(port), arguments["foxglove_host"].strip() or FOXGLOVE_HOST)
    check_foxglove_endpoint(endpoint)
    return endpoint


def run_nodes(context, *args, **kwargs) -> list:
    """The run's nodes, from the arguments' values (an OpaqueFunction: plain values, not substitutions)."""
    arguments = context.launch_configurations
    strategy, preset = arguments["strategy"], arguments["preset"]
    seed = seed_value(arguments["seed"])
    foxglove = foxglove_endpoint(arguments)
    use_sim_time = arguments["use_sim_time"].strip().lower() == "true"
    namespace = normalize_namespace(arguments["namespace"])
    run_dir = Path(arguments["out"]).expanduser().resolve() if arguments["out"].strip() else \
        default_run_dir(strategy, seed)
    params_file = preset_file(preset, params_dir())
    learner_profile = arguments["learner_profile"].strip() or None
    # Departures (base+departure...) are the learner's to check: it refuses unknown ones by name.
    if learner_profile is not None and learner_profile.split("+")[0] not in LEARNER_PROFILES:
        raise ValueError(f"learner_profile:={learner_profile!r}: expected one of {', '.join(LEARNER_PROFILES)}, "
                         "with departures (base+departure...) or not")
    options = RunOptions(preset, step_budget_value(arguments["step_budget"]), learner_profile,
                         pairs_value(arguments["pairs"]), namespace, use_sim_time)
    check_pairs(options.pairs, strategy, force=True, use_sim_time=use_sim_time)
    claim_run_dir(run_dir, options.settings(strategy, seed))
    plan = options.parameters(strategy, seed, run_dir, new_bag_path(run_dir), foxglove)

    def node(path: str) -> Node:
        where = node_namespace(namespace, path)
        return Node(
            package=PACKAGE, executable=split_node_path(path)[1], output="screen",
            # Relative: an including launch file's PushRosNamespace comes in front of it.
            namespace=where.lstrip("/") or None,
            parameters=[str(params_file), plan[path]],
            remappings=namespace_remappings(where),
        )

    nodes = {path: node(path) for path in planned_nodes(foxglove, options.pairs)}
    # The run is over when the curriculum node ends: stop the rest, as glocal-ros launch does.
    end_of_run = RegisterEventHandler(OnProcessExit(
        target_action=nodes["curriculum_node"],
        on_exit=[EmitEvent(event=Shutdown(reason="curriculum_node ended"))],
    ))
    return [*nodes.values(), end_of_run]


def generate_launch_description() -> LaunchDescription:
    presets = sorted(path.stem for path in params_dir().glob("*.yaml"))
    return LaunchDescription([
        DeclareLaunchArgument("strategy", default_value="glocal", choices=list(STRATEGIES),
                              description="the curriculum strategy"),
        DeclareLaunchArgument("preset", default_value="demo", choices=presets,
                              description="parameter file of share/glocal_ros/assets/params"),
        DeclareLaunchArgument("seed", default_value="0", description="seeds the sim's episodes, the learner and "
                              "the curriculum: the same seed repeats the run"),
        DeclareLaunchArgument("out", default_value="", description="run directory (bag/, policies/, "
                              "curriculum/); empty: $ROS_HOME/glocal_ros/runs/<strategy>-seed<seed>"),
        DeclareLaunchArgument("namespace", default_value="", description="namespace of every node, e.g. robot1 "
                              "(several graphs on one domain); topics are then /robot1/..."),
        DeclareLaunchArgument("use_sim_time", default_value="false", choices=list(BOOLEANS),
                              description="sim_node and recorder_node on the sim's clock (<namespace>/clock)"),
        DeclareLaunchArgument("step_budget", default_value="", description="training steps of the run; empty: "
                              "the preset's"),
        DeclareLaunchArgument("learner_profile", default_value="", description="the learner profile, "
                              f"one of {', '.join(LEARNER_PROFILES)}, with departures "
                              "(paper+time-limit-bootstrap) or not; empty: the preset's"),
        DeclareLaunchArgument("foxglove", default_value="false", choices=list(BOOLEANS),
                              description="also start foxglove_bridge_node: the graph's topics live in Foxglove "
                              "over its WebSocket protocol (layout: share/glocal_ros/assets/foxglove/glocal.json)"),
        DeclareLaunchArgument("foxglove_port", default_value=str(FOXGLOVE_PORT),
                              description="the bridge's TCP port"),
        DeclareLaunchArgument("foxglove_host", default_value=FOXGLOVE_HOST, description="the address the bridge "
                              "serves on: 127.0.0.1 is this host only; e.g. 0.0.0.0 lets other hosts connect "
                              "(no authentication)"),
        DeclareLaunchArgument("pairs", default_value="1", description="sim/learner pairs: 1, the graph as it "
                              "always was; K >= 2 starts pairs in <namespace>/pair0 .. pairK-1 that train GloCAL's "
                              "local tasks at once (glocal, glocal_random_cluster; wall-clock)"),
        OpaqueFunction(function=run_nodes),
    ])

"""A run's nodes: what each one gets (the plan), and nodes as child processes.

The plan is ROS-free and is the one source of both ways to start a run:
``glocal-ros launch`` (``glocal_app.launch``) and ``ros2 launch glocal_ros
glocal.launch.py`` (``launch/glocal.launch.py``) give every node the same
parameters from it: the preset's parameter file, the seed, the run directory's
``bag/``, ``policies/``, ``tensorboard/`` and ``curriculum/``, the namespace and, for the nodes in
``SIM_TIME_NODES`` only, ``use_sim_time``. A run with a Foxglove endpoint
(``--foxglove [PORT]``, ``foxglove:=true``) also starts foxglove_bridge_node on it
(``run_nodes``), first, so that a viewer can connect while the others start.

Pairs: a run of K sim/learner pairs (``--pairs K``, ``pairs:=K``) puts each
pair's sim_node and learner_node in a namespace of its own under the run's,
``pair0`` .. ``pairK-1`` (``pair_namespaces``), and names them to the
curriculum (``learner_namespaces``, with ``parallel_locals`` on: K pairs are
started to train local tasks at once) and to the recorder
(``pair_namespaces``: one bag holds every pair's topics under its
namespace). One pair is today's graph exactly, with no pair namespace: its
nodes, topics and bags stay as they were. Every learner gets the run's one
policy directory. The plan names each node by its path under the run's
namespace: ``sim_node``, or ``pair1/sim_node`` (``node_path``).

A process is started as ``glocal-ros run NODE``, logged to a file and stopped
cleanly.

Standard library only at import: the launch file runs in the ``ros2``
command's own interpreter, which need not have the project's Python
dependencies (importing ``glocal_ros`` loads gymnasium).
"""

from __future__ import annotations

import errno
import json
import os
import re
import signal
import socket
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Mapping, Sequence

#: The nodes of a run of one pair, in the order they start (they stop in the reverse order).
RUN_NODES = ("recorder_node", "sim_node", "learner_node", "curriculum_node")
#: The nodes of one sim/learner pair, in the order they start.
PAIR_NODES = ("sim_node", "learner_node")
#: The strategies that train on several pairs at once (GloCAL's local tasks, ``parallel_locals``): as
#: ``glocal_ros.curriculum.glocal`` runs them (not imported: see the docstring; a test compares them).
PARALLEL_STRATEGIES = ("glocal", "glocal_random_cluster")
#: What the namespace of pair i is called, under the run's (runs of two pairs or more).
PAIR_NAMESPACE = "pair{}"
#: The live viewer's bridge, started (first) when the run is given a Foxglove endpoint.
FOXGLOVE_NODE = "foxglove_bridge_node"
#: The nodes that follow the sim's /clock when the run asks for sim time: the sim stamps what it
#: publishes with it, the recorder records on it, the Foxglove bridge gives its messages log times on
#: it. The learner's and the curriculum's timeouts (a service that does not answer, a goal that takes
#: too long) stay wall-clock on purpose.
SIM_TIME_NODES = ("sim_node", "recorder_node", FOXGLOVE_NODE)
#: Foxglove's own default port (foxglove_bridge's and the SDK's; foxglove_bridge_node's default too).
FOXGLOVE_PORT = 8765
#: Where the bridge serves unless told otherwise: this host only. Another address is an explicit opt-in,
#: as reaching other hosts over DDS is (ROS_AUTOMATIC_DISCOVERY_RANGE).
FOXGLOVE_HOST = "127.0.0.1"
#: Where a run directory holds its Train goals' training curves (TensorBoard and CSV, one folder per goal).
TENSORBOARD_DIR = "tensorboard"
#: What records which run a run directory holds (``claim_run_dir``).
RUN_FILE = "run.json"
#: Where a run directory holds the curriculum's latest state (its journal beside it).
STATE_FILE = Path("curriculum") / "state.json"
_NAMESPACE_TOKEN = re.compile(r"[A-Za-z_][A-Za-z0-9_]*")


@dataclass(frozen=True)
class FoxgloveEndpoint:
    """Where a run's foxglove_bridge_node serves: ``ws://host:port``."""

    port: int = FOXGLOVE_PORT
    host: str = FOXGLOVE_HOST

    @property
    def url(self) -> str:
        return f"ws://{self.host}:{self.port}"


def check_foxglove_endpoint(endpoint: FoxgloveEndpoint) -> None:
    """``ValueError`` unless a server can listen on ``endpoint``: a port of 1..65535, a local address, the port free.

    Checked before any node starts, so that a taken port (another run's bridge, a foxglove_bridge) is
    said at once, not in the bridge's log once the run is under way. Bound as the bridge's server binds
    (address reuse on: a port that only lingers in TIME_WAIT is free).
    """
    if not 1 <= endpoint.port <= 65535:
        raise ValueError(f"Foxglove port {endpoint.port}: expected 1..65535")
    try:
        infos = socket.getaddrinfo(endpoint.host, endpoint.port, type=socket.SOCK_STREAM)
    except socket.gaierror as error:
        raise ValueError(f"Foxglove host {endpoint.host!r}: {error.strerror}") from None
    family, kind, protocol, _, address = infos[0]
    with socket.socket(family, kind, protocol) as probe:
        probe.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            probe.bind(address)
        except OSError as error:
            if error.errno == errno.EADDRINUSE:
                raise ValueError(f"Foxglove port {endpoint.port} on {endpoint.host} is in use: choose another "
                                 f"with --foxglove PORT (foxglove_port:=PORT)") from None
            raise ValueError(f"cannot serve Foxglove on {endpoint.host}:{endpoint.port} ({error.strerror}): choose "
                             f"an address of this host with --foxglove-host (foxglove_host:=)") from None


def pair_namespaces(pairs: int = 1) -> tuple[str, ...]:
    """The pairs' namespaces, relative to the run's: ``("",)`` for one pair (today's graph, no pair namespace),
    else ``pair0`` .. ``pair<pairs-1>``."""
    if pairs < 1:
        raise ValueError(f"a run needs at least one sim/learner pair, got {pairs}")
    return ("",) if pairs == 1 else tuple(PAIR_NAMESPACE.format(index) for index in range(pairs))


def node_path(namespace: str, node: str) -> str:
    """A node's path under the run's namespace: ``sim_node`` (no pair namespace) or ``pair1/sim_node``."""
    return f"{namespace}/{node}" if namespace else node


def split_node_path(path: str) -> tuple[str, str]:
    """``(namespace, node)`` of a ``node_path``: ``("pair1", "sim_node")``, ``("", "recorder_node")``."""
    namespace, _, node = path.rpartition("/")
    return namespace, node


def node_namespace(namespace: str, path: str) -> str:
    """The namespace the plan's node ``path`` runs in, in a run under ``namespace`` (normalized; "" for none):
    ``/robot1/pair1`` for ``pair1/sim_node`` under ``robot1``."""
    return normalize_namespace(f"{namespace}/{split_node_path(path)[0]}")


def run_nodes(foxglove: FoxgloveEndpoint | None = None, pairs: int = 1) -> tuple[str, ...]:
    """The nodes of a run (``node_path``) in the order they start: the bridge first when the run has a Foxglove
    endpoint, the recorder, each pair's sim and learner, the curriculum last."""
    bridge = (FOXGLOVE_NODE,) if foxglove is not None else ()
    pair_nodes = tuple(node_path(namespace, node) for namespace in pair_namespaces(pairs) for node in PAIR_NODES)
    return bridge + ("recorder_node",) + pair_nodes + ("curriculum_node",)


def preset_file(preset: str, params_dir: Path | None = None) -> Path:
    """The parameter file of a preset (``assets/params/<preset>.yaml`` unless ``params_dir`` says where)."""
    if params_dir is None:
        from glocal_ros.paths import assets_dir

        params_dir = assets_dir() / "params"
    path = params_dir / f"{preset}.yaml"
    if not path.is_file():
        known = sorted(p.stem for p in params_dir.glob("*.yaml"))
        raise ValueError(f"unknown preset {preset!r}: expected one of {', '.join(known)}")
    return path


def normalize_namespace(namespace: str) -> str:
    """``""`` (the root) or an absolute namespace, ``/robot1``; ``ValueError`` for one ROS would refuse.

    ``robot1``, ``/robot1`` and ``robot1/`` are the same namespace (a run's namespace is absolute).
    """
    stripped = namespace.strip().strip("/")
    if not stripped:
        return ""
    tokens = stripped.split("/")
    if not all(_NAMESPACE_TOKEN.fullmatch(token) for token in tokens):
        raise ValueError(f"invalid namespace {namespace!r}: names of letters, digits and underscores, not starting "
                         f"with a digit, separated by single slashes (e.g. robot1 or lab/robot1)")
    return "/" + "/".join(tokens)


def namespace_remappings(namespace: str) -> list[tuple[str, str]]:
    """Remappings that a node in ``namespace`` ("" for none) needs beside ``__ns`` itself.

    rclpy's time source subscribes to the absolute ``/clock``, while a namespaced sim publishes its
    clock in its namespace (``/robot1/clock``): remapped to the relative ``clock``, every node of a
    namespaced graph hears its own sim's clock, not another graph's.
    """
    return [("/clock", "clock")] if namespace else []


def namespace_arguments(namespace: str) -> list[str]:
    """``--ros-args`` text for ``namespace`` (normalized; "" for none): what ``ros2 launch`` does for a Node."""
    if not namespace:
        return []
    arguments = ["-r", f"__ns:={namespace}"]
    for source, target in namespace_remappings(namespace):
        arguments += ["-r", f"{source}:={target}"]
    return arguments


def default_run_dir(strategy: str, seed: int) -> Path:
    """``$ROS_HOME/glocal_ros/runs/<strategy>-seed<seed>``: a ``ros2 launch`` run given no ``out``.

    ROS_HOME as ``glocal_ros.paths.ros_home`` reads it (not imported: see the module's docstring).
    """
    return Path(os.environ.get("ROS_HOME", Path.home() / ".ros")) / "glocal_ros" / "runs" / f"{strategy}-seed{seed}"


def new_bag_path(run_dir: Path) -> Path:
    """``<run_dir>/bag``, or ``bag.1``, ``bag.2``, ... after earlier launches: one bag per launch."""
    bag = run_dir / "bag"
    index = 1
    while bag.exists():
        bag = run_dir / f"bag.{index}"
        index += 1
    return bag


def recorded_run_settings(run_dir: Path) -> dict[str, object] | None:
    """What RUN_DIR's ``RUN_FILE`` records (``RunOptions.settings``); None when it holds no run."""
    path = run_dir / RUN_FILE
    return json.loads(path.read_text()) if path.is_file() else None


def check_run_dir(run_dir: Path, settings: Mapping[str, object]) -> bool:
    """True when RUN_DIR holds an earlier launch of the run ``settings``; ``ValueError`` when it holds another run."""
    found = recorded_run_settings(run_dir)
    if found is None:
        return False
    if found != dict(settings):
        raise ValueError(f"{run_dir} holds the run {found}, not {dict(settings)}: choose another run directory (--out)")
    return True


def claim_run_dir(run_dir: Path, settings: Mapping[str, object]) -> bool:
    """Record which run RUN_DIR holds (``RunOptions.settings``); True when it resumes an earlier launch.

    Another run's directory is refused (``check_run_dir``).
    """
    if check_run_dir(run_dir, settings):
        return True
    run_dir.mkdir(parents=True, exist_ok=True)
    (run_dir / RUN_FILE).write_text(json.dumps(dict(settings)) + "\n")
    return False


def preset_parameters(preset: str, node: str, params_dir: Path | None = None) -> dict[str, object]:
    """The parameters a preset gives ``node`` (its ``/**/NODE`` section)."""
    from ruamel.yaml import YAML  # not at import: see the module's docstring

    document = YAML(typ="safe").load(preset_file(preset, params_dir).read_text()) or {}
    return dict(document.get(f"/**/{node}", {}).get("ros__parameters", {}))


def check_episode_steps(preset: str, params_dir: Path | None = None) -> None:
    """``ValueError`` unless the preset gives the sim's T (``max_steps``) and the curriculum's
    (``max_episode_steps``, which sizes the baselines' goals) the same value."""
    from glocal_ros.sim_contract import DEFAULT_EPISODE_STEPS

    sim = preset_parameters(preset, "sim_node", params_dir).get("max_steps", DEFAULT_EPISODE_STEPS)
    curriculum = preset_parameters(preset, "curriculum_node", params_dir).get("max_episode_steps",
                                                                              DEFAULT_EPISODE_STEPS)
    if sim != curriculum:
        raise ValueError(f"preset {preset}: sim_node max_steps {sim} and curriculum_node max_episode_steps "
                         f"{curriculum} must be the same T")


def check_step_budget(preset: str, step_budget: int | None) -> None:
    """``ValueError`` when ``step_budget`` (None: the preset's own) ends before any strategy evaluates a trained task.

    GloCAL checks a training task every ``eval_interval`` steps, the baselines evaluate every
    ``baseline_eval_interval`` steps: a budget below either leaves that strategy nothing to learn by.
    """
    if step_budget is None:
        return
    parameters = preset_parameters(preset, "curriculum_node")
    intervals = {name: int(parameters[name]) for name in ("eval_interval", "baseline_eval_interval")
                 if name in parameters}
    if step_budget < max(intervals.values(), default=1):
        shown = ", ".join(f"{name} {value}" for name, value in intervals.items())
        raise ValueError(f"a budget of {step_budget} training steps is below one evaluation of preset {preset} "
                         f"({shown}): a strategy would never evaluate what it trained")


def check_learner_profile(name: str | None) -> None:
    """``ValueError`` naming the profiles unless ``name`` is one (None: the preset's)."""
    if name is not None:
        from learner_node.profiles import learner_profile

        learner_profile(name)


def check_writable_directory(folder: Path, option: str) -> None:
    """``ValueError`` naming ``option`` unless ``folder`` can be made and written to (it is made)."""
    try:
        folder.mkdir(parents=True, exist_ok=True)
        with tempfile.TemporaryFile(dir=folder):
            pass
    except OSError as error:
        raise ValueError(f"{option} {folder}: not a directory this user can write to ({error.strerror})") from None


@dataclass(frozen=True)
class RunOptions:
    """What a run is beside its strategy and seed, and what every run of one experiment shares.

    Each way to start runs builds one and hands it on whole: the command line
    (``glocal_app.arguments.run_options``), the launch file (from its
    arguments), ``glocal-ros pair`` (``from_settings``: a run directory's
    ``RUN_FILE``). From it come the checks before anything starts (``check``),
    what ``RUN_FILE`` records (``settings``) and what each node gets (the plan,
    ``parameters``), for ``launch``, experiments, Ray tasks and the benches
    alike. An option has one name throughout: the field, the command line's
    ``--step-budget``, ``--learner-profile``, ... (dashes for underscores), the
    launch file's ``step_budget:=``, ... and the node parameter it sets.
    """

    preset: str
    #: Training steps of the whole run, instead of the preset's (the curriculum's ``step_budget``).
    step_budget: int | None = None
    #: Instead of the preset's (every learner's ``learner_profile``).
    learner_profile: str | None = None
    pairs: int = 1
    namespace: str = ""
    use_sim_time: bool = False

    def check(self, strategies: Sequence[str] = (), force: bool = True, remote_pairs: int = 0) -> RunOptions:
        """These options with the namespace normalised; ``ValueError`` before anything starts for an unknown
        preset or profile, a preset whose T differs between sim and curriculum, a budget below one evaluation, an
        invalid namespace, or pairs that ``check_pairs`` refuses with any of ``strategies`` (``force``: more
        pairs than cores, the command line's to check)."""
        preset_file(self.preset)
        check_episode_steps(self.preset)
        check_step_budget(self.preset, self.step_budget)
        check_learner_profile(self.learner_profile)
        for strategy in strategies or (None,):
            check_pairs(self.pairs, strategy, force, self.use_sim_time, remote=remote_pairs)
        return replace(self, namespace=normalize_namespace(self.namespace))

    def settings(self, strategy: str, seed: int) -> dict[str, object]:
        """What ``RUN_FILE`` records of the run: its strategy, preset and seed, the budget and learner profile
        where they replace the preset's, and its pairs when more than one (a run of one pair records what it
        always did). Namespace and clock are how a run is watched, not which run it is."""
        settings: dict[str, object] = {"strategy": strategy, "preset": self.preset, "seed": seed}
        if self.step_budget is not None:
            settings["step_budget"] = self.step_budget
        if self.learner_profile is not None:
            settings["learner_profile"] = self.learner_profile
        if self.pairs != 1:
            settings["pairs"] = self.pairs
        return settings

    @classmethod
    def from_settings(cls, settings: Mapping[str, object], namespace: str = "",
                      use_sim_time: bool = False) -> RunOptions:
        """The options of a run as ``settings`` (its ``RUN_FILE``) records them."""
        budget, profile = settings.get("step_budget"), settings.get("learner_profile")
        return cls(str(settings["preset"]), None if budget is None else int(budget),
                   None if profile is None else str(profile), int(settings.get("pairs", 1)), namespace, use_sim_time)

    def parameters(self, strategy: str, seed: int, run_dir: Path, bag: Path, foxglove: FoxgloveEndpoint | None = None,
                   tensorboard_dir: Path | None = None) -> dict[str, dict[str, object]]:
        """What each node of the run gets on top of its preset, keyed by ``node_path``, in ``run_nodes`` order.

        ``use_sim_time`` is given to the nodes of ``SIM_TIME_NODES`` only, and only when on: a node
        without it keeps whatever its preset says. ``step_budget`` and ``learner_profile`` replace the
        preset's when given; ``foxglove`` adds the bridge, serving there. Every learner writes its goals'
        training curves in ``tensorboard_dir`` (default ``RUN_DIR/tensorboard``). ``pairs`` above one: every
        pair's sim and learner get the same seed and the one policy directory; the recorder and the
        curriculum get the pairs' namespaces (relative: they resolve under the run's), and the curriculum
        ``parallel_locals``.
        """
        budget = {"step_budget": self.step_budget} if self.step_budget is not None else {}
        sim_time = {"use_sim_time": True} if self.use_sim_time else {}
        profile = {"learner_profile": self.learner_profile} if self.learner_profile is not None else {}
        bridge = {FOXGLOVE_NODE: {"port": foxglove.port, "address": foxglove.host, **sim_time}} if foxglove else {}
        namespaces = pair_namespaces(self.pairs)
        listed = ",".join(namespaces)
        curves = str(tensorboard_dir or run_dir / TENSORBOARD_DIR)
        pair_nodes: dict[str, dict[str, object]] = {}
        for namespace in namespaces:
            pair_nodes[node_path(namespace, "sim_node")] = {"seed": seed, **sim_time}
            pair_nodes[node_path(namespace, "learner_node")] = {
                "seed": seed, "policy_dir": str(run_dir / "policies"), "tensorboard_dir": curves, **profile}
        several = self.pairs > 1
        parallel = {"learner_namespaces": listed, "parallel_locals": True} if several else {}
        return {
            **bridge,
            "recorder_node": {"output": str(bag), **sim_time, **({"pair_namespaces": listed} if several else {})},
            **pair_nodes,
            "curriculum_node": {"strategy": strategy, "seed": seed, "state_dir": str(run_dir / STATE_FILE.parent),
                                **budget, **parallel},
        }


def check_pairs(pairs: int, strategy: str | None = None, force: bool = False, use_sim_time: bool = False,
                cpus: int | None = None, remote: int = 0) -> None:
    """``ValueError`` unless a run can have ``pairs`` sim/learner pairs, ``remote`` of them started on other
    hosts: at least one pair, no more started here than this machine's cores (``os.cpu_count()``; each pair is
    a sim and a learner busy at once) unless ``force``, and several only for a strategy that trains on several
    at once (``PARALLEL_STRATEGIES``: the others are sequential and would leave every pair but the first idle)
    and on wall-clock (each pair's sim has a clock of its own: there is no one sim time to record a bag of
    several pairs on). Remote pairs are pairs of a run of several (a run of one has no pair namespace)."""
    if pairs > 1 and use_sim_time:
        raise ValueError(f"--pairs {pairs} with --use-sim-time: each pair's sim has a clock of its own, so a run "
                         f"of several pairs records on wall-clock")
    if pairs < 1:
        raise ValueError(f"--pairs {pairs}: a run needs at least one sim/learner pair")
    if remote and (remote < 0 or remote > pairs or pairs < 2):
        raise ValueError(f"--remote-pairs {remote} of --pairs {pairs}: expected 0, or 1 to {pairs} of a run of "
                         f"2 pairs or more")
    cpus = (os.cpu_count() or 1) if cpus is None else cpus
    if pairs - remote > cpus and not force:
        raise ValueError(f"--pairs {pairs} is more pairs than this machine has cores ({cpus}); each pair is a sim "
                         f"and a learner training at once: --force starts them anyway")
    if pairs > 1 and strategy is not None and strategy not in PARALLEL_STRATEGIES:
        raise ValueError(f"--pairs {pairs} with strategy {strategy}: only {', '.join(PARALLEL_STRATEGIES)} train "
                         f"local tasks on several pairs at once (the other strategies are sequential)")


def remote_pair_indices(pairs: int, remote: int) -> range:
    """The indices of the pairs started on other hosts: the last ``remote`` of ``pairs``."""
    return range(pairs - remote, pairs)


def ros_param_text(value) -> str:
    """A Python value as ``-p name:=value`` text that ROS parses back to the same type."""
    if isinstance(value, bool):
        return "true" if value else "false"
    return str(value)


class NodeProcess:
    """One node process. Its output goes to ``<log_dir>/<name>-<time>.log`` (``pair1-sim_node-...`` for
    ``pair1/sim_node``).

    ``node`` is the executable; ``name`` what messages call it, its path in the run's plan (``node_path``;
    default: ``node``).
    """

    def __init__(
        self,
        node: str,
        log_dir: Path,
        params: Mapping[str, object] | None = None,
        params_file: Path | None = None,
        env: Mapping[str, str] | None = None,
        extra_args: Sequence[str] = (),
        cwd: Path | None = None,
        name: str | None = None,
    ):
        self.node = node
        self.name = name or node
        log_dir.mkdir(parents=True, exist_ok=True)
        stem = self.name.replace("/", "-")
        self.log_path = log_dir / f"{stem}-{time.strftime('%Y%m%d-%H%M%S')}-{time.monotonic_ns() % 10**6}.log"
        command = [sys.executable, "-m", "glocal_app.cli", "run", node, "--ros-args"]
        if params_file is not None:
            command += ["--params-file", str(params_file)]
        for name, value in (params or {}).items():
            command += ["-p", f"{name}:={ros_param_text(value)}"]
        command += list(extra_args)
        self._log = open(self.log_path, "w")
        self.process = subprocess.Popen(
            command, stdout=self._log, stderr=subprocess.STDOUT, cwd=cwd,
            env=dict(env) if env is not None else None,
            # Own process group: a Ctrl-C in the terminal reaches the launcher,
            # which then stops the nodes in order.
            start_new_session=True,
        )

    @property
    def running(self) -> bool:
        return self.process.poll() is None

    def log(self) -> str:
        return self.log_path.read_text()

    def stop(self, sig: int = signal.SIGINT, timeout: float = 20.0) -> int:
        """Signal the node, wait for it, kill it if it does not end; its exit code."""
        if self.running:
            self.process.send_signal(sig)
            try:
                self.process.wait(timeout)
            except subprocess.TimeoutExpired:
                self.process.kill()
                self.process.wait()
        self._log.close()
        return self.process.returncode


def isolated_environment(domain_id: int, log_dir: Path, keep_discovery_range: bool = False) -> dict[str, str]:
    """This process's environment on ``domain_id``, discovery on loopback, ROS logs in ``log_dir``.

    A domain chosen free on this machine is only free here, so discovery is forced onto loopback.
    ``keep_discovery_range``: the user chose the domain, and a ``ROS_AUTOMATIC_DISCOVERY_RANGE`` of
    theirs (SUBNET, to watch from another host) is kept; unset, the nodes take LOCALHOST
    (``node_common.runner.configure_discovery``).
    """
    env = dict(os.environ)
    env.update(ROS_DOMAIN_ID=str(domain_id), ROS_LOG_DIR=str(log_dir), PYTHONUNBUFFERED="1")
    if not keep_discovery_range:
        env["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
    env.setdefault("AMENT_PREFIX_PATH", sys.prefix)
    return env

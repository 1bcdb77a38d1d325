"""``glocal-ros launch``: the whole graph as processes, on your ROS domain or a free one.

``launch`` starts recorder, sim and learner, waits until the recorder
listens to the episode stream, then starts the curriculum and shows its
progress (training steps, learned objects, current task) until the
curriculum node ends. The other nodes are then stopped in reverse order with
SIGINT, so the bag is closed cleanly, and the report is written from the
run's bags. Ctrl-C does the same at any time, and the same command resumes
the run: RUN_DIR keeps the curriculum's journal (``curriculum/``), the
learner's policies and checkpoints (``policies/``), one bag per launch
(``bag/``, ``bag.1/``, ...), the training curves (``tensorboard/``, or ``--tensorboard DIR``),
``logs/`` and ``report/``; with a Foxglove endpoint, also the
Foxglove layout written for the run's namespace (``foxglove-layout.json``,
``glocal_ros.foxglove_layout``), which opens the live graph and the run's bags alike.

The seed goes to sim, learner and curriculum alike, so that a run with the
same seed repeats this one. Every node gets what ``glocal_app.processes.
RunOptions.parameters`` plans, as ``ros2 launch glocal_ros glocal.launch.py`` gives it.

The domain is the user's ``ROS_DOMAIN_ID`` when set (a viewer already runs
on it), else a free one of this machine (``glocal_ros.domain``); the launch
prints which. A namespace (``--namespace robot1``) puts every node, and the
launcher's own subscriptions and service probe, under ``/robot1``, so that
several graphs can share a domain; ``--use-sim-time`` gives sim_node and
recorder_node ``use_sim_time`` (the sim's /clock), while the learner's and the
curriculum's timeouts stay wall-clock.

Pairs (``--pairs K``, K >= 2): K sims and K learners, pair i in
``<namespace>/pair<i>``, as ``RunOptions.parameters`` plans them; the
launch waits until the recorder listens to every pair's episodes, and the
progress bar and the watchdog hear every pair (a stall names the pairs whose
learner no longer answers). ``--remote-pairs R`` leaves the last R pairs to
other hosts: the launch prints for each the ``glocal-ros pair`` command that
starts it there (``serve_pair``) and waits for it.

On the user's ROS_DOMAIN_ID other graphs may run: the launch first listens
to the domain for a few seconds and refuses to start a node whose name, in
its namespace, another graph already uses (``check_names_free``).

A watchdog stops a hung run instead of letting it wait: when a node process
ends before the curriculum does, or nothing moves for ``watchdog_sec``
(no episode, no training progress, no curriculum state, and before a resumed
run's first state no report of its journal's replay: a running graph sends
one of those every few seconds, evaluating or training), the launch
says what it last heard, what the curriculum was waiting for and whether
the learner still answers, stops the graph as Ctrl-C does, and exits with
``EXIT_STALLED``; the same command resumes the run.

``glocal-ros experiment`` is many launches: ``glocal_app.experiment``.
"""

from __future__ import annotations

import json
import signal
import sys
import time
from pathlib import Path
from typing import Sequence

import rclpy
from diagnostic_msgs.msg import DiagnosticArray
from glocal_interfaces.msg import CurriculumState, EpisodeRecord, TrainingProgress
from glocal_interfaces.srv import ListPolicies
from rclpy.node import Node
from rclpy.signals import SignalHandlerOptions

from glocal_app.exit_codes import EXIT_FAILED, EXIT_INTERRUPTED, EXIT_STALLED
from glocal_app.processes import (PAIR_NAMESPACE, PAIR_NODES, STATE_FILE, TENSORBOARD_DIR, FoxgloveEndpoint,
                                  NodeProcess, RunOptions, check_foxglove_endpoint, check_writable_directory,
                                  claim_run_dir, isolated_environment, namespace_arguments, new_bag_path,
                                  node_namespace, node_path, normalize_namespace, pair_namespaces, preset_file,
                                  recorded_run_settings, remote_pair_indices, run_nodes, split_node_path)
from glocal_app.provenance import record_code_version
from glocal_ros.domain import Domain, choose_domain_id, domain_id_from_environment
from glocal_ros.foxglove_layout import RUN_LAYOUT, write_layout
from glocal_ros.recording import message_counts
from glocal_ros.topics import REPLAY_STATUS
from node_common import names, qos
from node_common.runner import configure_discovery

STATUS_NAMES = {value: name.removeprefix("STATUS_").lower() for name, value in vars(CurriculumState).items()
                if name.startswith("STATUS_")}
#: Seconds without an episode, a progress report or a curriculum state before a run counts as hung.
#: Longer than the curriculum's own re-send of an unanswered goal (ros_learner.GOAL_RESPONSE_TIMEOUT_SEC).
DEFAULT_WATCHDOG_SEC = 60.0
#: How much longer than the start-up timeout a launch waits for pairs started on other hosts (by hand).
REMOTE_PAIR_WAIT_SEC = 600.0
#: How long a launch on the user's ROS_DOMAIN_ID listens for the domain's nodes before it checks its names.
DISCOVERY_SEC = 5.0
LEARNER_PROBE_SEC = 5.0
#: What the watchdog calls the curriculum's state: once heard, the run has started.
CURRICULUM_HEARD = "curriculum state"
#: A resumed curriculum replaying its journal, before its first state (``curriculum_node``'s diagnostics).
REPLAY_HEARD = "curriculum replay"


class GraphStalled(RuntimeError):
    """A node of the run ended early, or the run made no progress: the message says which and where."""


class Watchdog:
    """When the graph was last heard from, and what it said.

    The silence allowed is ``silence_sec`` once the curriculum has published its first state, and
    ``startup_sec`` (if longer) before: a node that starts, and is discovered, on a loaded machine can
    take longer than a phase may stay silent.
    """

    def __init__(self, silence_sec: float, startup_sec: float = 0.0):
        self.silence_sec = silence_sec
        self.startup_sec = startup_sec
        self.last_heard: dict[str, float] = {}
        self.started = time.monotonic()

    def heard(self, what: str) -> None:
        self.last_heard[what] = time.monotonic()

    def silent_for(self) -> float:
        return time.monotonic() - max(self.last_heard.values(), default=self.started)

    def stalled(self) -> bool:
        allowed = self.silence_sec
        if CURRICULUM_HEARD not in self.last_heard:
            allowed = max(allowed, self.startup_sec)
        return self.silent_for() > allowed

    def describe_silence(self, state: CurriculumState | None, progress: TrainingProgress | None) -> str:
        now = time.monotonic()
        heard = ", ".join(f"{what} {now - when:.0f} s ago" for what, when in sorted(self.last_heard.items(),
                                                                                     key=lambda item: -item[1]))
        text = f"no progress for {self.silent_for():.0f} s (last heard: {heard or 'nothing'})"
        if state is not None:
            status = STATUS_NAMES.get(state.status, state.status)
            text += f"; the curriculum was {status} {state.current_task or ''}".rstrip()
            if state.status in (CurriculumState.STATUS_TRAINING, CurriculumState.STATUS_TRAINING_GLOBAL,
                                CurriculumState.STATUS_TRAINING_LOCAL):
                text += f", waiting for learner/train ({state.current_policy})"
            elif state.status == CurriculumState.STATUS_EVALUATING:
                text += ", waiting for learner/evaluate"
        if progress is not None:
            text += f"; the learner last reported {progress.output_policy} at step {progress.goal_steps}"
        return text


def describe(state: CurriculumState) -> str:
    text = f"[{state.strategy}] iteration {state.iteration}, {STATUS_NAMES.get(state.status, state.status)}"
    if state.clusters:
        text += f", {len(state.clusters)} clusters, C1 = {','.join(state.clusters[0].tasks)}"
    if state.global_task:
        text += f", global task {state.global_task}, local tasks {','.join(state.local_tasks) or '-'}"
    return text + f", learned {len(state.learned_tasks)}/{len(state.learned_tasks) + len(state.remaining_tasks)}"


def run_finished(run_dir: Path) -> bool:
    state = run_dir / STATE_FILE
    return state.is_file() and json.loads(state.read_text())["status"] == CurriculumState.STATUS_FINISHED


class Progress:
    """A progress bar over the run's training steps: learned objects and the current task beside it."""

    def __init__(self):
        from tqdm import tqdm

        self.bar = tqdm(total=0, unit="step", desc="training", dynamic_ncols=True)
        self.state: CurriculumState | None = None
        self.progress: TrainingProgress | None = None
        self.goal_steps: dict[str, int] = {}  # of the goal each pair reported last, by pair
        self.shown_iteration = None

    def on_state(self, state: CurriculumState) -> None:
        if state.iteration != self.shown_iteration and state.clusters:
            self.shown_iteration = state.iteration
            self.bar.write(describe(state))
        self.state = state
        self.goal_steps.clear()
        self._draw()

    def on_replay(self, message: str) -> None:
        """A resumed curriculum's replay of its journal, shown until its first state."""
        if self.state is None:
            self.bar.set_postfix_str(message, refresh=True)

    def on_progress(self, progress: TrainingProgress, pair: str = "") -> None:
        self.progress = progress
        self.goal_steps[pair] = progress.goal_steps
        self._draw()

    def _draw(self) -> None:
        state = self.state
        if state is None:
            return
        self.bar.total = state.step_budget
        self.bar.n = min(state.total_steps + sum(self.goal_steps.values()), state.step_budget)
        total = len(state.learned_tasks) + len(state.remaining_tasks)
        self.bar.set_postfix_str(f"learned {len(state.learned_tasks)}/{total}, iteration {state.iteration}, "
                                 f"{STATUS_NAMES.get(state.status, state.status)} {state.current_task}".rstrip(),
                                 refresh=True)

    def close(self) -> None:
        self.bar.close()
        if self.state is not None:
            print(describe(self.state))


def pair_name(pair: str, name: str) -> str:
    """``name`` under a pair's namespace (relative to the run's), as the launcher's node resolves it."""
    return f"{pair}/{name}" if pair else name


def learner_answers(node, timeout_sec: float = LEARNER_PROBE_SEC, pair: str = "") -> bool:
    """Whether the learner_node of ``pair`` ("" the run's own) answers learner/list_policies (served beside a
    running goal) in time."""
    client = node.create_client(ListPolicies, pair_name(pair, names.LEARNER_LIST_POLICIES))
    try:
        future = client.call_async(ListPolicies.Request())
        rclpy.spin_until_future_complete(node, future, timeout_sec=timeout_sec)
        return future.done()
    finally:
        node.destroy_client(client)


def check_graph(node, watchdog: Watchdog, progress: Progress, started: Sequence[NodeProcess],
                curriculum: NodeProcess, pairs: Sequence[str] = ("",)) -> None:
    """Raise ``GraphStalled`` when a node other than the curriculum ended, or the run stopped moving.

    ``pairs``: the pairs' namespaces (``processes.pair_namespaces``); a stall says whose learner answers.
    """
    for process in started:
        if process is not curriculum and not process.running:
            raise GraphStalled(f"{process.name} ended (exit code {process.process.returncode}) while the run "
                               f"went on: see {process.log_path}")
    if watchdog.stalled():
        text = watchdog.describe_silence(progress.state, progress.progress)
        for pair in pairs:
            learner = pair_name(pair, "learner_node")
            answers = learner_answers(node, pair=pair)
            text += f"; {learner} answers requests" if answers else f"; {learner} does not answer requests"
        raise GraphStalled(text)


def launch(strategy: str, seed: int, run_dir: Path, options: RunOptions, startup_timeout: float = 120.0,
           report: bool = True, watchdog_sec: float = DEFAULT_WATCHDOG_SEC, foxglove: FoxgloveEndpoint | None = None,
           remote_pairs: int = 0, tensorboard_dir: Path | None = None) -> int:
    """Run (or resume) one run in ``run_dir``; the curriculum's exit code, ``EXIT_INTERRUPTED`` on Ctrl-C or
    ``EXIT_STALLED``.

    ``options``: the run's preset, budget, learner profile, pairs, namespace and clock (``RunOptions``).
    ``foxglove`` starts foxglove_bridge_node there, before the other nodes; the last ``remote_pairs`` of the
    pairs are started on other hosts (``serve_pair``; the launch waits for them on the user's ROS_DOMAIN_ID);
    the learners here write their goals' training curves in ``tensorboard_dir`` (default
    ``RUN_DIR/tensorboard``; a remote pair's, in its host's ``RUN_DIR/tensorboard``). Bad input (what
    ``RunOptions.check`` refuses but for the machine's cores, which the command line checks; an invalid
    ROS_DOMAIN_ID, another run's directory, a Foxglove port that is taken or invalid, a ``tensorboard_dir``
    that cannot be written, remote pairs without a ROS_DOMAIN_ID set, a node of the plan already running on
    the user's domain: ``check_names_free``) raises ``ValueError`` before anything starts.
    """
    options = options.check([strategy], force=True, remote_pairs=remote_pairs)
    namespace, pairs = options.namespace, options.pairs
    if foxglove is not None:
        check_foxglove_endpoint(foxglove)
    if tensorboard_dir is not None:
        check_writable_directory(tensorboard_dir, "--tensorboard")
    curves = tensorboard_dir or run_dir / TENSORBOARD_DIR
    remote = {PAIR_NAMESPACE.format(index) for index in remote_pair_indices(pairs, remote_pairs)}
    *graph, last = [path for path in run_nodes(foxglove, pairs) if split_node_path(path)[0] not in remote]
    domain, node, resumed = open_run(run_dir, options.settings(strategy, seed), namespace, (*graph, last),
                                     remote_pairs)
    record_code_version(run_dir)
    logs = run_dir / "logs"
    bag = new_bag_path(run_dir)
    env = isolated_environment(domain.domain_id, logs, keep_discovery_range=domain.from_environment)
    where = f", namespace {namespace}" if namespace else ""
    where += f", {pairs} sim/learner pairs" if pairs > 1 else ""
    print(f"{'resuming' if resumed else 'launching'} preset {options.preset}, strategy {strategy}, seed "
          f"{seed}{where} on {domain.describe()}; logs in {logs}", flush=True)
    print(f"training curves: {Path(sys.executable).parent / 'tensorboard'} --logdir {curves}",
          flush=True)

    progress = Progress()
    watchdog = Watchdog(watchdog_sec, startup_timeout)
    pairs_here = pair_namespaces(pairs)
    listen_for_progress(node, progress, watchdog, pairs_here)
    started: list[NodeProcess] = []
    plan = options.parameters(strategy, seed, run_dir, bag, foxglove, curves)
    params_file = preset_file(options.preset)

    def start(path: str) -> NodeProcess:
        process = NodeProcess(split_node_path(path)[1], logs, plan[path], params_file, env, name=path,
                              extra_args=namespace_arguments(node_namespace(namespace, path)))
        started.append(process)
        return process

    exit_code = EXIT_FAILED
    try:
        for path in graph:
            start(path)
        if foxglove is not None:
            layout = write_layout(run_dir / RUN_LAYOUT, namespace, pairs_here[0])
            print(f"Foxglove: open a connection to {foxglove.url} (layout: {layout})", flush=True)
        for index in remote_pair_indices(pairs, remote_pairs):
            print(f"waiting for pair {index}: on its host, with this run directory at the same path, "
                  f"ROS_DOMAIN_ID={domain.domain_id} {pair_command(run_dir, index, namespace)}", flush=True)
        wait_for_recorder(node, started, startup_timeout + (REMOTE_PAIR_WAIT_SEC if remote_pairs else 0), pairs_here)
        curriculum = start(last)
        watchdog.started = time.monotonic()
        exit_code = follow_curriculum(node, watchdog, progress, started, curriculum, pairs_here)
    except KeyboardInterrupt:
        progress.close()
        print("interrupted: stopping the graph; the same command resumes the run")
        exit_code = EXIT_INTERRUPTED
    except GraphStalled as stalled:
        progress.close()
        print(f"the run is stuck: {stalled}\nstopping the graph; the same command resumes the run", flush=True)
        exit_code = EXIT_STALLED
    finally:
        node_failure = stop_graph(started)  # always: every node gets its SIGINT
        exit_code = exit_code or node_failure
        node.destroy_node()
        rclpy.try_shutdown()
        domain.close()
    print_bag_summary(bag)
    if report:
        write_run_report([run_dir], run_dir / "report")
    return exit_code


def open_run(run_dir: Path, settings: dict[str, object], namespace: str, planned: Sequence[str],
             remote_pairs: int = 0) -> tuple[Domain, Node, bool]:
    """The run's domain (``choose_domain_id``), the launcher's node on it, and whether the run resumes, once
    ``run_dir`` is claimed for ``settings``. ``ValueError``, with nothing claimed or left open, for remote
    pairs without the user's ROS_DOMAIN_ID, a node of ``planned`` (``node_path``s) that another graph on the
    user's domain already runs, or a directory of another run."""
    domain = choose_domain_id()
    node = None
    try:
        if remote_pairs and not domain.from_environment:
            raise ValueError(f"--remote-pairs {remote_pairs}: set ROS_DOMAIN_ID (the same on every host) and a "
                             f"discovery that reaches them (ROS_AUTOMATIC_DISCOVERY_RANGE=SUBNET or a Fast DDS "
                             f"discovery server)")
        node = launcher_node(domain.domain_id, namespace)
        if domain.from_environment:  # a free domain has no other graph
            check_names_free(node, [full_node_name(namespace, path) for path in planned])
        return domain, node, claim_run_dir(run_dir, settings)
    except ValueError:
        if node is not None:
            node.destroy_node()
            rclpy.try_shutdown()
        domain.close()
        raise


def pair_command(run_dir: Path, index: int, namespace: str = "") -> str:
    """The command that starts pair ``index`` of the run in ``run_dir`` on another host (``serve_pair``)."""
    return f"glocal-ros pair --out {run_dir} --index {index}" + (f" --namespace {namespace}" if namespace else "")


def full_node_name(namespace: str, path: str) -> str:
    """The fully qualified name of the plan's node ``path`` in a run under ``namespace``: ``/robot1/pair1/sim_node``."""
    return f"{node_namespace(namespace, path).rstrip('/')}/{split_node_path(path)[1]}"


def check_names_free(node, planned: Sequence[str], discovery_sec: float = DISCOVERY_SEC) -> None:
    """``ValueError`` when a node of ``planned`` (fully qualified names) already runs on the domain: another
    graph in the same namespace, whose topics and services this run's would meet. Waits ``discovery_sec``
    for the domain's nodes to show first."""
    deadline = time.monotonic() + discovery_sec
    while time.monotonic() < deadline:
        rclpy.spin_once(node, timeout_sec=0.1)
    running = {f"{space.rstrip('/')}/{name}" for name, space in node.get_node_names_and_namespaces()}
    taken = [name for name in planned if name in running]
    if taken:
        raise ValueError(f"{', '.join(taken)} already run(s) on this ROS_DOMAIN_ID: another graph uses these "
                         f"namespaces; give this run another --namespace (or ROS_DOMAIN_ID)")


def serve_pair(run_dir: Path, index: int, namespace: str = "") -> int:
    """``glocal-ros pair``: pair ``index`` of the run in ``run_dir`` (a ``launch --pairs K --remote-pairs R`` on
    another host), its sim and learner started here as that launch plans them, on the user's ROS_DOMAIN_ID,
    until Ctrl-C or one of them ends; 0 after Ctrl-C, else ``EXIT_FAILED``.

    ``run_dir`` is the launch's run directory, mounted here at the same path: its ``run.json`` says which run
    this is, and its ``policies/`` is the store every learner shares. ``namespace``: the launch's
    ``--namespace``. ``ValueError`` before anything starts for a directory that holds no run of several
    pairs, an index not among them, or no ROS_DOMAIN_ID.
    """
    settings = recorded_run_settings(run_dir)
    if settings is None:
        raise ValueError(f"{run_dir} holds no run: start `glocal-ros launch --pairs K --remote-pairs R --out "
                         f"{run_dir}` first, with this directory at the same path on both hosts")
    pairs = int(settings.get("pairs", 1))
    if not 0 <= index < pairs or pairs < 2:
        raise ValueError(f"{run_dir} holds a run of {pairs} pair(s): --index {index} is not one of its pairs "
                         f"(0 to {pairs - 1})")
    domain_id = domain_id_from_environment()
    if domain_id is None:
        raise ValueError("set ROS_DOMAIN_ID to the launch's (it prints it) and a discovery that reaches its host")
    options = RunOptions.from_settings(settings, normalize_namespace(namespace))
    plan = options.parameters(str(settings["strategy"]), int(settings["seed"]), run_dir, run_dir / "bag")
    namespace = options.namespace
    pair = PAIR_NAMESPACE.format(index)
    logs = run_dir / "logs"
    env = isolated_environment(domain_id, logs, keep_discovery_range=True)
    params_file = preset_file(options.preset)
    # Set, not inherited, as for the launcher (``launcher_node``): a background job inherits SIGINT ignored.
    signal.signal(signal.SIGINT, signal.default_int_handler)
    signal.signal(signal.SIGTERM, signal.default_int_handler)
    started: list[NodeProcess] = []
    exit_code = EXIT_FAILED
    try:
        for executable in PAIR_NODES:
            path = node_path(pair, executable)
            started.append(NodeProcess(executable, logs, plan[path], params_file, env, name=path,
                                       extra_args=namespace_arguments(node_namespace(namespace, path))))
        print(f"pair {index} of {run_dir} on ROS_DOMAIN_ID {domain_id}: {', '.join(p.name for p in started)}; "
              f"logs in {logs}; Ctrl-C stops it", flush=True)
        while all(process.running for process in started):
            time.sleep(0.5)
        ended = next(process for process in started if not process.running)
        print(f"{ended.name} ended: see {ended.log_path}", flush=True)
    except KeyboardInterrupt:
        exit_code = 0
    finally:
        stop_graph(started)
    return exit_code


def launcher_node(domain_id: int, namespace: str):
    """The launcher's own node, in the graph's namespace, with SIGINT and SIGTERM raising KeyboardInterrupt.

    SIGINT is the launcher's to handle (stop the graph in order). rclpy's handler would shut the
    context down first, and a spin_once in progress then raises ExternalShutdownException instead
    (seen under load); SIGTERM stops the graph as Ctrl-C does. Set, not inherited: a launcher started
    as a script's background job inherits SIGINT ignored (POSIX shells do that to async commands), and
    Python then leaves it so: Ctrl-C did nothing. In the namespace: the names it uses are relative
    (node_common.names), so the progress, the watchdog and the learner probe hear this graph's nodes
    and no other's.
    """
    configure_discovery()  # the launcher's own participant on loopback too
    rclpy.init(domain_id=domain_id, signal_handler_options=SignalHandlerOptions.NO)
    signal.signal(signal.SIGINT, signal.default_int_handler)
    signal.signal(signal.SIGTERM, signal.default_int_handler)
    return rclpy.create_node("glocal_ros_launch", namespace=namespace or None)


def listen_for_progress(node, progress: Progress, watchdog: Watchdog, pairs: Sequence[str] = ("",)) -> None:
    """What the progress bar shows and the watchdog hears: curriculum states, and each pair's training progress
    and episodes (``pairs``: their namespaces, ``processes.pair_namespaces``)."""
    def heard(what: str, handle=lambda message: None):
        return lambda message: (watchdog.heard(what), handle(message))

    node.create_subscription(CurriculumState, names.CURRICULUM_STATE, heard(CURRICULUM_HEARD, progress.on_state),
                             qos.LATCHED)

    def on_diagnostics(message: DiagnosticArray) -> None:
        for status in message.status:
            if status.name.endswith(f": {REPLAY_STATUS}"):
                watchdog.heard(REPLAY_HEARD)
                progress.on_replay(status.message)

    node.create_subscription(DiagnosticArray, names.DIAGNOSTICS, on_diagnostics, qos.EVENTS)
    for pair in pairs:
        source = f"{pair}: " if pair else ""
        node.create_subscription(
            TrainingProgress, pair_name(pair, names.TRAINING_PROGRESS),
            heard(f"{source}training progress", lambda message, pair=pair: progress.on_progress(message, pair)),
            qos.EVENTS)
        # Raw: the watchdog only needs to know that an episode came, not what it holds.
        node.create_subscription(EpisodeRecord, pair_name(pair, names.EPISODES), heard(f"{source}an episode"),
                                 qos.EPISODES, raw=True)


def wait_for_recorder(node, started: Sequence[NodeProcess], timeout: float, pairs: Sequence[str] = ("",),
                      spun_elsewhere: bool = False) -> None:
    """Until the recorder listens to every pair's episode stream, so that the bag holds every episode from seq 0.

    ``RuntimeError`` naming the node and its log when a started node ends, or after ``timeout`` seconds the
    streams that nothing publishes yet (a pair started elsewhere) or nothing records. ``spun_elsewhere``: an
    executor of its own spins ``node`` (``node_common.runner.spinning_node``), so this only waits.
    """
    deadline = time.monotonic() + timeout
    topics = [pair_name(pair, names.EPISODES) for pair in pairs]

    def waiting() -> list[str]:
        return [topic for topic in topics if node.count_subscribers(topic) < 1 or node.count_publishers(topic) < 1]

    while waiting():
        if spun_elsewhere:
            time.sleep(0.1)
        else:
            rclpy.spin_once(node, timeout_sec=0.1)
        failed = [p for p in started if not p.running]
        if failed:
            raise RuntimeError(f"{failed[0].name} did not start: see {failed[0].log_path}")
        if time.monotonic() > deadline:
            raise RuntimeError(f"after {timeout:.0f} s, no sim publishes or no recorder records "
                               f"{', '.join(waiting())}: see the logs in {started[0].log_path.parent}")


def follow_curriculum(node, watchdog: Watchdog, progress: Progress, started: Sequence[NodeProcess],
                      curriculum: NodeProcess, pairs: Sequence[str] = ("",)) -> int:
    """Show the run's progress until the curriculum node ends; its exit code. ``GraphStalled`` from the watchdog."""
    while curriculum.running:
        rclpy.spin_once(node, timeout_sec=0.2)
        check_graph(node, watchdog, progress, started, curriculum, pairs)
    for _ in range(5):  # the last state may still be on its way
        rclpy.spin_once(node, timeout_sec=0.1)
    progress.close()
    exit_code = curriculum.process.returncode
    if exit_code:
        print(f"curriculum_node ended with exit code {exit_code}: see {curriculum.log_path}")
    return exit_code


def stop_graph(started: Sequence[NodeProcess]) -> int:
    """SIGINT to every node, the last started first, so that the recorder closes the bag after the others.

    Returns the first non-zero exit code of a node other than the curriculum (whose own code the run
    already has), else 0; each such node is named with its log.
    """
    first_failure = 0
    for process in reversed(started):
        code = process.stop(signal.SIGINT)
        if code not in (0, None) and process.node != "curriculum_node":
            print(f"{process.name} exited with {code}: see {process.log_path}")
            first_failure = first_failure or code
    return first_failure


def print_bag_summary(bag: Path) -> None:
    """The bag's message count per topic, or how to recover it when the recorder did not close it."""
    if (bag / "metadata.yaml").is_file():
        counts = ", ".join(f"{topic} {count}" for topic, count in message_counts(bag).items() if count)
        print(f"bag: {bag} ({counts})")
    else:
        print(f"bag: {bag} was not closed (see the recorder's log); `glocal-ros bag repair {bag}` recovers it")


def write_run_report(run_dirs: Sequence[Path], out_dir: Path) -> None:
    from glocal_ros.analysis.report import write_report

    try:
        path = write_report(run_dirs, out_dir)
    except ValueError as error:
        print(f"no report: {error}")
        return
    print(f"report: {path}")

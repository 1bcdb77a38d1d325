"""``glocal-ros launch``: the whole graph as processes on an isolated ROS domain.

Starts recorder, sim and learner, waits until the recorder listens to the
episode stream, then starts the curriculum and follows its state until the
curriculum node ends. The other nodes are then stopped in reverse order with
SIGINT, so the bag is closed cleanly; Ctrl-C does the same at any time.
RUN_DIR gets ``bag/`` (a new ``bag.N/`` if one exists), ``policies/`` (the
learner's policy store) and ``logs/``.
"""

from __future__ import annotations

import signal
import time
from pathlib import Path

import rclpy
from glocal_interfaces.msg import CurriculumState

from glocal_ros.domain import reserve_domain_id
from glocal_ros.paths import assets_dir
from glocal_ros.processes import NodeProcess, isolated_environment
from glocal_ros.recording import message_counts
from node_common import names, qos

STATUS_NAMES = {value: name.removeprefix("STATUS_").lower() for name, value in vars(CurriculumState).items()
                if name.startswith("STATUS_")}


def preset_file(preset: str) -> Path:
    path = assets_dir() / "params" / f"{preset}.yaml"
    if not path.is_file():
        known = sorted(p.stem for p in path.parent.glob("*.yaml"))
        raise ValueError(f"unknown preset {preset!r}: expected one of {', '.join(known)}")
    return path


def new_bag_path(run_dir: Path) -> Path:
    bag = run_dir / "bag"
    index = 1
    while bag.exists():
        bag = run_dir / f"bag.{index}"
        index += 1
    return bag


def describe(state: CurriculumState) -> str:
    text = f"[{state.strategy}] iteration {state.iteration}, {STATUS_NAMES.get(state.status, state.status)}"
    if state.clusters:
        text += f", {len(state.clusters)} clusters, C1 = {','.join(state.clusters[0].tasks)}"
    if state.global_task:
        text += f", global task {state.global_task}, local tasks {','.join(state.local_tasks) or '-'}"
    return text + f", learned {len(state.learned_tasks)}/{len(state.learned_tasks) + len(state.remaining_tasks)}"


def launch(strategy: str, preset: str, seed: int, run_dir: Path, startup_timeout: float = 120.0) -> int:
    params_file = preset_file(preset)
    run_dir.mkdir(parents=True, exist_ok=True)
    logs = run_dir / "logs"
    bag = new_bag_path(run_dir)
    domain_id, domain_lock = reserve_domain_id()
    env = isolated_environment(domain_id, logs)
    print(f"launching preset {preset}, strategy {strategy}, seed {seed} on ROS_DOMAIN_ID {domain_id}; logs in {logs}")

    rclpy.init(domain_id=domain_id)
    node = rclpy.create_node("glocal_ros_launch")
    states: list[CurriculumState] = []
    node.create_subscription(CurriculumState, names.CURRICULUM_STATE, states.append, qos.LATCHED)
    started: list[NodeProcess] = []

    def start(name: str, **params) -> NodeProcess:
        process = NodeProcess(name, logs, params, params_file, env)
        started.append(process)
        return process

    exit_code = 1
    try:
        start("recorder_node", output=str(bag))
        start("sim_node")
        start("learner_node", seed=seed, policy_dir=str(run_dir / "policies"))
        deadline = time.monotonic() + startup_timeout
        while node.count_subscribers("/" + names.EPISODES) < 1 or node.count_publishers("/" + names.EPISODES) < 1:
            rclpy.spin_once(node, timeout_sec=0.1)
            failed = [p for p in started if not p.running]
            if failed or time.monotonic() > deadline:
                raise RuntimeError(f"{(failed or started)[0].node} did not start: see {(failed or started)[0].log_path}")
        curriculum = start("curriculum_node", strategy=strategy, seed=seed)
        shown = 0
        while curriculum.running:
            rclpy.spin_once(node, timeout_sec=0.2)
            for state in states[shown:]:
                print(describe(state), flush=True)
            shown = len(states)
        exit_code = curriculum.process.returncode
        print(f"curriculum_node ended with exit code {exit_code}")
    except KeyboardInterrupt:
        print("interrupted: stopping the graph")
    finally:
        for process in reversed(started):
            code = process.stop(signal.SIGINT)
            if code not in (0, None) and process.node != "curriculum_node":
                print(f"{process.node} exited with {code}: see {process.log_path}")
                exit_code = exit_code or code
        node.destroy_node()
        rclpy.try_shutdown()
        domain_lock.close()
    if (bag / "metadata.yaml").is_file():
        counts = ", ".join(f"{topic} {count}" for topic, count in message_counts(bag).items() if count)
        print(f"bag: {bag} ({counts})")
    else:
        print(f"bag: {bag} was not closed (see the recorder's log)")
    return exit_code

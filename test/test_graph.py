"""The whole graph as processes: curriculum -> learner -> sim and back, recorded."""

import os
import shutil
import signal
import subprocess
from pathlib import Path

import pytest
from glocal_interfaces.msg import CurriculumState, EpisodeRecord, TaskAssignment
from rosbags.highlevel import AnyReader

from conftest import REPO, wait_until
from glocal_app.processes import NodeProcess
from glocal_ros.recording import graph_typestore
from node_common import names, qos
from node_common.runner import PROFILES_FILE_VARIABLE

TASKS = ["A0", "B2", "D4", "G6"]
EVAL_EPISODES = 2


def test_curriculum_decision_travels_through_learner_and_sim(start_node, ros_node, tmp_path):
    states, assignments, episodes = [], [], []
    ros_node.create_subscription(CurriculumState, names.CURRICULUM_STATE, states.append, qos.LATCHED)
    ros_node.create_subscription(TaskAssignment, names.TASK_ASSIGNMENT, assignments.append, qos.LATCHED)
    ros_node.create_subscription(EpisodeRecord, names.EPISODES, episodes.append, qos.EPISODES)
    bag = tmp_path / "bag"
    recorder = start_node("recorder_node", output=str(bag))
    sim = start_node("sim_node", num_envs=2, max_steps=10)
    learner = start_node("learner_node")
    wait_until(lambda: ros_node.count_publishers("/" + names.EPISODES) and "/learner/evaluate" in dict(
        ros_node.get_service_names_and_types()), 60, "sim and learner", processes=[recorder, sim, learner])
    curriculum = start_node("curriculum_node", tasks=",".join(TASKS), eval_episodes=EVAL_EPISODES, seed=3,
                            threshold=1.0, step_budget=60, task_step_budget=30, eval_interval=20,
                            max_episode_steps=10, state_dir=str(tmp_path / "curriculum"))
    processes = [recorder, sim, learner, curriculum]

    # The node ends with the run: here when its 60 training steps are spent.
    assert curriculum.process.wait(180) == 0, curriculum.log()
    wait_until(lambda: states and states[-1].status == CurriculumState.STATUS_FINISHED, 10,
               "the end of the run", processes=processes[:-1])
    assert 60 <= states[-1].total_steps < 62 and states[-1].step_budget == 60
    state = next(s for s in states if s.status == CurriculumState.STATUS_TRAINING_GLOBAL)
    assert state.strategy == "glocal" and state.iteration == 1 and state.run_id == "glocal-seed3"
    assert sorted(t for c in state.clusters for t in c.tasks) == sorted(TASKS)
    assert all(0 <= s <= EVAL_EPISODES for c in state.clusters for s in c.scores)
    best = state.clusters[0]
    assert state.global_task == best.tasks[len(best.tasks) // 2]
    assert sorted([state.global_task, *state.local_tasks]) == sorted(best.tasks)
    wait_until(lambda: assignments, 60, "the global task's assignment", processes=processes[:-1])
    assert (assignments[0].role, assignments[0].task) == (TaskAssignment.ROLE_GLOBAL, state.global_task)
    assert (assignments[0].initial_policy, assignments[0].output_policy) == ("prior", "glocal-seed3.G1")
    assert all(a.role == TaskAssignment.ROLE_LOCAL for a in assignments[1:])

    # The evaluation ran in the sim: at least S-bar finished eval episodes per task; then training.
    finished = [e for e in episodes if e.phase == EpisodeRecord.PHASE_EVAL and not e.interrupted]
    for task in TASKS:
        assert sum(e.task == task for e in finished) >= EVAL_EPISODES
    trained = [e for e in episodes if e.phase == EpisodeRecord.PHASE_TRAIN and e.policy_name == "glocal-seed3.G1"]
    assert trained and {e.task for e in trained} == {state.global_task}
    assert [e.seq for e in episodes] == list(range(len(episodes)))

    # Every node shuts down cleanly on SIGTERM, and the recorder leaves a readable bag.
    for process in reversed(processes):
        assert process.stop(signal.SIGTERM) == 0, process.log()
    with AnyReader([bag], default_typestore=graph_typestore()) as reader:
        by_topic = {}
        for connection, _, raw in reader.messages():
            by_topic.setdefault(connection.topic, []).append(reader.deserialize(raw, connection.msgtype))
    assert [e.seq for e in by_topic["/glocal/episodes"]] == [e.seq for e in episodes]
    assert by_topic["/glocal/curriculum_state"][-1].status == CurriculumState.STATUS_FINISHED
    assert by_topic["/glocal/evaluations"][0].policy == "prior"


def udp_sockets(pid: int) -> list[tuple[str, int]]:
    """(address, port) of every UDP socket the process holds, from ``ss``."""
    lines = subprocess.run(["ss", "-uanpH"], capture_output=True, text=True, check=True).stdout.splitlines()
    sockets = []
    for line in lines:
        if f"pid={pid}," in line:
            address, _, port = line.split()[3].rpartition(":")
            sockets.append((address.strip("[]"), int(port)))
    return sockets


def ephemeral_ports() -> range:
    low, high = map(int, Path("/proc/sys/net/ipv4/ip_local_port_range").read_text().split())
    return range(low, high + 1)


def rtps_unicast_ports(domain_id: int) -> range:
    """The RTPS well-known unicast ports of a domain (port base 7400, domain gain 250; +10, +11 per participant)."""
    first = 7400 + 250 * domain_id + 10
    return range(first, first + 250 - 10)


def without_profile() -> dict[str, str]:
    """This environment without the loopback profile the suite loads (see conftest)."""
    return {key: value for key, value in os.environ.items() if key != PROFILES_FILE_VARIABLE}


@pytest.mark.skipif(shutil.which("ss") is None, reason="needs ss (iproute2)")
def test_nodes_listen_on_loopback_unless_the_user_opts_in(tmp_path):
    """Before, discovery was LOCALHOST but Fast DDS bound its ports to 0.0.0.0 and the host's address."""
    domain_id = int(os.environ["ROS_DOMAIN_ID"])
    ours = NodeProcess("recorder_node", tmp_path, {"output": str(tmp_path / "bag")}, cwd=REPO)
    subnet = NodeProcess("recorder_node", tmp_path, {"output": str(tmp_path / "bag-subnet")}, cwd=REPO,
                         env={**without_profile(), "ROS_AUTOMATIC_DISCOVERY_RANGE": "SUBNET"})
    try:
        for process in (ours, subnet):
            wait_until(lambda: "recording" in process.log(), 60, "the recorder to start", processes=[process])

        def well_known(process: NodeProcess) -> list[tuple[str, int]]:
            return [s for s in udp_sockets(process.process.pid) if s[1] in rtps_unicast_ports(domain_id)]

        wait_until(lambda: len(well_known(ours)) >= 2 and len(well_known(subnet)) >= 2, 60,
                   "the nodes' discovery and data ports", processes=[ours, subnet])
        sockets = udp_sockets(ours.process.pid)
        # Every port a peer could be told about (discovery, data, anything not ephemeral) is on loopback.
        # rmw_fastrtps's LOCALHOST mode adds a send-only UDP transport of its own: its output sockets
        # have ephemeral ports on the wildcard and host addresses, and nothing reads them.
        assert all(address == "127.0.0.1" for address, port in sockets if port not in ephemeral_ports()), sockets
        assert all(address == "127.0.0.1" for address, _ in well_known(ours)), sockets
        # The documented opt-in (SUBNET) drops the loopback profile: reachable from other hosts.
        assert any(address == "0.0.0.0" for address, _ in well_known(subnet)), udp_sockets(subnet.process.pid)
    finally:
        assert ours.stop() == 0 and subnet.stop() == 0

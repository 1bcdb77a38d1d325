"""The whole graph as processes: curriculum -> learner -> sim and back, recorded."""

import signal

from glocal_interfaces.msg import CurriculumState, EpisodeRecord, TaskAssignment
from rosbags.highlevel import AnyReader

from conftest import wait_until
from glocal_ros.recording import graph_typestore
from node_common import names, qos

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
    curriculum = start_node("curriculum_node", tasks=",".join(TASKS), eval_episodes=EVAL_EPISODES, seed=3)
    processes = [recorder, sim, learner, curriculum]

    # The node ends once its decision is out (training arrives with issue "Curriculum").
    assert curriculum.process.wait(90) == 0, curriculum.log()
    wait_until(lambda: states and states[-1].status == CurriculumState.STATUS_TRAINING_GLOBAL, 10,
               "the first GloCAL decision", processes=processes[:-1])
    state = states[-1]
    assert state.strategy == "glocal" and state.iteration == 1
    assert sorted(t for c in state.clusters for t in c.tasks) == sorted(TASKS)
    assert all(0 <= s <= EVAL_EPISODES for c in state.clusters for s in c.scores)
    best = state.clusters[0]
    assert state.global_task == best.tasks[len(best.tasks) // 2]
    assert sorted([state.global_task, *state.local_tasks]) == sorted(best.tasks)
    wait_until(lambda: assignments, 10, "the global task's assignment", processes=processes[:-1])
    assert (assignments[-1].role, assignments[-1].task) == (TaskAssignment.ROLE_GLOBAL, state.global_task)
    assert assignments[-1].initial_policy == "prior"

    # The evaluation ran in the sim: at least S-bar finished eval episodes per task.
    finished = [e for e in episodes if e.phase == EpisodeRecord.PHASE_EVAL and not e.interrupted]
    for task in TASKS:
        assert sum(e.task == task for e in finished) >= EVAL_EPISODES
    assert [e.seq for e in episodes] == list(range(len(episodes)))

    # Every node shuts down cleanly on SIGTERM, and the recorder leaves a readable bag.
    for process in reversed(processes):
        assert process.stop(signal.SIGTERM) == 0, process.log()
    with AnyReader([bag], default_typestore=graph_typestore()) as reader:
        by_topic = {}
        for connection, _, raw in reader.messages():
            by_topic.setdefault(connection.topic, []).append(reader.deserialize(raw, connection.msgtype))
    assert [e.seq for e in by_topic["/glocal/episodes"]] == [e.seq for e in episodes]
    assert by_topic["/glocal/curriculum_state"][-1].global_task == state.global_task
    assert by_topic["/glocal/evaluations"][0].policy == "prior"

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

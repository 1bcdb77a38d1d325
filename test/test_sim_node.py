"""sim_node as a process: the batched services, the episode stream, bad input."""

import math

import numpy as np
import pytest
from glocal_interfaces.msg import EpisodeRecord
from glocal_interfaces.srv import ResetEnvs, StepEnvs
from sensor_msgs.msg import JointState

from conftest import wait_until
from node_common import names, qos
from node_common.arrays import from_float32_field, to_float32_field
from node_common.calls import call

T = 5
NUM_ENVS = 2


@pytest.fixture
def sim(start_node, ros_node):
    process = start_node("sim_node", num_envs=NUM_ENVS, max_steps=T, viewer_rate_hz=20.0)
    reset = ros_node.create_client(ResetEnvs, names.SIM_RESET)
    step = ros_node.create_client(StepEnvs, names.SIM_STEP)
    wait_until(lambda: reset.service_is_ready() and step.service_is_ready(), 60, "sim services", processes=[process])
    return process, reset, step


def step_request(actions, **fields):
    return StepEnvs.Request(actions=to_float32_field(np.asarray(actions, dtype=np.float32)), **fields)


def test_lockstep_batch_and_episode_stream(sim, ros_node):
    process, reset, step = sim
    episodes = []
    ros_node.create_subscription(EpisodeRecord, names.EPISODES, episodes.append, qos.EPISODES)
    joint_states = []
    ros_node.create_subscription(JointState, names.JOINT_STATES, joint_states.append, qos.VIEWER)

    response = call(reset, ResetEnvs.Request(tasks=["A0", "B1"], seeds=[11], phase=EpisodeRecord.PHASE_TRAIN,
                                             policy_name="zeros"))
    assert response.success and (response.num_envs, response.obs_dim, response.action_dim) == (NUM_ENVS, 63, 5)
    first = from_float32_field(response.observations, NUM_ENVS)

    for k in range(3 * T):
        response = call(step, step_request(np.zeros((NUM_ENVS, 5)), phase=EpisodeRecord.PHASE_TRAIN,
                                           policy_name="zeros", global_step=k, next_tasks=["C2", ""]))
        assert response.success, response.message
        assert list(response.rewards) == [-1.0] * NUM_ENVS
        assert list(response.truncated) == [(k + 1) % T == 0] * NUM_ENVS
    assert response.tasks == ["C2", "B1"]

    wait_until(lambda: len(episodes) >= 3 * NUM_ENVS, 60, "6 episode records", processes=[process])
    assert [e.seq for e in episodes] == list(range(len(episodes)))
    record = episodes[0]
    assert (record.task, record.phase, record.policy_name, record.length) == ("A0", 0, "zeros", T)
    observations = np.asarray(record.observations, dtype=np.float32).reshape(T + 1, 63)
    np.testing.assert_array_equal(observations[0], first[record.env_index])
    assert len(record.actions) == T * 5 and len(record.rewards) == T
    assert len(record.joint_positions) == (T + 1) * len(record.joint_names) == (T + 1) * 9
    assert record.truncated and not record.success and not record.interrupted
    wait_until(lambda: joint_states, 60, "joint states for viewers", processes=[process])


def test_evaluation_has_envs_of_its_own_and_a_step_moves_only_the_envs_named(sim, ros_node):
    """Phase eval addresses DEFAULT_EVAL_ENVS envs, numbered after the training envs in the records; a step
    that names envs 9 and 3 answers their rows in that order, and only they run episodes."""
    from glocal_ros.sim_contract import DEFAULT_EVAL_ENVS

    process, reset, step = sim
    episodes = []
    ros_node.create_subscription(EpisodeRecord, names.EPISODES, episodes.append, qos.EPISODES)
    response = call(reset, ResetEnvs.Request(tasks=["A0"], seeds=[3], phase=EpisodeRecord.PHASE_EVAL), 120)
    assert response.success, response.message
    assert response.num_envs == DEFAULT_EVAL_ENVS
    for k in range(T):
        response = call(step, step_request(np.zeros((2, 5)), env_indices=[9, 3], next_tasks=["", "D4"],
                                           phase=EpisodeRecord.PHASE_EVAL))
        assert response.success, response.message
        assert len(response.rewards) == 2 and len(response.observations) == 2 * 63
    assert list(response.tasks) == ["A0", "D4"]
    wait_until(lambda: len(episodes) >= 2, 60, "the two evaluation episodes", processes=[process])
    assert sorted(e.env_index for e in episodes if e.phase == EpisodeRecord.PHASE_EVAL) == [NUM_ENVS + 3,
                                                                                             NUM_ENVS + 9]
    training = call(reset, ResetEnvs.Request(phase=EpisodeRecord.PHASE_TRAIN))
    assert training.success and training.num_envs == NUM_ENVS


@pytest.mark.parametrize("request_fields, message", [
    ({"actions": np.zeros(NUM_ENVS * 5 - 1)}, "expected 10 action values"),
    ({"actions": np.full(NUM_ENVS * 5, math.nan)}, "NaN or inf"),
    ({"actions": np.full(NUM_ENVS * 5, 3.0)}, "[-1, 1]"),
    ({"actions": np.zeros(NUM_ENVS * 5), "next_tasks": ["A0", "X7"]}, "unknown task 'X7'"),
    ({"actions": np.zeros(NUM_ENVS * 5), "phase": 9}, "phase"),
])
def test_bad_step_is_answered_and_the_node_keeps_serving(sim, request_fields, message):
    process, reset, step = sim
    actions = request_fields.pop("actions")
    response = call(step, step_request(actions, **request_fields))
    assert not response.success and message in response.message
    assert call(step, step_request(np.zeros((NUM_ENVS, 5)))).success
    assert process.process.poll() is None


def test_bad_reset_is_answered_and_the_node_keeps_serving(sim):
    process, reset, step = sim
    for request, message in [
        (ResetEnvs.Request(tasks=["G7"]), "unknown task 'G7'"),
        (ResetEnvs.Request(env_indices=[5]), "out of range"),
        (ResetEnvs.Request(tasks=["A0", "A1", "A2"]), "one per reset env"),
    ]:
        response = call(reset, request)
        assert not response.success and message in response.message
    assert call(reset, ResetEnvs.Request()).success
    assert process.process.poll() is None

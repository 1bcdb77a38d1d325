"""learner_node against a real sim_node: the Evaluate service and bad requests.

One sim/learner pair serves the module's tests, as it serves a run: a test's
bad request must leave it serving the next test's good ones.
"""

import pytest
from glocal_interfaces.msg import EvaluationResult
from glocal_interfaces.srv import CopyPolicy, Evaluate, ListPolicies

from conftest import answers, node_starter, spun_test_node, store_pickled_policy, wait_until
from node_common import names, qos
from node_common.calls import call


@pytest.fixture(scope="module")
def ros_node():
    with spun_test_node() as node:
        yield node


@pytest.fixture(scope="module")
def policy_dir(tmp_path_factory):
    """A policy store holding one (untrained) SAC policy, 'untrained', and one of the pickled format before."""
    tmp_path = tmp_path_factory.mktemp("learner")
    from learner_node.policy_store import PolicyRecord, PolicyStore
    from learner_node.sac_settings import DEFAULT_NETWORK, network
    from sim_node.grasp_env import GraspEnv

    env = GraspEnv("A0")
    model = network(DEFAULT_NETWORK).new_model(env, 0, buffer_size=100)
    PolicyStore(tmp_path / "policies").save(model, PolicyRecord(name="untrained", task="A0"))
    store_pickled_policy(tmp_path / "policies", "pickled", model, task="A0")
    env.close()
    return tmp_path / "policies"


@pytest.fixture(scope="module")
def learner(ros_node, policy_dir):
    with node_starter(policy_dir.parent) as start_node:
        sim = start_node("sim_node", num_envs=2, max_steps=10)
        learner = start_node("learner_node", max_eval_episodes=50, policy_dir=str(policy_dir))
        evaluate = ros_node.create_client(Evaluate, names.LEARNER_EVALUATE)
        probe = Evaluate.Request(policy="random", tasks=["A0"], episodes=1)
        wait_until(lambda: answers(evaluate, probe), 60, "an answer from learner/evaluate", processes=[sim, learner])
        yield learner, evaluate


def test_evaluate_scores_every_task(learner, ros_node):
    process, evaluate = learner
    evaluations = []
    ros_node.create_subscription(EvaluationResult, names.EVALUATIONS, evaluations.append, qos.EVENTS)
    response = call(evaluate, Evaluate.Request(policy="random", tasks=["A0", "D3", "G6"], episodes=3, seed=4))
    assert response.success, response.message
    assert [(s.task, s.episodes) for s in response.scores] == [("A0", 3), ("D3", 3), ("G6", 3)]
    assert all(0 <= s.successes <= 3 for s in response.scores)
    wait_until(lambda: evaluations, 60, "the evaluation on glocal/evaluations", processes=[process])
    assert evaluations[0].policy == "random" and evaluations[0].purpose == "request"

    policies = call(ros_node.create_client(ListPolicies, names.LEARNER_LIST_POLICIES), ListPolicies.Request())
    assert {"random", "untrained"} <= {p.name for p in policies.policies}


def test_evaluate_a_stored_policy_records_its_score(learner, ros_node, policy_dir):
    process, evaluate = learner
    response = call(evaluate, Evaluate.Request(policy="untrained", tasks=["B1"], episodes=2, seed=0))
    assert response.success, response.message
    assert (response.scores[0].task, response.scores[0].episodes) == ("B1", 2)
    listed = call(ros_node.create_client(ListPolicies, names.LEARNER_LIST_POLICIES), ListPolicies.Request())
    untrained = next(p for p in listed.policies if p.name == "untrained")
    assert (untrained.task, untrained.last_score_task) == ("A0", "B1")
    assert untrained.last_score == response.scores[0].successes and untrained.updated.sec > 0


@pytest.mark.parametrize("request_fields, message", [
    ({"policy": "no_such_policy", "tasks": ["A0"]}, "unknown policy 'no_such_policy'"),
    ({"policy": "../etc", "tasks": ["A0"]}, "invalid policy name"),
    ({"policy": "random", "tasks": ["A0", "K2"]}, "unknown task 'K2'"),
    ({"policy": "random", "tasks": []}, "no task"),
    ({"policy": "random", "tasks": ["A0", "A0"]}, "repeat"),
    ({"policy": "random", "tasks": ["A0"], "episodes": 51}, "max_eval_episodes"),
    ({"policy": "pickled", "tasks": ["A0"]}, "is a stable-baselines3 zip, whose loading unpickles"),
])
def test_bad_evaluate_is_answered_and_the_node_keeps_serving(learner, request_fields, message):
    process, evaluate = learner
    response = call(evaluate, Evaluate.Request(**{"seed": -1, "episodes": 2, **request_fields}))
    assert not response.success and message in response.message
    assert call(evaluate, Evaluate.Request(policy="random", tasks=["A0"], episodes=1, seed=-1)).success
    assert process.process.poll() is None


def test_copy_policy_into_the_store(learner, ros_node, policy_dir):
    process, evaluate = learner
    copy = ros_node.create_client(CopyPolicy, names.LEARNER_COPY_POLICY)
    response = call(copy, CopyPolicy.Request(source="prior", destination="A0_learned"))
    assert response.success and response.error == CopyPolicy.Response.ERROR_NONE
    assert (policy_dir / "A0_learned" / "policy.json").is_file()
    exists, refused = CopyPolicy.Response.ERROR_EXISTS, CopyPolicy.Response.ERROR_REFUSED
    for source, destination, message, kind in [("prior", "A0_learned", "exists already", exists),
                                               ("nope", "x", "unknown policy 'nope'", refused),
                                               ("random", "r2", "built in", refused),
                                               ("prior", "../x", "invalid policy name", refused)]:
        response = call(copy, CopyPolicy.Request(source=source, destination=destination))
        assert not response.success and message in response.message
        assert response.error == kind, (source, destination, response.error)
    response = call(evaluate, Evaluate.Request(policy="A0_learned", tasks=["A0"], episodes=2, seed=1))
    assert response.success and process.process.poll() is None


@pytest.mark.parametrize("params, message", [
    (dict(fine_tuning="rlpd"), "parameter fine_tuning: unknown fine-tuning recipe 'rlpd': choose from random-first, "
                               "policy-first"),
    (dict(learner_profile="sb2"), "parameter learner_profile: unknown learner profile 'sb2': choose from "
                                  "glocal_ros, paper"),
    (dict(learner_profile="paper", fine_tuning="parent-experience"),
     "parameter fine_tuning: fine-tuning recipe 'parent-experience' contradicts learner profile 'paper'"),
])
def test_a_bad_profile_or_recipe_stops_the_node_naming_the_parameter_and_the_choices(start_node, tmp_path, params,
                                                                                     message):
    node = start_node("learner_node", policy_dir=str(tmp_path / "policies"), **params)
    assert node.process.wait(120) == 1
    assert message in node.log()

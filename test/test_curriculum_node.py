"""curriculum_node with the real learner and sim on the smoke preset: every strategy end to end, and resuming.

The smoke budgets are far too small to learn; these tests check that each
strategy drives the graph to the end of its budget, publishes its state and
assignments, and refuses what it cannot run. Resuming a killed run: test_resume.py.
"""

import json

import pytest
from glocal_interfaces.msg import CurriculumState, TaskAssignment

from conftest import REPO, SMOKE, smoke_tasks, wait_until
from glocal_app.processes import NodeProcess
from node_common import names, qos

STRATEGIES = ["glocal", "random", "alp_gmm_250", "alp_gmm_10", "glocal_no_global", "glocal_random_cluster"]


@pytest.fixture(scope="module")
def graph(tmp_path_factory):
    """One sim and one learner for the module; each test runs its own curriculum node."""
    logs = tmp_path_factory.mktemp("graph")
    sim = NodeProcess("sim_node", logs, params_file=SMOKE, cwd=REPO)
    learner = NodeProcess("learner_node", logs, {"policy_dir": str(logs / "policies")}, params_file=SMOKE, cwd=REPO)
    yield [sim, learner]
    for process in (learner, sim):
        process.stop()


def curriculum(tmp_path, strategy, **params) -> NodeProcess:
    params = {"strategy": strategy, "state_dir": str(tmp_path / "state"), "learner_timeout_sec": 120.0, **params}
    return NodeProcess("curriculum_node", tmp_path, params, params_file=SMOKE, cwd=REPO)


@pytest.mark.parametrize("strategy", STRATEGIES)
def test_every_strategy_runs_to_the_end_of_its_budget(graph, ros_node, tmp_path, strategy):
    states, assignments = [], []
    ros_node.create_subscription(CurriculumState, names.CURRICULUM_STATE, states.append, qos.LATCHED)
    ros_node.create_subscription(TaskAssignment, names.TASK_ASSIGNMENT, assignments.append, qos.LATCHED)
    node = curriculum(tmp_path, strategy)
    wait_until(lambda: node.process.poll() is not None, 240, f"the {strategy} run", processes=graph)
    assert node.process.returncode == 0, node.log()

    wait_until(lambda: states and states[-1].status == CurriculumState.STATUS_FINISHED, 120,
               f"the final state; the curriculum node's log:\n{node.log()}")
    final = states[-1]
    assert (final.strategy, final.run_id) == (strategy, f"{strategy}-seed0")
    assert final.step_budget == 300 and final.total_steps <= 300, "no goal trains past its budget"
    assert sorted(final.learned_tasks + final.remaining_tasks) == smoke_tasks()
    assert list(final.milestone_steps) == [100, 200, 300], "a finished run stands at every milestone"
    assert final.evaluation_episodes > 0, "evaluations are counted, beside the training steps"
    assert assignments and all(a.output_policy.startswith(f"{strategy}-seed0.") for a in assignments)
    roles = {a.role for a in assignments}
    expected = {"glocal": {TaskAssignment.ROLE_GLOBAL}, "glocal_random_cluster": {TaskAssignment.ROLE_GLOBAL},
                "glocal_no_global": {TaskAssignment.ROLE_CLUSTER}}.get(strategy, {TaskAssignment.ROLE_SAMPLED})
    assert expected <= roles
    saved = json.loads((tmp_path / "state" / "state.json").read_text())
    assert saved["total_steps"] == final.total_steps and saved["status"] == CurriculumState.STATUS_FINISHED


def test_a_journal_of_other_settings_ends_the_node_with_a_clear_error(graph, tmp_path):
    (tmp_path / "state").mkdir()
    (tmp_path / "state" / "journal.jsonl").write_text(json.dumps({"config": {"strategy": "random"}}) + "\n")
    node = curriculum(tmp_path, "glocal")
    assert node.process.wait(60) == 1
    assert "belongs to a run with other settings" in node.log()


@pytest.mark.parametrize("params, message", [
    ({"strategy": "greedy"}, "unknown strategy 'greedy'"),
    ({"strategy": "random", "baseline_tasks": "most"}, "baseline_tasks 'most': expected one of all, unlearned"),
])
def test_unknown_settings_are_refused(graph, tmp_path, params, message):
    node = curriculum(tmp_path, **params)
    assert node.process.wait(60) == 1
    assert message in node.log()


def test_learner_namespaces_are_a_list_of_distinct_namespaces():
    from curriculum_node.curriculum_node import learner_namespace_list

    assert learner_namespace_list("") == [""], "the default: the node's own names"
    assert learner_namespace_list("/,pair1, /pair2/") == ["/", "/pair1", "/pair2"]
    # Relative names resolve under the node's namespace, as ROS resolves every name.
    assert learner_namespace_list("pair0,pair1", "/robot1") == ["/robot1/pair0", "/robot1/pair1"]
    assert learner_namespace_list(",pair1", "/robot1") == ["/robot1", "/robot1/pair1"]
    assert learner_namespace_list("/,/pair2", "/robot1") == ["/", "/pair2"]
    with pytest.raises(ValueError, match="repeat"):
        learner_namespace_list("pair0,/pair0")

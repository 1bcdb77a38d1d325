"""The learner's Train action against a real sim_node: train, evaluate meanwhile, cancel, restart, bad goals.

Goals start from the shipped A0 prior and use small budgets: the point is the
action's behaviour, not learning (that is `glocal-ros bench learner`).
"""

import json
import signal
import threading
import time

import pytest
from action_msgs.msg import GoalStatus
from glocal_interfaces.action import Train
from glocal_interfaces.msg import TrainingProgress
from glocal_interfaces.srv import Evaluate, ListPolicies
from rclpy.action import ActionClient

from conftest import answers, wait_until
from node_common import names, qos
from node_common.calls import call


class Goal:
    """A sent goal: its handle, feedback and, later, its result."""

    def __init__(self, client: ActionClient, goal: Train.Goal, timeout: float = 30.0):
        self.feedback: list[Train.Feedback] = []
        accepted = threading.Event()
        future = client.send_goal_async(goal, feedback_callback=lambda message: self.feedback.append(message.feedback))
        future.add_done_callback(lambda _: accepted.set())
        assert accepted.wait(timeout), "the goal was neither accepted nor rejected"
        self.handle = future.result()
        self._result = None
        self._done = threading.Event()
        if self.handle.accepted:
            self.handle.get_result_async().add_done_callback(self._finish)

    def _finish(self, future) -> None:
        self._result = future.result()
        self._done.set()

    @property
    def done(self) -> bool:
        return self._done.is_set()

    def result(self, timeout: float, processes=()) -> tuple[int, Train.Result]:
        wait_until(self._done.is_set, timeout, "the Train result", processes=processes)
        return self._result.status, self._result.result


def train_goal(**fields) -> Train.Goal:
    defaults = dict(task="A0", initial_policy="prior", output_policy="trained", step_budget=40, eval_episodes=2)
    return Train.Goal(**{**defaults, **fields})


@pytest.fixture
def graph(start_node, ros_node, tmp_path):
    """sim_node (2 envs, T = 10) and learner_node, plus the test's clients."""
    policy_dir = tmp_path / "policies"
    sim = start_node("sim_node", num_envs=2, max_steps=10)

    def start_learner(checkpoint_interval: int = 40):
        learner = start_node("learner_node", max_eval_episodes=50, policy_dir=str(policy_dir),
                             checkpoint_interval=checkpoint_interval)
        wait_until(train.server_is_ready, 60, "learner/train", processes=[sim, learner])
        # After a restart the killed learner's endpoints linger in discovery:
        # an answered request proves that this one is matched.
        probe = Evaluate.Request(policy="random", tasks=["A0"], episodes=1)
        wait_until(lambda: answers(evaluate, probe), 60, "an answer from the new learner", processes=[sim, learner])
        return learner

    train = ActionClient(ros_node, Train, names.LEARNER_TRAIN)
    evaluate = ros_node.create_client(Evaluate, names.LEARNER_EVALUATE)
    learner = start_learner()
    return dict(sim=sim, learner=learner, start_learner=start_learner, train=train, evaluate=evaluate,
                policy_dir=policy_dir)


def stored_policies(ros_node) -> dict:
    listed = call(ros_node.create_client(ListPolicies, names.LEARNER_LIST_POLICIES), ListPolicies.Request())
    return {p.name: p for p in listed.policies}


def test_train_stores_the_policy_with_its_score(graph, ros_node):
    progress = []
    ros_node.create_subscription(TrainingProgress, names.TRAINING_PROGRESS, progress.append, qos.EVENTS)
    goal = Goal(graph["train"], train_goal(step_budget=60, eval_interval=30))
    status, result = goal.result(120, processes=[graph["learner"]])

    assert status == GoalStatus.STATUS_SUCCEEDED, result.message
    assert 60 <= result.steps_used < 62  # 2 envs step together
    assert (result.score.task, result.score.episodes) == ("A0", 2)
    assert result.learned == (result.score.successes > 75)
    assert result.episodes and all(e.task == "A0" and 1 <= e.length <= 10 for e in result.episodes)
    assert goal.feedback and goal.feedback[-1].steps <= 60
    wait_until(lambda: progress, 10, "glocal/training_progress")
    assert progress[-1].output_policy == "trained" and progress[-1].step_budget == 60

    trained = stored_policies(ros_node)["trained"]
    assert (trained.task, trained.parent, trained.last_score_task) == ("A0", "prior", "A0")
    assert trained.steps_trained == stored_policies(ros_node)["prior"].steps_trained + result.steps_used
    assert not (graph["policy_dir"] / ".checkpoints" / "trained" / "checkpoint.json").exists()

    # The same goal again (a client that lost the result): the outcome, without training again.
    status, again = Goal(graph["train"], train_goal(step_budget=60, eval_interval=30)).result(30)
    assert status == GoalStatus.STATUS_SUCCEEDED and "not trained again" in again.message
    assert (again.steps_used, again.score.successes) == (result.steps_used, result.score.successes)


def test_episode_tasks_are_trained_in_turn(graph):
    goal = Goal(graph["train"], train_goal(task="", episode_tasks=["B0", "C3"], step_budget=60))
    status, result = goal.result(120, processes=[graph["learner"]])
    assert status == GoalStatus.STATUS_SUCCEEDED, result.message
    assert {e.task for e in result.episodes} == {"B0", "C3"}
    assert result.score.episodes == 0 and not result.learned


def test_evaluate_is_served_while_a_goal_trains(graph):
    goal = Goal(graph["train"], train_goal(step_budget=600))
    wait_until(lambda: goal.feedback, 60, "feedback", processes=[graph["learner"]])
    response = call(graph["evaluate"], Evaluate.Request(policy="random", tasks=["G6"], episodes=2, seed=1), 60)
    assert response.success, response.message
    assert not goal.done, "the evaluation waited for the whole goal"
    status, result = goal.result(300, processes=[graph["learner"]])
    assert status == GoalStatus.STATUS_SUCCEEDED, result.message
    assert result.steps_used >= 600


def test_cancel_stops_the_goal_and_stores_nothing(graph, ros_node):
    goal = Goal(graph["train"], train_goal(step_budget=1_000_000))
    wait_until(lambda: goal.feedback, 60, "feedback", processes=[graph["learner"]])
    done = threading.Event()
    goal.handle.cancel_goal_async().add_done_callback(lambda _: done.set())
    assert done.wait(30)
    status, result = goal.result(60, processes=[graph["learner"]])
    assert status == GoalStatus.STATUS_CANCELED
    assert 0 < result.steps_used < 1_000_000 and "canceled" in result.message
    assert "trained" not in stored_policies(ros_node)


def test_a_killed_learner_resumes_the_goal_from_its_checkpoint(graph, ros_node):
    checkpoint = graph["policy_dir"] / ".checkpoints" / "trained" / "checkpoint.json"
    goal = Goal(graph["train"], train_goal(step_budget=400))
    wait_until(lambda: checkpoint.is_file() and json.loads(checkpoint.read_text())["state"]["steps_used"] >= 80,
               120, "a checkpoint at 80 steps or more", processes=[graph["learner"]])
    graph["learner"].process.kill()
    graph["learner"].process.wait()
    saved_steps = json.loads(checkpoint.read_text())["state"]["steps_used"]

    graph["start_learner"]()
    status, result = Goal(graph["train"], train_goal(step_budget=400)).result(300)
    assert status == GoalStatus.STATUS_SUCCEEDED, result.message
    assert f"resumed from a checkpoint at step {saved_steps}" in result.message
    assert 400 <= result.steps_used < 402
    assert stored_policies(ros_node)["trained"].parent == "prior"


def test_ctrl_c_mid_goal_checkpoints_the_last_step_at_once(graph):
    """Ctrl-C reaches sim and learner together: the step that is out (nearly always, as updates overlap
    it) is never answered, and the learner checkpoints its last whole step instead of waiting for it."""
    graph["learner"].stop()
    learner = graph["start_learner"](checkpoint_interval=10**6)  # no periodic checkpoint
    goal = Goal(graph["train"], train_goal(step_budget=5_000))
    wait_until(lambda: goal.feedback and goal.feedback[-1].steps >= 320, 120, "updates under way",
               processes=[learner])
    steps_seen = goal.feedback[-1].steps
    started = time.monotonic()
    graph["sim"].process.send_signal(signal.SIGINT)
    assert learner.stop(signal.SIGINT) == 0, learner.log()
    assert time.monotonic() - started < 8
    checkpoint = json.loads((graph["policy_dir"] / ".checkpoints" / "trained" / "checkpoint.json").read_text())
    assert checkpoint["state"]["steps_used"] >= steps_seen
    assert "Traceback" not in learner.log()


@pytest.mark.parametrize("fields, message", [
    (dict(step_budget=0), "step_budget must be at least 1"),
    (dict(initial_policy="nope"), "unknown policy 'nope'"),
    (dict(initial_policy="random"), "has no model to train from"),
    (dict(task="Z9"), "Z9"),
    (dict(eval_episodes=51), "eval_episodes 51 outside 1..50"),
    (dict(output_policy="bad name"), "invalid policy name"),
    (dict(task="", episode_tasks=[]), "needs a task or episode_tasks"),
])
def test_bad_goals_are_aborted_with_the_reason_and_the_node_keeps_serving(graph, fields, message):
    status, result = Goal(graph["train"], train_goal(**fields)).result(30, processes=[graph["learner"]])
    assert status == GoalStatus.STATUS_ABORTED
    assert message in result.message
    response = call(graph["evaluate"], Evaluate.Request(policy="random", tasks=["A0"], episodes=1), 60)
    assert response.success, response.message


def test_a_second_goal_is_rejected_while_one_runs(graph):
    first = Goal(graph["train"], train_goal(step_budget=1_000_000))
    wait_until(lambda: first.feedback, 60, "feedback", processes=[graph["learner"]])
    second = Goal(graph["train"], train_goal(output_policy="other"))
    assert not second.handle.accepted
    first.handle.cancel_goal_async()
    status, _ = first.result(60)
    assert status == GoalStatus.STATUS_CANCELED


def test_a_policy_that_passes_already_is_stored_without_training(tmp_path):
    """In-process (T = 50, where the prior grasps A0): the check before the first step."""
    from glocal_ros.paths import assets_dir
    from learner_node.policies import PolicyRegistry
    from learner_node.policy_store import PolicyStore
    from learner_node.training import Trainer, TrainSpec
    from sim_node.batch import BatchedEnvs
    from sim_node.grasp_env import GraspEnv

    envs = BatchedEnvs(lambda i: GraspEnv("A0"), 2, "A0")
    policies = PolicyRegistry(PolicyStore(tmp_path / "store"), [PolicyStore(assets_dir() / "priors")])
    try:
        outcome = Trainer(envs, policies, tmp_path / "checkpoints").train(TrainSpec(
            "A0", "prior", "a0", step_budget=1_000, threshold=0, eval_episodes=4, eval_interval=500,
            stop_when_learned=True))
    finally:
        envs.close()
    assert outcome.learned and outcome.steps_used == 0 and outcome.score.successes > 0
    assert policies.record("a0").steps_trained == policies.record("prior").steps_trained

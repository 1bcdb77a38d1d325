"""The learner's Train action against a real sim_node: train, evaluate meanwhile, cancel, restart, bad goals.

Goals start from the shipped A0 prior and use small budgets: the point is the
action's behaviour, not learning (that is `glocal-ros bench learner`).

Tests that leave the sim/learner pair serving (goals that finish, are canceled
or refused) share one pair per class, as a run's pair serves goal after goal:
``TestOnASharedGraph`` (T = 10) and ``TestOnASharedGraspingGraph`` (T = 50).
Each of them names its own output policies and cancels what it left running.
A class's pair is stopped when its last test is done, before any other pair
starts: two learners on the domain would both take a goal. Tests that kill,
stop or restart a node start their own pair (``graph``).
"""

import json
import signal
import threading
import time

import pytest
from action_msgs.msg import GoalStatus
from glocal_interfaces.action import Train
from glocal_interfaces.msg import EpisodeRecord, EvaluationResult, TrainingProgress
from glocal_interfaces.srv import Evaluate, ListPolicies

from conftest import answers, node_starter, spun_test_node, wait_until
from node_common import names, qos
from node_common.action_client import ActionClient
from node_common.calls import call
from glocal_ros.sim_contract import PHASE_EVAL

#: The goals sent since a shared pair's test started: it cancels those still running when it ends.
_SENT: list["Goal"] = []


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
            _SENT.append(self)
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


def start_graph(start_node, ros_node, policy_dir, sim_params: dict, learner_params: dict) -> dict:
    """sim_node (2 envs, T = 10 unless ``sim_params`` say otherwise) and learner_node, plus the clients."""
    sim = start_node("sim_node", **{"num_envs": 2, "max_steps": 10, **sim_params})

    def start_learner(checkpoint_interval: int = 40, **params):
        learner = start_node("learner_node", max_eval_episodes=50, policy_dir=str(policy_dir),
                             checkpoint_interval=checkpoint_interval, **params)
        wait_until(train.server_is_ready, 60, "learner/train", processes=[sim, learner])
        # After a restart the killed learner's endpoints linger in discovery:
        # an answered request proves that this one is matched.
        probe = Evaluate.Request(policy="random", tasks=["A0"], episodes=1)
        wait_until(lambda: answers(evaluate, probe), 60, "an answer from the new learner", processes=[sim, learner])
        return learner

    train = ActionClient(ros_node, Train, names.LEARNER_TRAIN)
    evaluate = ros_node.create_client(Evaluate, names.LEARNER_EVALUATE)
    learner = start_learner(**learner_params)
    return dict(sim=sim, learner=learner, start_learner=start_learner, train=train, evaluate=evaluate,
                policy_dir=policy_dir)


@pytest.fixture
def graph(request, start_node, ros_node, tmp_path):
    """A pair of the test's own, for tests that kill, stop or restart a node: the test's parameter, if any,
    gives the sim's (``sim``) and the learner's (``learner``) node parameters."""
    params = getattr(request, "param", {})
    return start_graph(start_node, ros_node, tmp_path / "policies", params.get("sim", {}), params.get("learner", {}))


class SharedGraph:
    """One pair for the class's tests (``SIM``: the sim's parameters); each test must leave it serving."""

    SIM: dict = {}

    @pytest.fixture(scope="class")
    @classmethod
    def ros_node(cls):
        with spun_test_node() as node:
            yield node

    @pytest.fixture(scope="class")
    @classmethod
    def shared_graph(cls, ros_node, tmp_path_factory):
        log_dir = tmp_path_factory.mktemp("shared-graph")
        with node_starter(log_dir) as start_node:
            yield start_graph(start_node, ros_node, log_dir / "policies", cls.SIM, {})

    @pytest.fixture
    def graph(self, shared_graph, ros_node):
        """The shared pair, checked alive; afterwards the test's running goals are canceled and its
        subscriptions destroyed, so the next test finds the learner idle."""
        processes = [shared_graph["sim"], shared_graph["learner"]]
        for process in processes:
            if not process.running:
                pytest.fail(f"the shared {process.node} exited with {process.process.returncode} before this test:\n"
                            f"{process.log()}")
        _SENT.clear()
        subscriptions = {id(subscription) for subscription in ros_node.subscriptions}
        yield shared_graph
        for subscription in [s for s in ros_node.subscriptions if id(s) not in subscriptions]:
            ros_node.destroy_subscription(subscription)
        running = [goal for goal in _SENT if not goal.done]
        _SENT.clear()
        for goal in running:
            goal.handle.cancel_goal_async()
        for goal in running:
            goal.result(120, processes=processes)


def stored_policies(ros_node) -> dict:
    client = ros_node.create_client(ListPolicies, names.LEARNER_LIST_POLICIES)
    try:
        listed = call(client, ListPolicies.Request())
    finally:
        ros_node.destroy_client(client)
    return {p.name: p for p in listed.policies}


class TestOnASharedGraph(SharedGraph):
    """T = 10; goals that finish, are canceled or are refused."""

    def test_train_stores_the_policy_with_its_score(self, graph, ros_node):
        progress = []
        ros_node.create_subscription(
            TrainingProgress, names.TRAINING_PROGRESS,
            lambda message: progress.append(message) if message.output_policy == "stores" else None, qos.EVENTS)
        goal = Goal(graph["train"], train_goal(output_policy="stores", step_budget=60, eval_interval=30))
        status, result = goal.result(120, processes=[graph["learner"]])

        assert status == GoalStatus.STATUS_SUCCEEDED, result.message
        assert result.steps_used == 60
        assert (result.score.task, result.score.episodes) == ("A0", 2)
        assert result.learned == (result.score.successes > 75)
        assert result.episodes and all(e.task == "A0" and 1 <= e.length <= 10 for e in result.episodes)
        assert goal.feedback and goal.feedback[-1].steps <= 60
        wait_until(lambda: progress, 60, "glocal/training_progress of 'stores'")
        assert progress[-1].step_budget == 60

        stored = stored_policies(ros_node)["stores"]
        assert (stored.task, stored.parent, stored.last_score_task) == ("A0", "prior", "A0")
        assert stored.steps_trained == stored_policies(ros_node)["prior"].steps_trained + result.steps_used
        assert not (graph["policy_dir"] / ".checkpoints" / "stores" / "checkpoint.json").exists()

        # The same goal again (a client that lost the result): the outcome, without training again.
        again_goal = train_goal(output_policy="stores", step_budget=60, eval_interval=30)
        status, again = Goal(graph["train"], again_goal).result(30)
        assert status == GoalStatus.STATUS_SUCCEEDED and "not trained again" in again.message
        assert (again.steps_used, again.score.successes) == (result.steps_used, result.score.successes)

    def test_episode_tasks_are_trained_in_turn(self, graph):
        goal = Goal(graph["train"], train_goal(task="", episode_tasks=["B0", "C3"], output_policy="in-turn",
                                               step_budget=60))
        status, result = goal.result(120, processes=[graph["learner"]])
        assert status == GoalStatus.STATUS_SUCCEEDED, result.message
        assert {e.task for e in result.episodes} == {"B0", "C3"}
        assert result.score.episodes == 0 and not result.learned

    def test_evaluate_is_served_while_a_goal_trains(self, graph):
        goal = Goal(graph["train"], train_goal(output_policy="meanwhile", step_budget=600))
        wait_until(lambda: goal.feedback, 60, "feedback", processes=[graph["learner"]])
        response = call(graph["evaluate"], Evaluate.Request(policy="random", tasks=["G6"], episodes=2, seed=1), 60)
        assert response.success, response.message
        assert not goal.done, "the evaluation waited for the whole goal"
        status, result = goal.result(300, processes=[graph["learner"]])
        assert status == GoalStatus.STATUS_SUCCEEDED, result.message
        assert result.steps_used >= 600

    def test_cancel_stops_the_goal_and_stores_nothing(self, graph, ros_node):
        goal = Goal(graph["train"], train_goal(output_policy="canceled", step_budget=1_000_000))
        wait_until(lambda: goal.feedback, 60, "feedback", processes=[graph["learner"]])
        done = threading.Event()
        goal.handle.cancel_goal_async().add_done_callback(lambda _: done.set())
        assert done.wait(30)
        status, result = goal.result(60, processes=[graph["learner"]])
        assert status == GoalStatus.STATUS_CANCELED
        assert 0 < result.steps_used < 1_000_000 and "canceled" in result.message
        assert "canceled" not in stored_policies(ros_node)

    @pytest.mark.parametrize("fields, message", [
        (dict(step_budget=0), "step_budget 0 outside 1..100000000"),
        (dict(step_budget=2**64 - 1), f"step_budget {2**64 - 1} outside"),
        (dict(output_policy="prior"), "'prior' is shipped read-only"),
        (dict(initial_policy="nope"), "unknown policy 'nope'"),
        (dict(initial_policy="random"), "has no model to train from"),
        (dict(task="Z9"), "Z9"),
        (dict(eval_episodes=51), "eval_episodes 51 outside 1..50"),
        (dict(output_policy="bad name"), "invalid policy name"),
        (dict(task="", episode_tasks=[]), "needs a task or episode_tasks"),
        (dict(threshold=float("nan")), "threshold is NaN"),
    ])
    def test_bad_goals_are_aborted_with_the_reason_and_the_node_keeps_serving(self, graph, fields, message):
        goal = train_goal(**{"output_policy": "refused", **fields})
        status, result = Goal(graph["train"], goal).result(30, processes=[graph["learner"]])
        assert status == GoalStatus.STATUS_ABORTED
        assert message in result.message
        response = call(graph["evaluate"], Evaluate.Request(policy="random", tasks=["A0"], episodes=1), 60)
        assert response.success, response.message

    def test_of_two_goals_sent_at_once_exactly_one_is_accepted(self, graph, ros_node):
        """Two clients, one moment: the goal callback takes the learner under a lock, so the second is
        rejected (before, both were accepted in 9 of 30 tries and ran one after the other)."""
        clients = [graph["train"], ActionClient(ros_node, Train, names.LEARNER_TRAIN)]
        wait_until(clients[1].server_is_ready, 60, "the second client's server")
        for attempt in range(3):
            start = threading.Barrier(2)
            goals: list[Goal] = [None, None]

            def send(index: int) -> None:
                start.wait()
                goals[index] = Goal(clients[index], train_goal(step_budget=1_000_000, output_policy=f"at-once-{index}"))

            senders = [threading.Thread(target=send, args=(i,)) for i in range(2)]
            for sender in senders:
                sender.start()
            for sender in senders:
                sender.join(60)
            accepted = [goal for goal in goals if goal.handle.accepted]
            assert len(accepted) == 1, f"attempt {attempt}: {len(accepted)} goals accepted"
            accepted[0].handle.cancel_goal_async()
            status, _ = accepted[0].result(60, processes=[graph["learner"]])
            assert status == GoalStatus.STATUS_CANCELED
        response = call(graph["evaluate"], Evaluate.Request(policy="random", tasks=["A0"], episodes=1), 60)
        assert response.success, response.message

    def test_a_second_goal_is_rejected_while_one_runs(self, graph):
        first = Goal(graph["train"], train_goal(output_policy="first", step_budget=1_000_000))
        wait_until(lambda: first.feedback, 60, "feedback", processes=[graph["learner"]])
        second = Goal(graph["train"], train_goal(output_policy="second"))
        assert not second.handle.accepted
        first.handle.cancel_goal_async()
        status, _ = first.result(60)
        assert status == GoalStatus.STATUS_CANCELED


def test_a_killed_learner_resumes_the_goal_from_its_checkpoint(graph, ros_node):
    checkpoint = graph["policy_dir"] / ".checkpoints" / "trained" / "checkpoint.json"
    Goal(graph["train"], train_goal(step_budget=400))  # to the learner killed below, which never answers it
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


@pytest.mark.parametrize("graph", [dict(learner=dict(sim_timeout_sec=5.0))], indirect=True, ids=["sim_timeout_sec=5"])
def test_a_goal_whose_sim_dies_is_aborted_with_the_steps_it_trained(graph, ros_node):
    """The learner stops waiting after sim_timeout_sec, keeps serving, and says how far the goal got
    and where its checkpoint stands (before, the result said steps_used=0)."""
    learner = graph["learner"]
    checkpoint = graph["policy_dir"] / ".checkpoints" / "trained" / "checkpoint.json"
    goal = Goal(graph["train"], train_goal(step_budget=100_000))
    wait_until(lambda: checkpoint.is_file() and json.loads(checkpoint.read_text())["state"]["steps_used"] >= 80,
               120, "a checkpoint at 80 steps or more", processes=[learner])
    graph["sim"].process.kill()
    status, result = goal.result(120, processes=[learner])
    saved_steps = json.loads(checkpoint.read_text())["state"]["steps_used"]
    assert status == GoalStatus.STATUS_ABORTED
    assert result.steps_used == saved_steps >= 80, (result.steps_used, saved_steps, result.message)
    assert f"checkpoint at step {saved_steps}" in result.message and "did not answer" in result.message
    assert "prior" in stored_policies(ros_node) and learner.running, "the learner stopped serving"


@pytest.mark.parametrize("graph", [dict(learner=dict(checkpoint_interval=10**6, sim_timeout_sec=600.0))],
                         indirect=True, ids=["no_periodic_checkpoint"])
def test_ctrl_c_mid_goal_checkpoints_the_last_step_at_once(graph):
    """Ctrl-C reaches sim and learner together: the step that is out (nearly always, as updates overlap
    it) is never answered, and the learner checkpoints its last whole step instead of waiting for it.
    A learner that waited would wait sim_timeout_sec (600 s) and be killed by ``stop`` long before."""
    learner = graph["learner"]  # checkpoint_interval 10**6: no periodic checkpoint
    goal = Goal(graph["train"], train_goal(step_budget=5_000))
    wait_until(lambda: goal.feedback and goal.feedback[-1].steps >= 320, 120, "updates under way",
               processes=[learner])
    steps_seen = goal.feedback[-1].steps
    graph["sim"].process.send_signal(signal.SIGINT)
    assert learner.stop(signal.SIGINT, timeout=120) == 0, learner.log()
    checkpoint = json.loads((graph["policy_dir"] / ".checkpoints" / "trained" / "checkpoint.json").read_text())
    assert checkpoint["state"]["steps_used"] >= steps_seen
    assert "Traceback" not in learner.log()


def test_a_client_whose_learner_dies_sends_the_goal_again_and_it_resumes(graph, ros_node):
    """The curriculum's client notices the learner's action server leave the graph, waits for a new
    learner, and sends the same goal, which resumes from its checkpoint."""
    from curriculum_node.ros_learner import RosLearner
    from glocal_ros.curriculum.learner import TrainGoal

    checkpoint = graph["policy_dir"] / ".checkpoints" / "trained" / "checkpoint.json"
    learner = RosLearner(ros_node, timeout_sec=120)
    request = TrainGoal(task="A0", initial_policy="prior", output_policy="trained", step_budget=400,
                           threshold=1.0, eval_episodes=2, stop_when_learned=False)
    outcome: dict = {}
    client = threading.Thread(target=lambda: outcome.update(result=learner.train(request)), daemon=True)
    client.start()
    wait_until(lambda: checkpoint.is_file() and json.loads(checkpoint.read_text())["state"]["steps_used"] >= 80,
               120, "a checkpoint at 80 steps or more", processes=[graph["learner"]])
    graph["learner"].process.kill()
    graph["learner"].process.wait()
    saved_steps = json.loads(checkpoint.read_text())["state"]["steps_used"]
    new_learner = graph["start_learner"]()
    client.join(300)
    assert "result" in outcome, "the client did not finish the goal\n" + new_learner.log()
    assert 400 <= outcome["result"].steps_used < 402
    assert f"resumed from a checkpoint at step {saved_steps}" in new_learner.log()


def evaluations_of(ros_node, policy: str) -> list[EvaluationResult]:
    """The list that ``glocal/evaluations`` of ``policy`` will be appended to."""
    heard: list[EvaluationResult] = []
    ros_node.create_subscription(EvaluationResult, names.EVALUATIONS,
                                 lambda message: heard.append(message) if message.policy == policy else None,
                                 qos.EVENTS)
    return heard


class TestOnASharedGraspingGraph(SharedGraph):
    """T = 50, where the prior grasps A0 (19-20 of 20)."""

    SIM = dict(max_steps=50)

    def test_evaluations_inside_a_goal_score_as_learner_evaluate_does(self, graph, ros_node):
        """A goal's check before its first step scores exactly what learner/evaluate scores for the same policy,
        task and seeded episodes: on the result, on glocal/evaluations and in the sim's eval EpisodeRecords.
        D3: the prior meets it with A0's task inputs at a goal's start (the default profile), and Evaluate
        scores it so too (with raw inputs it scored 2 of 20 where the goal's check scored 20)."""
        from glocal_ros.seeds import derived_seed
        from learner_node.training import EVALUATION_STREAM

        seed, episodes, output = 7, 20, "scored-as-evaluate"
        evaluations = evaluations_of(ros_node, output)
        eval_records = []
        ros_node.create_subscription(
            EpisodeRecord, names.EPISODES,
            lambda record: eval_records.append(record) if record.phase == PHASE_EVAL and record.policy_name == output
            else None, qos.EPISODES)
        goal = Goal(graph["train"], train_goal(task="D3", output_policy=output, step_budget=8, eval_episodes=episodes,
                                               threshold=episodes - 0.5, stop_when_learned=True, seed=seed))
        status, result = goal.result(300, processes=[graph["learner"]])
        assert status == GoalStatus.STATUS_SUCCEEDED, result.message
        standalone = call(graph["evaluate"], Evaluate.Request(policy="prior", tasks=["D3"], episodes=episodes,
                                                              seed=derived_seed(seed, EVALUATION_STREAM, 0)), 300)
        assert standalone.success, standalone.message

        wait_until(lambda: evaluations and evaluations[-1].scores[0].successes == result.score.successes, 60,
                   "the goal's evaluations on glocal/evaluations")
        assert {message.purpose for message in evaluations} == {"train"}
        assert evaluations[0].scores[0].successes == standalone.scores[0].successes
        scored_feedback = {f.latest_score for f in goal.feedback} - {-1.0}
        assert scored_feedback <= {float(message.scores[0].successes) for message in evaluations}, scored_feedback
        wait_until(lambda: len(eval_records) >= episodes * len(evaluations), 60, "the evaluations' episodes")

    def test_a_goal_that_stops_when_learned_ends_at_its_last_evaluation_whatever_it_scores(self, graph, ros_node):
        """Through the graph, what holds for any outcome (whether the prior passes E3, and when, is chance;
        ``test_the_stop_rule_ends_a_goal_at_the_evaluation_that_passed`` scripts it): every evaluation up to
        the last is at or below B, one every interval from step 0; a learned goal's last is above B, and its
        steps_used is that evaluation's step; nothing is evaluated after it."""
        threshold, interval, budget, output = 8.5, 50, 100, "stops-when-learned"
        evaluations = evaluations_of(ros_node, output)
        goal = Goal(graph["train"], train_goal(task="E3", output_policy=output, step_budget=budget,
                                               eval_interval=interval, eval_episodes=10, threshold=threshold,
                                               stop_when_learned=True, seed=2))
        status, result = goal.result(300, processes=[graph["learner"]])
        assert status == GoalStatus.STATUS_SUCCEEDED, result.message
        wait_until(lambda: evaluations and evaluations[-1].scores[0].successes == result.score.successes, 30,
                   "the goal's evaluations on glocal/evaluations")
        time.sleep(1)  # an evaluation after the last would have been published by now: the learner sent the result
        scores = [message.scores[0].successes for message in evaluations]
        assert all(score <= threshold for score in scores[:-1]), scores
        assert result.steps_used == interval * (len(scores) - 1), (result.steps_used, scores)
        assert result.learned == (scores[-1] > threshold)
        if not result.learned:
            assert result.steps_used == budget, (result.steps_used, scores)
        assert f"{'learned' if result.learned else 'not learned'} after {result.steps_used} steps" in result.message

    def test_a_threshold_of_zero_is_honoured(self, graph):
        """B = 0 (learned from one success on) was taken for "unset" and judged at 0.75 x S-bar instead."""
        goal = train_goal(output_policy="threshold-zero", step_budget=2, threshold=0.0, eval_episodes=4)
        status, result = Goal(graph["train"], goal).result(120, processes=[graph["learner"]])
        assert status == GoalStatus.STATUS_SUCCEEDED, result.message
        assert result.learned == (result.score.successes > 0), result
        stored = json.loads((graph["policy_dir"] / "threshold-zero" / "policy.json").read_text())
        assert stored["extra"]["threshold"] == 0.0, stored


@pytest.mark.parametrize("script, passing", [([3, 5, 9], 2), ([9], 0), ([1, 1, 1, 1, 1], None)])
def test_the_stop_rule_ends_a_goal_at_the_evaluation_that_passed(tmp_path, monkeypatch, script, passing):
    """In-process, the sim and SAC real and the scores scripted: a goal that stops when learned ends with
    the first evaluation above B (the check before the first step included), its steps_used that
    evaluation's step, and nothing is evaluated after it; a goal that never passes trains its budget."""
    import learner_node.training as training
    from glocal_ros.paths import assets_dir
    from learner_node.evaluation import Score
    from learner_node.policies import PolicyRegistry
    from learner_node.policy_store import PolicyStore
    from sim_node.batch import BatchedEnvs
    from sim_node.grasp_env import GraspEnv, GraspEnvConfig

    scores = iter(script)
    monkeypatch.setattr(training, "evaluate", lambda envs, policy, tasks, episodes, **options: [
        Score(tasks[0], next(scores), episodes)])
    envs = BatchedEnvs(lambda i: GraspEnv("A0", config=GraspEnvConfig(max_steps=10)), 2, "A0")
    policies = PolicyRegistry(PolicyStore(tmp_path / "store"), [PolicyStore(assets_dir() / "priors")])
    evaluated = []
    try:
        outcome = training.Trainer(envs, policies, tmp_path / "checkpoints").train(
            training.TrainGoal("A0", "prior", "out", step_budget=8, eval_interval=2, eval_episodes=10,
                               threshold=8.5, stop_when_learned=True),
            on_evaluation=lambda score, steps: evaluated.append((steps, score.successes)))
    finally:
        envs.close()
    assert evaluated == [(2 * k, score) for k, score in enumerate(script)]
    assert outcome.learned == (passing is not None)
    assert outcome.steps_used == (8 if passing is None else 2 * passing)


def test_a_policy_that_passes_already_is_stored_without_training(tmp_path):
    """In-process (T = 50, where the prior grasps A0): the check before the first step."""
    from glocal_ros.paths import assets_dir
    from learner_node.policies import PolicyRegistry
    from learner_node.policy_store import PolicyStore
    from glocal_ros.curriculum.learner import TrainGoal
    from learner_node.training import Trainer
    from sim_node.batch import BatchedEnvs
    from sim_node.grasp_env import GraspEnv

    envs = BatchedEnvs(lambda i: GraspEnv("A0"), 2, "A0")
    policies = PolicyRegistry(PolicyStore(tmp_path / "store"), [PolicyStore(assets_dir() / "priors")])
    try:
        outcome = Trainer(envs, policies, tmp_path / "checkpoints").train(TrainGoal(
            "A0", "prior", "a0", step_budget=1_000, threshold=0, eval_episodes=4, eval_interval=500,
            stop_when_learned=True))
    finally:
        envs.close()
    assert outcome.learned and outcome.steps_used == 0 and outcome.score.successes > 0
    assert policies.record("a0").steps_trained == policies.record("prior").steps_trained


def test_a_goal_never_trains_past_its_budget_and_ends_at_its_episode_limit(tmp_path):
    """In-process, 2 lockstep envs (T = 10): a budget of 41 trains 40 steps (SB3 steps both envs, so 42
    before); an episode limit of 3 ends the goal at the step where the third episode finished."""
    from glocal_ros.paths import assets_dir
    from learner_node.policies import PolicyRegistry
    from learner_node.policy_store import PolicyStore
    from glocal_ros.curriculum.learner import TrainGoal
    from learner_node.training import Trainer
    from sim_node.batch import BatchedEnvs
    from sim_node.grasp_env import GraspEnv, GraspEnvConfig

    envs = BatchedEnvs(lambda i: GraspEnv("A0", config=GraspEnvConfig(max_steps=10)), 2, "A0")
    policies = PolicyRegistry(PolicyStore(tmp_path / "store"), [PolicyStore(assets_dir() / "priors")])
    trainer = Trainer(envs, policies, tmp_path / "checkpoints", seed=3)
    listed = ("B0", "C3", "D2", "E1", "F0", "G6", "A1", "B2", "C4", "D5")
    try:
        odd = trainer.train(TrainGoal("", "prior", "odd", step_budget=41, episode_tasks=("A0",), seed=1))
        limited = trainer.train(TrainGoal("", "prior", "limited", step_budget=1_000, episode_tasks=listed,
                                          episode_limit=3, seed=2))
    finally:
        envs.close()
    assert odd.completed and odd.steps_used == 40
    assert policies.record("odd").steps_trained == policies.record("prior").steps_trained + 40
    assert limited.completed and 3 <= len(limited.episodes) <= 4, limited.episodes
    # Two envs take the listed tasks in turn: the third finished episode ends by the second round's end.
    assert limited.steps_used <= 2 * 2 * 10
    finished = [e.task for e in limited.episodes]
    assert set(finished) <= set(listed) and len(set(finished)) == len(finished), "each a listed task, none twice"


def test_a_goal_resumed_from_its_checkpoint_ends_as_the_uninterrupted_goal(tmp_path):
    """In-process (T = 10): the goal's checkpoint at step 290 (mid-episode) is copied aside while the goal runs on to
    its end; another trainer (another store, seed and sim history) resumed from that copy ends the goal
    with the same episodes, evaluations and weights, as a learner killed after the checkpoint would."""
    import shutil

    import jax
    import numpy as np

    from glocal_ros.paths import assets_dir
    from learner_node.evaluation import evaluate
    from learner_node.policies import PolicyRegistry
    from learner_node.policy_store import PolicyStore
    from glocal_ros.curriculum.learner import TrainGoal
    from learner_node.training import CHECKPOINT_FILE, Trainer
    from sim_node.batch import BatchedEnvs
    from sim_node.grasp_env import GraspEnv, GraspEnvConfig

    spec = TrainGoal("A0", "prior", "goal", step_budget=600, eval_episodes=2, eval_interval=200, seed=11)
    copy = tmp_path / "copy"

    def run(name: str, trainer_seed: int, between_steps=lambda: False):
        envs = BatchedEnvs(lambda i: GraspEnv("A0", config=GraspEnvConfig(max_steps=10)), 2, "A0")
        policies = PolicyRegistry(PolicyStore(tmp_path / name / "store"), [PolicyStore(assets_dir() / "priors")])
        trainer = Trainer(envs, policies, tmp_path / name / "checkpoints", seed=trainer_seed, checkpoint_interval=290)
        try:
            if name == "resumed":  # another history of the sim, and the checkpoint in place
                evaluate(envs, policies.load("random", seed=3), ["B2"], 3)
                shutil.copytree(copy, tmp_path / name / "checkpoints" / "goal")
            outcome = trainer.train(spec, between_steps=between_steps)
            return outcome, policies.model("goal")
        finally:
            envs.close()

    checkpoint = tmp_path / "uninterrupted" / "checkpoints" / "goal" / CHECKPOINT_FILE

    def copy_the_first_checkpoint() -> bool:
        if checkpoint.is_file() and not copy.exists():
            shutil.copytree(checkpoint.parent, copy)
        return False

    uninterrupted, model = run("uninterrupted", 0, copy_the_first_checkpoint)
    assert json.loads((copy / CHECKPOINT_FILE).read_text())["state"]["steps_used"] == 290  # mid-episode
    resumed, resumed_model = run("resumed", 5)
    assert "resumed from a checkpoint at step 290" in resumed.message
    assert model.num_timesteps > model.learning_starts + 200, "the gradient steps were not part of the test"
    assert (resumed.learned, resumed.score, resumed.steps_used) == \
        (uninterrupted.learned, uninterrupted.score, uninterrupted.steps_used)
    assert resumed.episodes == uninterrupted.episodes
    for name in ("actor_state", "qf_state"):
        for weights, resumed_weights in zip(*(jax.tree_util.tree_leaves(getattr(each.policy, name).params)
                                              for each in (model, resumed_model))):
            np.testing.assert_array_equal(weights, resumed_weights, err_msg=name)

"""The curriculum's ``Learner`` protocol over the learner node's action and services.

Calls block until answered (a Train goal until it ends), so they run in the
curriculum's worker thread while the node's executor spins elsewhere.
"""

from __future__ import annotations

import threading
import time
from typing import Callable, Sequence

from action_msgs.msg import GoalStatus
from glocal_interfaces.action import Train
from glocal_interfaces.srv import CopyPolicy, Evaluate
from rclpy.action import ActionClient
from rclpy.callback_groups import ReentrantCallbackGroup
from rclpy.node import Node

from glocal_ros.curriculum.learner import EpisodeSummary, TrainRequest, TrainResult
from node_common import names
from node_common.calls import ServiceCallError, call_checked, wait_for_service

#: How long to wait before offering a goal again that the learner rejected
#: because it is busy (with a goal this node sent before it was restarted).
BUSY_RETRY_SEC = 2.0


class LearnerStopped(RuntimeError):
    """The node is shutting down, or the goal was canceled: the run stops here and can resume."""


class RosLearner:
    def __init__(self, node: Node, timeout_sec: float,
                 on_feedback: Callable[[Train.Feedback], None] = lambda feedback: None):
        group = ReentrantCallbackGroup()
        self.node = node
        self.timeout_sec = timeout_sec
        self.on_feedback = on_feedback
        self._evaluate = node.create_client(Evaluate, names.LEARNER_EVALUATE, callback_group=group)
        self._copy = node.create_client(CopyPolicy, names.LEARNER_COPY_POLICY, callback_group=group)
        self._train = ActionClient(node, Train, names.LEARNER_TRAIN, callback_group=group)

    def wait_for_learner(self) -> None:
        wait_for_service(self._evaluate, self.timeout_sec)
        wait_for_service(self._copy, self.timeout_sec)
        if not self._train.wait_for_server(timeout_sec=self.timeout_sec):
            raise ServiceCallError(f"action {names.LEARNER_TRAIN} is not available after {self.timeout_sec:.0f} s")

    def evaluate(self, policy: str, tasks: Sequence[str], episodes: int) -> dict[str, float]:
        request = Evaluate.Request(policy=policy, tasks=list(tasks), episodes=episodes, seed=-1)
        response = call_checked(self._evaluate, request, timeout_sec=self.timeout_sec)
        return {score.task: float(score.successes) for score in response.scores}

    def copy(self, source: str, destination: str) -> None:
        try:
            call_checked(self._copy, CopyPolicy.Request(source=source, destination=destination), self.timeout_sec)
        except ServiceCallError as error:
            # Copied just before this node was killed, before the journal had it.
            if "exists already" not in str(error):
                raise
            self.node.get_logger().info(f"{destination} exists already: kept")

    def train(self, request: TrainRequest) -> TrainResult:
        goal = Train.Goal(
            task=request.task, episode_tasks=list(request.episode_tasks), initial_policy=request.initial_policy,
            output_policy=request.output_policy, step_budget=request.step_budget, threshold=request.threshold,
            eval_episodes=request.eval_episodes, eval_interval=request.eval_interval,
            stop_when_learned=request.stop_when_learned, keep_replay_buffer=request.keep_replay_buffer,
        )
        handle = self._send(goal)
        response = self._wait(handle.get_result_async())
        status, result = response.status, response.result
        if status == GoalStatus.STATUS_SUCCEEDED:
            episodes = tuple(EpisodeSummary(e.task, e.episode_return, e.length, e.success) for e in result.episodes)
            score = float(result.score.successes) if result.score.episodes else -1.0
            return TrainResult(result.learned, score, int(result.steps_used), episodes)
        if status == GoalStatus.STATUS_CANCELED or not self.node.context.ok():
            raise LearnerStopped(f"training {request.output_policy} stopped: {result.message}")
        raise ServiceCallError(f"training {request.output_policy} failed: {result.message}")

    def _send(self, goal: Train.Goal):
        while True:
            handle = self._wait(self._train.send_goal_async(
                goal, feedback_callback=lambda message: self.on_feedback(message.feedback)), self.timeout_sec)
            if handle.accepted:
                return handle
            self.node.get_logger().info(f"the learner is busy; offering {goal.output_policy} again shortly")
            time.sleep(BUSY_RETRY_SEC)

    def _wait(self, future, timeout_sec: float | None = None):
        """The future's result; a goal may take hours, so by default only shutdown ends the wait."""
        done = threading.Event()
        future.add_done_callback(lambda _: done.set())
        deadline = None if timeout_sec is None else time.monotonic() + timeout_sec
        while not done.wait(0.5):
            if not self.node.context.ok():
                raise LearnerStopped("the node is shutting down")
            if deadline is not None and time.monotonic() > deadline:
                raise ServiceCallError(f"{names.LEARNER_TRAIN} did not answer within {timeout_sec:.0f} s")
        return future.result()

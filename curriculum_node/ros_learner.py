"""The curriculum's ``Learner`` protocol over the learner node's action and services.

Calls block until answered (a Train goal until it ends), so they run in the
curriculum's worker thread while the node's executor spins elsewhere.

No answer is waited for forever. A Train goal is idempotent on the learner
(the same goal sent again resumes from its checkpoint, or gets back the
outcome of the run that finished), so every loss is answered by sending the
same goal again:
- the goal response (accepted/rejected) comes within
  ``GOAL_RESPONSE_TIMEOUT_SEC``, or the goal is sent again; a learner that is
  still running the first copy rejects the second as busy, and the copy
  offered after it finished gets its outcome;
- the result response: the result is asked for again every
  ``RESULT_PROBE_SEC``; the learner answers each request when the goal ends;
- the learner itself: a restarted learner answers those requests at once
  with STATUS_UNKNOWN (it never had the goal), and the goal is sent again,
  resuming from its last checkpoint; a learner that stays out of the graph
  for ``away_sec`` fails the call with ``LearnerAway``.
Evaluate and CopyPolicy are sent again when the learner that had them leaves
the graph (``node_common.calls.ServerWatch``) and is back within
``away_sec``: a seeded evaluation asked again scores the same, and a copy
made before the kill is found there.
The race that drops responses inside rclpy is closed by
``node_common.action_client``.

A learner is out of the graph once DDS drops it: a killed learner's
participant stays listed until its lease runs out (20 s, Fast DDS's
default), so a kill is noticed after about 20 s + ``away_sec``. Alone, a
learner may be away as long as any request may take (``timeout_sec``,
the default ``away_sec``); in a pool (``parallel_locals``) the call goes
to another learner sooner, and ``wait_until_ready`` keeps this one out of
the pool until it is back and runs no goal.
"""

from __future__ import annotations

import threading
import time
from typing import Callable, Sequence

from action_msgs.msg import GoalStatus
from glocal_interfaces.action import Train
from glocal_interfaces.srv import CopyPolicy, Evaluate
from rclpy.callback_groups import ReentrantCallbackGroup
from rclpy.node import Node

from glocal_ros.curriculum.learner import EpisodeSummary, TrainGoal, TrainResult
from node_common import names
from node_common.action_client import ActionClient
from node_common.calls import ServerGone, ServerWatch, ServiceCallError, call_checked, wait_for_service
from node_common.train_goal import goal_message

#: How long to wait before offering a goal again that the learner rejected
#: because it is busy (with a goal this node sent before it was restarted).
BUSY_RETRY_SEC = 2.0
#: The learner accepts or rejects a goal at once; no answer by then was lost.
GOAL_RESPONSE_TIMEOUT_SEC = 30.0
#: Seconds between extra result requests of a running goal (see ``RosLearner._wait_result``).
RESULT_PROBE_SEC = 10.0
POLL_SEC = 0.5


class LearnerStopped(RuntimeError):
    """The node is shutting down, or the goal was canceled: the run stops here and can resume."""


class LearnerAway(ServiceCallError):
    """The learner left the graph and was not back within ``away_sec``: the call may go to another."""


class _NoAnswer(Exception):
    """A response did not come in time."""


class RosLearner:
    def __init__(self, node: Node, timeout_sec: float,
                 on_feedback: Callable[[Train.Feedback], None] = lambda feedback: None, namespace: str = "",
                 away_sec: float | None = None):
        """``namespace``: the learner's (e.g. ``/pair1``, ``/`` the root, ``pair1`` under the node's); "" for the
        node's own. ``away_sec``: how long the learner may be out of the graph before a call on it fails
        (default ``timeout_sec``)."""
        group = ReentrantCallbackGroup()
        self.node = node
        self.timeout_sec = timeout_sec
        self.away_sec = timeout_sec if away_sec is None else away_sec
        self.on_feedback = on_feedback
        prefix = namespace.rstrip("/") + "/" if namespace else ""
        self._evaluate = node.create_client(Evaluate, prefix + names.LEARNER_EVALUATE, callback_group=group)
        self._copy = node.create_client(CopyPolicy, prefix + names.LEARNER_COPY_POLICY, callback_group=group)
        self.train_name = prefix + names.LEARNER_TRAIN
        self._train = ActionClient(node, Train, self.train_name, callback_group=group)
        # What the recovery below had to do (``glocal-ros bench graph`` reports them).
        self.goals_sent_again = 0  # a goal response lost, or the learner left mid-goal
        self.results_asked_again = 0  # the goal ended, its result response did not come
        self.calls_sent_again = 0  # an Evaluate or CopyPolicy whose learner left before answering

    def wait_for_learner(self) -> None:
        """Block until the learner's services and action are in the graph (``ServiceCallError`` after
        ``timeout_sec``)."""
        wait_for_service(self._evaluate, self.timeout_sec)
        wait_for_service(self._copy, self.timeout_sec)
        if not self._train.wait_for_server(timeout_sec=self.timeout_sec):
            raise ServiceCallError(f"action {self.train_name} is not available after {self.timeout_sec:.0f} s")

    def wait_until_ready(self) -> None:
        """Block until the learner is in the graph (within ``timeout_sec``) and runs no goal: one sent by a
        curriculum node killed before this one, which the same goal sent now would run a second time on
        another learner. Its goal status says so (every learner publishes one when it starts); a goal
        it runs is waited for as long as the learner stays in the graph."""
        self.wait_for_learner()
        away = self._absence()
        deadline, told = time.monotonic() + self.timeout_sec, False
        while True:
            busy = self._train.server_busy()
            if busy is False:
                return
            if busy is None and time.monotonic() > deadline:
                raise ServiceCallError(f"{self.train_name} published no goal status within "
                                       f"{self.timeout_sec:.0f} s")
            if busy and not told:
                told = True
                self.node.get_logger().info(f"{self.train_name} runs a goal sent before: "
                                            "waiting for it to end")
            if not self.node.context.ok():
                raise LearnerStopped("the node is shutting down")
            away.check()
            time.sleep(POLL_SEC)

    def evaluate(self, policy: str, tasks: Sequence[str], episodes: int, seed: int | None = None) -> dict[str, float]:
        request = Evaluate.Request(policy=policy, tasks=list(tasks), episodes=episodes,
                                   seed=-1 if seed is None else seed)
        response = self._call(self._evaluate, request)
        return {score.task: float(score.successes) for score in response.scores}

    def copy(self, source: str, destination: str) -> None:
        try:
            self._call(self._copy, CopyPolicy.Request(source=source, destination=destination))
        except ServiceCallError as error:
            # Copied just before this node was killed, before the journal had it.
            if error.response is None or error.response.error != CopyPolicy.Response.ERROR_EXISTS:
                raise
            self.node.get_logger().info(f"{destination} exists already: kept")

    def train(self, request: TrainGoal) -> TrainResult:
        goal = goal_message(request)
        while True:
            response = self._wait_result(self._send(goal))
            if response is not None:
                break
            self.goals_sent_again += 1
            self.node.get_logger().warning(
                f"the learner was restarted while training {goal.output_policy}: sending the goal again "
                f"(it resumes from its checkpoint)")
        status, result = response.status, response.result
        if status == GoalStatus.STATUS_SUCCEEDED:
            episodes = tuple(EpisodeSummary(e.task, e.episode_return, e.length, e.success) for e in result.episodes)
            score = float(result.score.successes) if result.score.episodes else -1.0
            return TrainResult(result.learned, score, int(result.steps_used), episodes)
        if status == GoalStatus.STATUS_CANCELED or not self.node.context.ok():
            raise LearnerStopped(f"training {request.output_policy} stopped: {result.message}")
        raise ServiceCallError(f"training {request.output_policy} failed: {result.message}")

    def _absence(self) -> _Absence:
        return _Absence(self._train, self.train_name, self.away_sec, self.node.get_logger())

    def _call(self, client, request):
        """``call_checked``, asked again of a learner that was restarted before it answered; ``LearnerAway``
        when it is not in the graph, or not back, within ``away_sec``."""
        self._wait_for_service(client)
        while True:
            try:
                return call_checked(client, request, self.timeout_sec, ServerWatch(self.node, client.srv_name))
            except ServerGone:
                self.calls_sent_again += 1
                self.node.get_logger().warning(f"the learner left before answering {client.srv_name}: "
                                               "asking again when it is back")
                self._wait_for_service(client)

    def _wait_for_service(self, client) -> None:
        if not client.wait_for_service(timeout_sec=self.away_sec):
            message = f"service {client.srv_name} is not available after {self.away_sec:.0f} s"
            self.node.get_logger().warning(message)
            raise LearnerAway(message)

    def _send(self, goal: Train.Goal):
        """The handle of ``goal`` once the learner accepted it."""
        deadline = time.monotonic() + self.timeout_sec
        away = self._absence()
        while True:
            future = self._train.send_goal_async(
                goal, feedback_callback=lambda message: self.on_feedback(message.feedback))
            try:
                handle = self._wait(future, GOAL_RESPONSE_TIMEOUT_SEC, away)
            except _NoAnswer:
                self._train._remove_pending_goal_request(future)
                self.goals_sent_again += 1
                if time.monotonic() > deadline:
                    raise ServiceCallError(
                        f"{names.LEARNER_TRAIN} answered no goal within {self.timeout_sec:.0f} s") from None
                self.node.get_logger().warning(
                    f"no answer to the goal {goal.output_policy} in {GOAL_RESPONSE_TIMEOUT_SEC:.0f} s: "
                    f"sending it again")
                continue
            if handle.accepted:
                return handle
            self.node.get_logger().info(f"the learner is busy; offering {goal.output_policy} again shortly")
            time.sleep(BUSY_RETRY_SEC)

    def _wait_result(self, handle):
        """The goal's result response; None when the learner no longer knows the goal (it was restarted).

        Besides the first result request, another goes every ``RESULT_PROBE_SEC`` while the
        server is up: the learner that runs the goal answers them all when it ends (so a lost
        response is made good), and a restarted learner, which never had the goal, answers at
        once with STATUS_UNKNOWN. The server seen in the graph says nothing here: a learner
        restarted within the discovery lease takes the old one's place unnoticed.
        """
        asked = []
        answered = threading.Event()

        def ask() -> None:
            future = handle.get_result_async()
            future.add_done_callback(lambda _: answered.set())
            asked.append(future)

        ask()
        next_probe, away = time.monotonic() + RESULT_PROBE_SEC, self._absence()
        try:
            while True:
                if answered.wait(POLL_SEC):
                    answered.clear()
                    responses = [future.result() for future in asked if future.done()]
                    known = [r for r in responses if r.status != GoalStatus.STATUS_UNKNOWN]
                    if known:
                        if not asked[0].done():
                            self.results_asked_again += 1  # the first response was lost
                        return known[0]
                    if responses:
                        return None
                if not self.node.context.ok():
                    raise LearnerStopped("the node is shutting down")
                if away.check() and time.monotonic() >= next_probe:
                    ask()
                    next_probe = time.monotonic() + RESULT_PROBE_SEC
        finally:
            for future in asked:
                if not future.done():
                    self._train._remove_pending_result_request(future)

    def _wait(self, future, timeout_sec: float, away: _Absence):
        """The future's result within ``timeout_sec`` (``_NoAnswer`` otherwise); shutdown ends the wait, and
        so does the server's absence (``_Absence``)."""
        done = threading.Event()
        future.add_done_callback(lambda _: done.set())
        deadline = time.monotonic() + timeout_sec
        while not done.wait(POLL_SEC):
            if not self.node.context.ok():
                raise LearnerStopped("the node is shutting down")
            away.check()
            if time.monotonic() > deadline:
                raise _NoAnswer()
        return future.result()


class _Absence:
    """How long an action server has been out of the graph: ``check`` raises ``LearnerAway`` past ``away_sec``."""

    def __init__(self, client: ActionClient, name: str, away_sec: float, logger):
        self.client, self.name, self.away_sec, self.logger = client, name, away_sec, logger
        self.since: float | None = None

    def check(self) -> bool:
        """True when the server is in the graph; raises once it has been out of it longer than ``away_sec``."""
        if self.client.server_is_ready():
            self.since = None
            return True
        now = time.monotonic()
        self.since = self.since or now
        if now - self.since > self.away_sec:
            message = f"{self.name} left the graph and was not back within {self.away_sec:.0f} s"
            self.logger.warning(message)
            raise LearnerAway(message)
        return False

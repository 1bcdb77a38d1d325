"""rclpy's ActionClient with its response race closed.

rclpy 7.1.6 (the only Jazzy wheel) sends a goal, cancel or result request
and only then registers the request's sequence number. Under a
MultiThreadedExecutor the response can be taken and handled on another
thread in between; it is then dropped with "Ignoring unexpected goal
response. There may be more than one action server ..." and its future
never completes (ros2/rclpy#1123, fixed upstream by ros2/rclpy#1308 and its
backports #1517/#1519, which this wheel predates). A `make run` lost a Train
goal's response exactly so, and waited out its whole timeout.

``ActionClient`` here is upstream's fix: one lock held while a request is
sent and registered, and while a response is matched to its request, so a
response is matched only after its request is registered. Service clients
need nothing: rclpy's ``Client.call_async`` registers under a lock already.

It also keeps the latest goal status array the server published (the
action's ``_action/status`` topic, reliable and transient-local, which rclpy
takes for its own goals only): ``server_busy`` tells whether the server runs
a goal, this client's or anyone's (a curriculum node killed and started
again finds its learners still running the goals it sent before).
"""

from __future__ import annotations

import threading

from action_msgs.msg import GoalStatus
from rclpy.action import ActionClient as RclpyActionClient

#: Statuses of a goal the server has not ended.
_ACTIVE = (GoalStatus.STATUS_ACCEPTED, GoalStatus.STATUS_EXECUTING, GoalStatus.STATUS_CANCELING)


class ActionClient(RclpyActionClient):
    """``rclpy.action.ActionClient`` whose responses cannot arrive before their requests are registered."""

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        # Reentrant: a future's done callback may run inline and send the next request.
        self._registration_lock = threading.RLock()
        self._server_status = None  # the latest GoalStatusArray the server published

    def server_busy(self) -> bool | None:
        """Whether the server has a goal it has not ended, by the latest status it published; None before
        any came (a server publishes one when it starts, see learner_node, and at every goal's change)."""
        status = self._server_status
        if status is None:
            return None
        return any(goal.status in _ACTIVE for goal in status.status_list)

    def send_goal_async(self, goal, feedback_callback=None, goal_uuid=None):
        with self._registration_lock:
            return super().send_goal_async(goal, feedback_callback, goal_uuid)

    def _cancel_goal_async(self, goal_handle):
        with self._registration_lock:
            return super()._cancel_goal_async(goal_handle)

    def _get_result_async(self, goal_handle):
        with self._registration_lock:
            return super()._get_result_async(goal_handle)

    async def execute(self, taken_data):
        if "status" in taken_data:
            self._server_status = taken_data["status"]
        responses = {key: taken_data[key] for key in ("goal", "cancel", "result") if key in taken_data}
        if responses:
            # Matching responses to requests awaits nothing, so the lock is never held across a
            # suspension; feedback callbacks (which may await) run outside it.
            with self._registration_lock:
                await super().execute(responses)
        rest = {key: value for key, value in taken_data.items() if key not in responses}
        if rest:
            await super().execute(rest)

"""One-shot ROS clients behind the ``glocal-ros`` commands."""

from __future__ import annotations

from glocal_interfaces.srv import Evaluate
import rclpy

from node_common import names
from node_common.runner import configure_discovery


def evaluate_policy(
    policy: str, tasks: list[str], episodes: int, seed: int, timeout_sec: float
) -> list[tuple[str, int, int]]:
    """Call ``learner/evaluate`` once; ``(task, successes, episodes)`` per task, or SystemExit with the reason."""
    if episodes < 1:
        raise SystemExit(f"--episodes must be at least 1, got {episodes}")
    configure_discovery()
    rclpy.init()
    try:
        node = rclpy.create_node("glocal_ros_evaluate")
        client = node.create_client(Evaluate, names.LEARNER_EVALUATE)
        if not client.wait_for_service(timeout_sec=min(timeout_sec, 30.0)):
            raise SystemExit(f"no learner answers on {client.srv_name}: is learner_node running on this ROS_DOMAIN_ID?")
        future = client.call_async(Evaluate.Request(policy=policy, tasks=tasks, episodes=episodes, seed=seed))
        rclpy.spin_until_future_complete(node, future, timeout_sec=timeout_sec)
        if not future.done():
            raise SystemExit(f"the learner did not answer within {timeout_sec:.0f} s")
        response = future.result()
        if not response.success:
            raise SystemExit(f"evaluation refused: {response.message}")
        return [(s.task, s.successes, s.episodes) for s in response.scores]
    finally:
        rclpy.try_shutdown()

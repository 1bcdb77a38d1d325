"""learner_node: the policies, and the Evaluate (and later Train) requests on them.

Services: ``learner/evaluate`` (glocal_interfaces/srv/Evaluate),
``learner/list_policies``. Topic: ``glocal/evaluations`` (every evaluation's
scores, for the record). The learner never imports pybullet: it acts through
the sim node's batched ``sim/reset`` and ``sim/step``.

Policies: ``random``, the learner's policy store (``policy_dir``) and the
shipped A0 ``prior``; ``learner/copy_policy`` copies one into the store.
Issue "Learner" adds SAC training (the ``learner/train`` action).
"""

from __future__ import annotations

import os
import threading
from datetime import datetime
from pathlib import Path

from builtin_interfaces.msg import Time
from glocal_interfaces.msg import EvaluationResult, PolicyInfo, TaskScore
from glocal_interfaces.srv import CopyPolicy, Evaluate, ListPolicies
from rclpy.callback_groups import MutuallyExclusiveCallbackGroup
from rclpy.node import Node

from glocal_ros.paths import assets_dir
from glocal_ros.tasks import validate_tasks
from learner_node.evaluation import evaluate
from learner_node.policies import PolicyRegistry
from learner_node.policy_store import PolicyStore
from learner_node.sim_client import SimClient
from node_common import names, qos
from node_common.params import declare
from node_common.runner import spin_node
from node_common.services import answers_errors

DEFAULT_EVAL_EPISODES = 100


class LearnerNode(Node):
    def __init__(self) -> None:
        super().__init__("learner_node")
        self.max_eval_episodes = declare(self, "max_eval_episodes", 10_000, "largest episodes-per-task of a request",
                                         min_value=1, max_value=1_000_000)
        self.sim_timeout = declare(self, "sim_timeout_sec", 30.0, "how long to wait for the sim node's services",
                                   min_value=0.1, max_value=3600.0)
        seed = declare(self, "seed", 0, "seed of the learner's random streams", min_value=0, max_value=2**31 - 1)
        policy_dir = declare(self, "policy_dir", str(default_policy_dir()), "the learner's policy store")

        self.policies = PolicyRegistry(PolicyStore(Path(policy_dir)), [PolicyStore(assets_dir() / "priors")], seed)
        self.sim = SimClient(self, timeout_sec=self.sim_timeout)
        # One request at a time drives the sim's envs.
        self.sim_lock = threading.Lock()
        self.learner_steps = 0

        requests = MutuallyExclusiveCallbackGroup()
        self.create_service(Evaluate, names.LEARNER_EVALUATE, self.on_evaluate, callback_group=requests)
        self.create_service(ListPolicies, names.LEARNER_LIST_POLICIES, self.on_list_policies)
        self.create_service(CopyPolicy, names.LEARNER_COPY_POLICY, self.on_copy_policy)
        self.evaluations_pub = self.create_publisher(EvaluationResult, names.EVALUATIONS, qos.EVENTS)
        self.get_logger().info(f"policies: {', '.join(self.policies.names())}")

    @answers_errors("evaluate")
    def on_evaluate(self, request: Evaluate.Request, response: Evaluate.Response) -> Evaluate.Response:
        episodes = request.episodes or DEFAULT_EVAL_EPISODES
        if not request.tasks:
            raise ValueError("no task to evaluate")
        tasks = validate_tasks(request.tasks)
        if len(set(tasks)) != len(tasks):
            raise ValueError(f"tasks repeat: {list(tasks)}")
        if episodes > self.max_eval_episodes:
            raise ValueError(f"episodes {episodes} above max_eval_episodes {self.max_eval_episodes}")
        policy = self.policies.load(request.policy)
        with self.sim_lock:
            self.sim.wait_for_sim(self.sim_timeout)
            scores = evaluate(
                self.sim, policy, tasks, episodes, policy_name=request.policy,
                seed=None if request.seed < 0 else request.seed, global_step=self.learner_steps,
            )
        response.scores = [TaskScore(task=s.task, successes=s.successes, episodes=s.episodes) for s in scores]
        response.success = True
        if len(scores) == 1:
            self.policies.record_score(request.policy, scores[0].task, scores[0].successes)
        self._publish_evaluation(request.policy, response.scores, "request")
        self.get_logger().info(
            f"evaluated {request.policy}: " + ", ".join(f"{s.task} {s.successes}/{s.episodes}" for s in scores)
        )
        return response

    def on_list_policies(self, request: ListPolicies.Request, response: ListPolicies.Response):
        response.policies = [
            PolicyInfo(name=r.name, task=r.task, parent=r.parent, steps_trained=r.steps_trained,
                       last_score=r.last_score, last_score_task=r.last_score_task,
                       updated=Time(sec=_epoch_seconds(r.updated)))
            for r in self.policies.records()
        ]
        return response

    @answers_errors("copy_policy")
    def on_copy_policy(self, request: CopyPolicy.Request, response: CopyPolicy.Response) -> CopyPolicy.Response:
        self.policies.copy(request.source, request.destination)
        response.success = True
        self.get_logger().info(f"copied policy {request.source} to {request.destination}")
        return response

    def _publish_evaluation(self, policy: str, scores: list[TaskScore], purpose: str) -> None:
        result = EvaluationResult(policy=policy, learner_steps=self.learner_steps, purpose=purpose, scores=scores)
        result.header.stamp = self.get_clock().now().to_msg()
        self.evaluations_pub.publish(result)


def default_policy_dir() -> Path:
    """``$ROS_HOME/glocal_ros/policies`` (ROS_HOME defaults to ~/.ros)."""
    return Path(os.environ.get("ROS_HOME", Path.home() / ".ros")) / "glocal_ros" / "policies"


def _epoch_seconds(iso_time: str) -> int:
    return int(datetime.fromisoformat(iso_time).timestamp())


def main(args=None) -> int:
    # Evaluate blocks on sim/step responses, which another thread must take.
    return spin_node(LearnerNode, args, num_threads=4)


if __name__ == "__main__":
    raise SystemExit(main())

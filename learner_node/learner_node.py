"""learner_node: the policies, and the Evaluate (and later Train) requests on them.

Services: ``learner/evaluate`` (glocal_interfaces/srv/Evaluate),
``learner/list_policies``. Topic: ``glocal/evaluations`` (every evaluation's
scores, for the record). The learner never imports pybullet: it acts through
the sim node's batched ``sim/reset`` and ``sim/step``.

Issue "Learner" adds SAC training (the ``learner/train`` action), the policy
store on disk and ``learner/copy_policy``.
"""

from __future__ import annotations

import threading

from glocal_interfaces.msg import EvaluationResult, PolicyInfo, TaskScore
from glocal_interfaces.srv import Evaluate, ListPolicies
from rclpy.callback_groups import MutuallyExclusiveCallbackGroup
from rclpy.node import Node

from glocal_ros.tasks import validate_tasks
from learner_node.evaluation import evaluate
from learner_node.policies import PolicyRegistry
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

        self.policies = PolicyRegistry(seed)
        self.sim = SimClient(self, timeout_sec=self.sim_timeout)
        # One request at a time drives the sim's envs.
        self.sim_lock = threading.Lock()
        self.learner_steps = 0

        requests = MutuallyExclusiveCallbackGroup()
        self.create_service(Evaluate, names.LEARNER_EVALUATE, self.on_evaluate, callback_group=requests)
        self.create_service(ListPolicies, names.LEARNER_LIST_POLICIES, self.on_list_policies)
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
        self._publish_evaluation(request.policy, response.scores, "request")
        self.get_logger().info(
            f"evaluated {request.policy}: " + ", ".join(f"{s.task} {s.successes}/{s.episodes}" for s in scores)
        )
        return response

    def on_list_policies(self, request: ListPolicies.Request, response: ListPolicies.Response):
        response.policies = [PolicyInfo(name=name, last_score=-1.0) for name in self.policies.names()]
        return response

    def _publish_evaluation(self, policy: str, scores: list[TaskScore], purpose: str) -> None:
        result = EvaluationResult(policy=policy, learner_steps=self.learner_steps, purpose=purpose, scores=scores)
        result.header.stamp = self.get_clock().now().to_msg()
        self.evaluations_pub.publish(result)


def main(args=None) -> int:
    # Evaluate blocks on sim/step responses, which another thread must take.
    return spin_node(LearnerNode, args, num_threads=4)


if __name__ == "__main__":
    raise SystemExit(main())

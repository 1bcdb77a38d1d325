"""curriculum_node: runs a curriculum strategy against the learner.

Publishes ``glocal/curriculum_state`` and ``glocal/task_assignment`` (both
reliable, transient-local). Calls ``learner/evaluate``.

Now: the first decision of GloCAL's Algorithm 1 (evaluate pi_curr on the
remaining tasks, cluster by score, pick C_1, its global and local tasks),
published as state and as the global task's assignment; then the node ends,
exit code 0 (1 when the learner could not be reached). Issue "Curriculum"
adds the training loop through ``learner/train``, the baselines and
ablations, and resuming a run.
"""

from __future__ import annotations

import threading
import traceback

from glocal_interfaces.msg import CurriculumState, TaskAssignment, TaskCluster
from glocal_interfaces.srv import Evaluate
from rclpy.callback_groups import ReentrantCallbackGroup
from rclpy.duration import Duration
from rclpy.node import Node

from glocal_ros.clustering import Clustering, cluster_tasks, split_global_local
from glocal_ros.tasks import parse_task_list
from node_common import names, qos
from node_common.calls import ServiceCallError, call_checked, wait_for_service
from node_common.params import declare
from node_common.runner import spin_node

STRATEGIES = ("glocal", "random", "alp_gmm_250", "alp_gmm_10", "glocal_no_global", "glocal_random_cluster")
IMPLEMENTED_STRATEGIES = ("glocal",)


class CurriculumNode(Node):
    def __init__(self) -> None:
        super().__init__("curriculum_node")
        self.strategy = declare(self, "strategy", "glocal", f"one of {', '.join(STRATEGIES)}")
        if self.strategy not in STRATEGIES:
            raise ValueError(f"unknown strategy {self.strategy!r}: expected one of {', '.join(STRATEGIES)}")
        if self.strategy not in IMPLEMENTED_STRATEGIES:
            raise ValueError(f"strategy {self.strategy!r} is not implemented yet (issue 'Curriculum')")
        self.tasks = parse_task_list(declare(self, "tasks", "all", "tasks of the run: 'all' or e.g. 'A0,A1,B0'"))
        self.initial_policy = declare(self, "initial_policy", "prior", "pi_init, the policy every strategy starts from")
        self.eval_episodes = declare(self, "eval_episodes", 100, "S-bar: evaluation episodes per task",
                                     min_value=1, max_value=100_000)
        self.k_min = declare(self, "k_min", 2, "fewest k-means clusters tried", min_value=2, max_value=49)
        self.k_max = declare(self, "k_max", 6, "most k-means clusters tried", min_value=2, max_value=49)
        self.seed = declare(self, "seed", 0, "seed of clustering and sampling", min_value=0, max_value=2**31 - 1)
        self.learner_timeout = declare(self, "learner_timeout_sec", 600.0, "how long to wait for the learner",
                                       min_value=0.1, max_value=86_400.0)
        if self.k_min > self.k_max:
            raise ValueError(f"k_min {self.k_min} is above k_max {self.k_max}")

        self.evaluate_client = self.create_client(Evaluate, names.LEARNER_EVALUATE,
                                                  callback_group=ReentrantCallbackGroup())
        self.state_pub = self.create_publisher(CurriculumState, names.CURRICULUM_STATE, qos.LATCHED)
        self.assignment_pub = self.create_publisher(TaskAssignment, names.TASK_ASSIGNMENT, qos.LATCHED)
        self.assignment_seq = 0
        self.exit_code = 0
        self.state = CurriculumState(strategy=self.strategy, status=CurriculumState.STATUS_STARTING,
                                     remaining_tasks=list(self.tasks), current_policy=self.initial_policy)
        self.publish_state()
        self._worker = threading.Thread(target=self.run, name="curriculum", daemon=True)
        self._worker.start()

    def run(self) -> None:
        try:
            wait_for_service(self.evaluate_client, self.learner_timeout)
            self.state.iteration = 1
            self.state.status = CurriculumState.STATUS_EVALUATING
            self.publish_state()
            scores = self.evaluate(self.initial_policy, self.state.remaining_tasks)
            clustering = cluster_tasks(scores, self.k_min, self.k_max, self.seed)
            self.decide(clustering)
        except ServiceCallError as error:
            self.get_logger().fatal(f"curriculum stopped: {error}")
            self.exit_code = 1
        except Exception:  # noqa: BLE001 - the run must end the node, not leave it hanging
            self.get_logger().fatal(f"curriculum failed:\n{traceback.format_exc()}")
            self.exit_code = 1
        self.finish()

    def finish(self) -> None:
        """End the node once subscribers (the recorder) have acknowledged the last state."""
        for publisher in (self.state_pub, self.assignment_pub):
            publisher.wait_for_all_acked(Duration(seconds=5.0))
        # Shutting the context down ends the executor's spin, and so main().
        self.context.try_shutdown()

    def evaluate(self, policy: str, tasks: list[str]) -> dict[str, float]:
        request = Evaluate.Request(policy=policy, tasks=tasks, episodes=self.eval_episodes, seed=-1)
        response = call_checked(self.evaluate_client, request, timeout_sec=self.learner_timeout)
        return {s.task: float(s.successes) for s in response.scores}

    def decide(self, clustering: Clustering) -> None:
        best = clustering.clusters[0]
        global_task, local_tasks = split_global_local(best)
        self.state.silhouette = clustering.silhouette
        self.state.clusters = [
            TaskCluster(tasks=list(c.tasks), scores=list(c.scores), mean_score=c.mean_score)
            for c in clustering.clusters
        ]
        self.state.chosen_cluster = 0
        self.state.global_task, self.state.local_tasks = global_task, local_tasks
        self.state.current_task = global_task
        self.state.status = CurriculumState.STATUS_TRAINING_GLOBAL
        self.publish_state()
        self.publish_assignment(TaskAssignment.ROLE_GLOBAL, global_task, f"G{self.state.iteration}")
        self.get_logger().info(
            f"iteration {self.state.iteration}: {len(clustering.clusters)} clusters, "
            f"C1 = {', '.join(best.tasks)}, global task {global_task}"
        )

    def publish_state(self) -> None:
        self.state.header.stamp = self.get_clock().now().to_msg()
        self.state_pub.publish(self.state)

    def publish_assignment(self, role: int, task: str, output_policy: str) -> None:
        assignment = TaskAssignment(
            seq=self.assignment_seq, iteration=self.state.iteration, role=role, task=task,
            initial_policy=self.state.current_policy, output_policy=output_policy,
        )
        assignment.header.stamp = self.get_clock().now().to_msg()
        self.assignment_seq += 1
        self.assignment_pub.publish(assignment)


def main(args=None) -> int:
    return spin_node(CurriculumNode, args)


if __name__ == "__main__":
    raise SystemExit(main())

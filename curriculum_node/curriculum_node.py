"""curriculum_node: runs a curriculum strategy against the learner node.

``ros2 run glocal_ros curriculum_node --ros-args -p strategy:=glocal`` runs
one of glocal, random, alp_gmm_250, alp_gmm_10, glocal_no_global,
glocal_random_cluster (``glocal_ros.curriculum``) through ``learner/train``,
``learner/evaluate`` and ``learner/copy_policy``, publishes
``glocal/curriculum_state`` after every decision and ``glocal/task_assignment``
for every goal (both reliable, transient-local), and ends when the run does:
exit code 0, or 1 when it failed.

The run resumes: every answered learner call is journaled in ``state_dir``
(``glocal_ros.curriculum.journal``), so a node started again with the same
parameters and ``state_dir`` goes on where the last one stopped;
``state_dir/state.json`` holds the latest state for people and scripts.
Replaying a long journal takes minutes (ALP-GMM-10 refits its sampler at
each of thousands of answers), and nothing is published meanwhile (replayed
decisions were published by the node that made them), so the replay reports
itself on ``diagnostics`` (``diagnostic_msgs``; replayed calls of all, every
``REPLAY_REPORT_SEC`` and at its end): the launcher's watchdog hears it.

Several pairs: ``learner_namespaces`` (comma-separated, e.g.
``pair0,pair1``; default "", the learner in this node's own namespace) names
the learners, one ``RosLearner`` each. Relative names resolve under this
node's namespace, as every ROS name does (``pair1`` of a node in ``/robot1``
is ``/robot1/pair1``; ``/`` is the root), so that a launch file's
``PushRosNamespace`` moves the curriculum and its pairs together. With ``parallel_locals`` GloCAL sends
its local tasks to whichever is free (``glocal_ros.curriculum.glocal``); the
journal says which learner (its index in ``learner_namespaces``) answered
each call; a call whose learner left the graph and was not back within
``learner_away_sec`` goes to the next free one (a Train goal resumes there
from its checkpoint in the shared policy store), and that learner gets
calls again once it is back. Without ``parallel_locals`` the run is
sequential and uses the first learner only. A run starts (and resumes) once
its learners run no goal: the goals a killed curriculum node left running
end first, and the same goals sent again get their outcome instead of
running a second time.
"""

from __future__ import annotations

import json
import threading
import time
import traceback
from dataclasses import MISSING, asdict, fields
from pathlib import Path

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from glocal_interfaces.msg import CurriculumState, TaskAssignment, TaskCluster
from rclpy.duration import Duration
from rclpy.node import Node

from glocal_ros.curriculum.codes import BASELINE_TASKS
from glocal_ros.curriculum.journal import CallJournal
from glocal_ros.files import atomic_write
from glocal_ros.paths import ros_home
from glocal_ros.sim_contract import DEFAULT_EPISODE_STEPS
from glocal_ros.curriculum.run import Assignment, Run, RunConfig, RunState
from glocal_ros.curriculum.strategies import STRATEGIES, run_strategy
from glocal_ros.tasks import parse_task_list
from glocal_ros.topics import REPLAY_STATUS
from curriculum_node.ros_learner import LearnerStopped, RosLearner
from node_common import names, qos
from node_common.calls import ServiceCallError
from node_common.params import declare
from node_common.runner import spin_node

#: The most a stopping node waits, per publisher, first for the subscribers the graph lists to
#: match, then for them to acknowledge its latest state and assignment. Each wait has its own
#: budget: a slow match on a loaded machine must not leave none for the acknowledgement.
DRAIN_SEC = 20.0
#: How often a replay reports its progress: well within the launcher's silence allowance.
REPLAY_REPORT_SEC = 2.0

_DEFAULTS = {f.name: f.default for f in fields(RunConfig) if f.default is not MISSING}


class CurriculumNode(Node):
    def __init__(self) -> None:
        super().__init__("curriculum_node")
        self.config = self._declare_run_config()
        self.max_episode_steps = declare(self, "max_episode_steps", DEFAULT_EPISODE_STEPS,
                                         "T of the sim's envs: the baselines size their goals with it",
                                         min_value=1, max_value=100_000)
        self.learner_timeout = declare(self, "learner_timeout_sec", 600.0,
                                       "how long to wait for the learner to answer a request",
                                       min_value=0.1, max_value=86_400.0)
        state_dir = declare(self, "state_dir", "", "the run's journal and state.json; "
                            "default $ROS_HOME/glocal_ros/runs/<strategy>-seed<seed>")
        self.state_dir = Path(state_dir) if state_dir else default_state_dir(self.config.run_id)

        self.state_pub = self.create_publisher(CurriculumState, names.CURRICULUM_STATE, qos.LATCHED)
        self.assignment_pub = self.create_publisher(TaskAssignment, names.TASK_ASSIGNMENT, qos.LATCHED)
        namespaces = declare(self, "learner_namespaces", "", "the learners, comma-separated namespaces "
                             "(e.g. pair0,pair1; / for the root); '' for this node's own")
        away = declare(self, "learner_away_sec", 30.0, "parallel_locals over several learners: how long one "
                       "may be out of the graph (noticed some 20 s after a kill) before its call goes to another",
                       min_value=0.0, max_value=86_400.0)
        self.learner_namespaces = learner_namespace_list(namespaces, self.get_namespace())
        pooled = self.config.parallel_locals and len(self.learner_namespaces) > 1
        self.learners = [RosLearner(self, self.learner_timeout, namespace=namespace,
                                    away_sec=away if pooled else None)
                         for namespace in self.learner_namespaces]
        self.diagnostics_pub = self.create_publisher(DiagnosticArray, names.DIAGNOSTICS, qos.EVENTS)
        self._replay_reported = self._replay_started = 0.0  # set by the first replayed call
        self.journal = CallJournal(self.state_dir / "journal.jsonl", self.config.journal_settings(),
                                   on_replayed=self.replayed)
        if self.journal.replaying:
            self.get_logger().info(f"resuming {self.config.run_id} from {self.journal.path}: "
                                   f"{self.journal.to_replay} answered calls to replay")
        self.exit_code = 0
        self._worker = threading.Thread(target=self.run, name="curriculum", daemon=True)
        self._worker.start()

    def _declare_run_config(self) -> RunConfig:
        strategy = declare(self, "strategy", "glocal", f"one of {', '.join(STRATEGIES)}")
        if strategy not in STRATEGIES:
            raise ValueError(f"unknown strategy {strategy!r}: expected one of {', '.join(STRATEGIES)}")
        tasks = parse_task_list(declare(self, "tasks", "all", "tasks of the run: 'all' or e.g. 'A0,A1,B0'"))
        positive = dict(min_value=1, max_value=10**12)
        return RunConfig(
            strategy=strategy,
            tasks=tuple(tasks),
            initial_policy=declare(self, "initial_policy", _DEFAULTS["initial_policy"],
                                   "pi_init, the policy every strategy starts from"),
            seed=declare(self, "seed", 0, "seed of clustering and sampling", min_value=0, max_value=2**31 - 1),
            step_budget=declare(self, "step_budget", _DEFAULTS["step_budget"],
                                "training env steps of the whole run", **positive),
            task_step_budget=declare(self, "task_step_budget", _DEFAULTS["task_step_budget"],
                                     "GloCAL: most training env steps per task attempt", **positive),
            eval_episodes=declare(self, "eval_episodes", _DEFAULTS["eval_episodes"],
                                  "S-bar: evaluation episodes per task", min_value=1, max_value=100_000),
            threshold=declare(self, "threshold", _DEFAULTS["threshold"],
                              "B: a task is learned when its score is above it", min_value=0.0, max_value=1e5),
            eval_interval=declare(self, "eval_interval", _DEFAULTS["eval_interval"],
                                  "GloCAL: training env steps between checks of score > B", **positive),
            k_min=declare(self, "k_min", _DEFAULTS["k_min"], "fewest k-means clusters tried",
                          min_value=2, max_value=49),
            k_max=declare(self, "k_max", _DEFAULTS["k_max"], "most k-means clusters tried",
                          min_value=2, max_value=49),
            max_iter=declare(self, "max_iter", _DEFAULTS["max_iter"], "GloCAL: most iterations", **positive),
            milestone_interval=declare(self, "milestone_interval", _DEFAULTS["milestone_interval"],
                                       "training env steps between milestones", **positive),
            baseline_eval_interval=declare(self, "baseline_eval_interval", _DEFAULTS["baseline_eval_interval"],
                                           "baselines: training env steps between evaluations", **positive),
            baseline_chunk_episodes=declare(self, "baseline_chunk_episodes", _DEFAULTS["baseline_chunk_episodes"],
                                            "random: episodes per Train goal", **positive),
            baseline_tasks=declare(self, "baseline_tasks", _DEFAULTS["baseline_tasks"],
                                   f"baselines draw from: {' or '.join(BASELINE_TASKS)} tasks"),
            parallel_locals=declare(self, "parallel_locals", _DEFAULTS["parallel_locals"],
                                    "GloCAL: local tasks on free learners at once, overlapping the next iteration"),
        )

    def run(self) -> None:
        try:
            pool = self.learners if self.config.parallel_locals else self.learners[:1]
            for learner in pool:
                learner.wait_until_ready()
            # With parallel_locals a call whose learner left goes to the next free one; without, the loss
            # ends the run (the same command resumes it).
            run = Run(self.config, pool[0], self, learners=pool, journal=self.journal,
                      resend_on=(ServiceCallError,) if self.config.parallel_locals else ())
            run_strategy(run, self.max_episode_steps)
            self.get_logger().info(
                f"{self.config.run_id} finished: {len(run.state.learned_tasks)}/{len(self.config.tasks)} tasks "
                f"learned in {run.state.total_steps} training steps"
            )
        except LearnerStopped as stopped:
            self.get_logger().info(f"run interrupted ({stopped}); the same command resumes it")
        except Exception:  # noqa: BLE001 - the run must end the node, not leave it hanging
            self.get_logger().fatal(f"curriculum failed:\n{traceback.format_exc()}")
            self.exit_code = 1
        self.finish()

    def finish(self) -> None:
        """End the node once subscribers (the recorder) have acknowledged the last state."""
        if self.context.ok():
            self.drain()
        # Shutting the context down ends the executor's spin, and so main().
        self.context.try_shutdown()

    def drain(self) -> None:
        """Deliver the latest state and assignment to every subscriber the graph lists (at most
        ``DRAIN_SEC`` to match and ``DRAIN_SEC`` to acknowledge), on Ctrl-C as at the end: a recorder that has
        not matched this node's publishers yet (a loaded machine) would otherwise close its bag without them."""
        for publisher in (self.state_pub, self.assignment_pub):
            deadline = time.monotonic() + DRAIN_SEC
            while (publisher.get_subscription_count() < self.count_subscribers(publisher.topic_name)
                   and time.monotonic() < deadline):
                time.sleep(0.05)
            if not publisher.wait_for_all_acked(Duration(seconds=DRAIN_SEC)):
                self.get_logger().warning(
                    f"{publisher.topic_name}: not every subscriber acknowledged the last message within "
                    f"{DRAIN_SEC:.0f} s; it may miss it")

    def replayed(self, replayed: int, total: int) -> None:
        """The journal's replay so far, on ``diagnostics`` (see the module doc)."""
        now = time.monotonic()
        if replayed == 1:  # the replay starts once the learners are ready, not when the node does
            self._replay_started = now
        elif replayed < total and now - self._replay_reported < REPLAY_REPORT_SEC:
            return
        self._replay_reported = now
        status = DiagnosticStatus(level=DiagnosticStatus.OK,
                                  name=f"{self.get_fully_qualified_name()}: {REPLAY_STATUS}",
                                  message=f"resuming: replayed {replayed} of {total} answered calls",
                                  values=[KeyValue(key="replayed", value=str(replayed)),
                                          KeyValue(key="to_replay", value=str(total))])
        message = DiagnosticArray(status=[status])
        message.header.stamp = self.get_clock().now().to_msg()
        self.diagnostics_pub.publish(message)
        if replayed == total:
            self.get_logger().info(f"replayed {total} answered calls in {now - self._replay_started:.0f} s; "
                                   "live from here")

    # RunObserver: what the run reports, published. Replayed decisions were
    # published by the node that made them, so only live ones go out.
    def state_changed(self, state: RunState) -> None:
        if self.journal.replaying:
            return
        self.state_pub.publish(state_message(state, self.get_clock().now().to_msg()))
        text = json.dumps(asdict(state), indent=1).encode()
        atomic_write(self.state_dir / "state.json", lambda stream: stream.write(text))

    def assigned(self, assignment: Assignment) -> None:
        if self.journal.replaying:
            return
        message = TaskAssignment(
            seq=assignment.seq, iteration=assignment.iteration, role=assignment.role, task=assignment.task,
            episode_tasks=list(assignment.episode_tasks), initial_policy=assignment.initial_policy,
            output_policy=assignment.output_policy, step_budget=assignment.step_budget,
        )
        message.header.stamp = self.get_clock().now().to_msg()
        self.assignment_pub.publish(message)
        self.get_logger().info(
            f"iteration {assignment.iteration}: {assignment.output_policy} from {assignment.initial_policy} on "
            f"{assignment.task or ','.join(sorted(set(assignment.episode_tasks)))}, {assignment.step_budget} steps"
        )


def state_message(state: RunState, stamp) -> CurriculumState:
    message = CurriculumState(
        run_id=state.run_id, seed=state.seed, strategy=state.strategy, status=state.status,
        iteration=state.iteration, total_steps=state.total_steps, step_budget=state.step_budget,
        evaluation_episodes=state.evaluation_episodes, silhouette=state.silhouette,
        clusters=[TaskCluster(tasks=list(tasks), scores=list(scores), mean_score=sum(scores) / len(scores))
                  for tasks, scores in state.clusters],
        chosen_cluster=state.chosen_cluster, global_task=state.global_task, local_tasks=list(state.local_tasks),
        current_task=state.current_task, current_policy=state.current_policy,
        learned_tasks=list(state.learned_tasks), learned_policies=list(state.learned_policies),
        learned_at_steps=list(state.learned_at_steps), remaining_tasks=list(state.remaining_tasks),
        milestone_interval=state.milestone_interval, milestone_steps=list(state.milestone_steps),
        milestone_learned=list(state.milestone_learned),
    )
    message.header.stamp = stamp
    return message


def learner_namespace_list(text: str, node_namespace: str = "/") -> list[str]:
    """``learner_namespaces`` as absolute namespaces: a relative one under ``node_namespace`` (the node's), an
    absolute one as it is, ``/`` for the root; "" alone (the default) is ``[""]``, the node's own names as they
    are. Repeats refused."""
    if not text.strip():
        return [""]
    base = node_namespace.rstrip("/")
    namespaces = []
    for part in text.split(","):
        name = part.strip()
        if name.startswith("/"):
            namespaces.append("/" + name.strip("/"))
        else:
            namespaces.append(f"{base}/{name.strip('/')}" if name.strip("/") else base or "/")
    if len(set(namespaces)) != len(namespaces):
        raise ValueError(f"learner_namespaces repeat: {text!r}")
    return namespaces


def default_state_dir(run_id: str) -> Path:
    """``$ROS_HOME/glocal_ros/runs/<run_id>`` (ROS_HOME defaults to ~/.ros)."""
    return ros_home() / "glocal_ros" / "runs" / run_id


def main(args=None) -> int:
    # Learner calls block the worker thread while the executor takes their answers.
    return spin_node(CurriculumNode, args, num_threads=2)


if __name__ == "__main__":
    raise SystemExit(main())

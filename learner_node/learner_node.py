"""learner_node: the policies, SAC training on them, and their evaluation.

Action ``learner/train`` (glocal_interfaces/action/Train): SAC from a stored
policy on a task, with feedback, cancel, and a checkpoint that the same goal
sent again after a crash continues from. Services ``learner/evaluate``,
``learner/list_policies``, ``learner/copy_policy``. Topics
``glocal/evaluations`` (every evaluation's scores) and
``glocal/training_progress``. The learner never imports pybullet: it acts
through the sim node's batched ``sim/reset`` and ``sim/step``.

One sim serves one job at a time. An Evaluate request that arrives while a
Train goal runs is served between two training steps (the goal pauses, then
goes on); a second Train goal is rejected while one runs (taken under a lock
in the goal callback, as ros2/examples' ``server_single_goal.py`` guards its
goal, so two goals sent at the same moment cannot both be accepted). A goal
the learner cannot run is accepted and aborted at once with the reason: the
action protocol gives a rejection no message, and the client must tell
"busy, offer it again" from "never send this".

Policies: ``random``, the learner's policy store (``policy_dir``) and the
shipped A0 ``prior`` of the learner's profile (``learner_profile``:
``learner_node.profiles``); ``learner/copy_policy`` copies one into the
store. A Train goal refuses a policy of another profile. ``learner/evaluate``
scores a policy as a Train goal from it starts it, so the two agree.
"""

from __future__ import annotations

import threading
import time
from collections import deque
from datetime import datetime
from pathlib import Path
from typing import Callable

from builtin_interfaces.msg import Time
from glocal_interfaces.action import Train
from glocal_interfaces.msg import EpisodeOutcome, EvaluationResult, PolicyInfo, TaskScore, TrainingProgress
from glocal_interfaces.srv import CopyPolicy, Evaluate, ListPolicies
from rclpy.action import ActionServer, CancelResponse, GoalResponse
from rclpy.callback_groups import MutuallyExclusiveCallbackGroup, ReentrantCallbackGroup
from rclpy.node import Node

from glocal_ros.curriculum.learner import PAPER_EVAL_EPISODES, TrainGoal
from glocal_ros.tasks import check_tasks
from learner_node.evaluation import evaluate
from learner_node.policies import PolicyExists, PolicyRegistry
from learner_node.policy_store import PolicyStore, default_policy_dir
from learner_node.profiles import DEFAULT_PROFILE, PROFILES, learner_profile
from learner_node.sac_settings import FINE_TUNING_RECIPES
from learner_node.sim_client import SimClient
from learner_node.training import (CHECKPOINTS_DIR, DEFAULT_MAX_STEP_BUDGET, GoalFailed, Trainer, TrainProgress,
                                   check_goal)
from node_common import names, qos
from node_common.params import declare
from node_common.runner import spin_node
from node_common.services import REFUSED, answers_errors
from node_common.train_goal import goal_from_message

JOB_POLL_SEC = 0.02
CLOSE_TIMEOUT_SEC = 10.0


class SimJob:
    """Work for the sim, run by whichever thread holds it (see ``LearnerNode.run_on_sim``)."""

    def __init__(self, work: Callable[[], object]):
        self.work = work
        self.done = threading.Event()
        self.result: object = None
        self.error: BaseException | None = None

    def run(self) -> None:
        try:
            self.result = self.work()
        except BaseException as error:  # noqa: BLE001 - handed to the waiting caller
            self.error = error
        self.done.set()


class LearnerNode(Node):
    def __init__(self) -> None:
        super().__init__("learner_node")
        self.max_eval_episodes = declare(self, "max_eval_episodes", 10_000, "largest episodes-per-task of a request",
                                         min_value=1, max_value=1_000_000)
        self.sim_timeout = declare(self, "sim_timeout_sec", 30.0, "how long to wait for the sim node's services",
                                   min_value=0.1, max_value=3600.0)
        seed = declare(self, "seed", 0, "seed of the learner's random streams", min_value=0, max_value=2**31 - 1)
        policy_dir = declare(self, "policy_dir", str(default_policy_dir()), "the learner's policy store")
        self.max_step_budget = declare(self, "max_step_budget", DEFAULT_MAX_STEP_BUDGET,
                                       "largest step_budget of a Train goal", min_value=1, max_value=2**62)
        checkpoint_interval = declare(self, "checkpoint_interval", 5_000,
                                      "training env steps between checkpoints of a Train goal",
                                      min_value=1, max_value=10_000_000)
        profile_name = declare(self, "learner_profile", DEFAULT_PROFILE, "how policies learn and are scored: "
                               f"one of {', '.join(PROFILES)} (learner_node/profiles.py)")
        tensorboard_dir = declare(self, "tensorboard_dir", "", "where each Train goal writes its training curves "
                                  "(TensorBoard events and a CSV, in a folder named after its output policy; "
                                  "learner_node/scalars.py); empty: nowhere")
        recipe = declare(self, "fine_tuning", "", "another way for a Train goal to start from a stored policy, "
                         "where the profile allows one (glocal_ros: any of "
                         f"{', '.join(FINE_TUNING_RECIPES)}); empty: the profile's own")
        try:
            profile = learner_profile(profile_name)
        except ValueError as error:
            raise ValueError(f"parameter learner_profile: {error}") from None
        try:
            fine_tuning = profile.with_recipe(recipe)
        except ValueError as error:
            raise ValueError(f"parameter fine_tuning: {error}") from None

        self.policies = PolicyRegistry(PolicyStore(Path(policy_dir)), [PolicyStore(profile.shipped_priors())], seed)
        self.sim = SimClient(self, timeout_sec=self.sim_timeout)
        self.trainer = Trainer(self.sim, self.policies, Path(policy_dir) / CHECKPOINTS_DIR, seed, checkpoint_interval,
                               profile=profile, fine_tuning=fine_tuning,
                               tensorboard_dir=Path(tensorboard_dir) if tensorboard_dir else None)
        # Whoever holds sim_lock runs the queued jobs: a training goal between
        # its steps, otherwise the requester itself.
        self.sim_lock = threading.Lock()
        self._jobs: deque[SimJob] = deque()
        self._jobs_lock = threading.Lock()
        self._goal_lock = threading.Lock()
        self._goal_taken = False  # under _goal_lock: from a goal's acceptance to the end of its execution

        requests = MutuallyExclusiveCallbackGroup()
        self.create_service(Evaluate, names.LEARNER_EVALUATE, self.on_evaluate, callback_group=requests)
        self.create_service(ListPolicies, names.LEARNER_LIST_POLICIES, self.on_list_policies)
        self.create_service(CopyPolicy, names.LEARNER_COPY_POLICY, self.on_copy_policy)
        self.evaluations_pub = self.create_publisher(EvaluationResult, names.EVALUATIONS, qos.EVENTS)
        self.progress_pub = self.create_publisher(TrainingProgress, names.TRAINING_PROGRESS, qos.EVENTS)
        self.train_server = ActionServer(
            self, Train, names.LEARNER_TRAIN, self.execute_train, goal_callback=self.on_train_goal,
            cancel_callback=lambda goal: CancelResponse.ACCEPT, callback_group=ReentrantCallbackGroup(),
        )
        # The goal status (transient-local) is published at every goal's change; published now too, so that
        # a client always finds one and reads from it whether this learner runs a goal (a curriculum node
        # started again waits for the goals its killed predecessor sent: curriculum_node.ros_learner).
        self.train_server._handle.publish_status()  # rclpy has no public call for it
        self.get_logger().info(f"policies: {', '.join(self.policies.names())}")

    @answers_errors("evaluate")
    def on_evaluate(self, request: Evaluate.Request, response: Evaluate.Response) -> Evaluate.Response:
        episodes = request.episodes or PAPER_EVAL_EPISODES
        if not request.tasks:
            raise ValueError("no task to evaluate")
        tasks = check_tasks(request.tasks)
        if len(set(tasks)) != len(tasks):
            raise ValueError(f"tasks repeat: {list(tasks)}")
        if episodes > self.max_eval_episodes:
            raise ValueError(f"episodes {episodes} above max_eval_episodes {self.max_eval_episodes}")
        seed = None if request.seed < 0 else request.seed
        policy = self.trainer.evaluation_policy(request.policy, tasks, seed)
        scores = self.run_on_sim(lambda: evaluate(
            self.sim, policy, tasks, episodes, policy_name=request.policy, seed=seed,
            global_step=self.trainer.total_steps,
        ))
        response.scores = [TaskScore(task=s.task, successes=s.successes, episodes=s.episodes) for s in scores]
        response.success = True
        if len(scores) == 1:
            self.policies.record_score(request.policy, scores[0].task, scores[0].successes)
        self._publish_evaluation(request.policy, response.scores, "request")
        self.get_logger().info(
            f"evaluated {request.policy}: " + ", ".join(f"{s.task} {s.successes}/{s.episodes}" for s in scores)
        )
        return response

    def run_on_sim(self, work: Callable[[], object]) -> object:
        """Run ``work`` on the sim: between two steps of a running Train goal, or at once when idle."""
        job = SimJob(work)
        with self._jobs_lock:
            self._jobs.append(job)
        while not job.done.wait(JOB_POLL_SEC):
            if self.sim_lock.acquire(blocking=False):
                try:
                    self.sim.wait_for_sim(self.sim_timeout)
                    self.run_jobs()
                finally:
                    self.sim_lock.release()
        if job.error is not None:
            raise job.error
        return job.result

    def run_jobs(self) -> bool:
        """Run every queued job (the caller holds ``sim_lock``); True when there was one."""
        ran = False
        while True:
            with self._jobs_lock:
                if not self._jobs:
                    return ran
                job = self._jobs.popleft()
            job.run()
            ran = True

    def on_train_goal(self, goal: Train.Goal) -> GoalResponse:
        with self._goal_lock:
            if self._goal_taken:
                self.get_logger().warning(f"rejected Train goal for {goal.output_policy}: a goal is running")
                return GoalResponse.REJECT
            self._goal_taken = True  # every accepted goal is executed, which gives it back
        return GoalResponse.ACCEPT

    def execute_train(self, goal_handle) -> Train.Result:
        try:
            return self._execute_train(goal_handle)
        finally:
            with self._goal_lock:
                self._goal_taken = False

    def _execute_train(self, goal_handle) -> Train.Result:
        result = Train.Result()
        try:
            spec = goal_from_message(goal_handle.request)
            check_goal(spec, self.max_eval_episodes, self.max_step_budget)
            self.trainer.check_initial_policy(spec.initial_policy)  # unknown, or of another profile: here
            self.policies.check_writable(spec.output_policy)
        except (ValueError, KeyError) as error:
            result.message = str(error)
            self.get_logger().warning(f"refused Train goal: {result.message}")
            goal_handle.abort()
            return result

        try:
            with self.sim_lock:
                self.sim.wait_for_sim(self.sim_timeout)
                self.get_logger().info(f"training {spec.output_policy} from {spec.initial_policy} on "
                                       f"{spec.task or ','.join(spec.episode_tasks)}, budget {spec.step_budget}")
                outcome = self.trainer.train(
                    spec,
                    on_progress=lambda progress: self._publish_progress(goal_handle, spec, progress),
                    should_stop=lambda: self._stop_reason(goal_handle),
                    between_steps=self.run_jobs,
                    on_evaluation=lambda score, steps: self._publish_evaluation(
                        spec.output_policy, [TaskScore(task=score.task, successes=score.successes,
                                                       episodes=score.episodes)], "train"),
                )
                self.run_jobs()  # whatever arrived after the last step
        except Exception as error:  # noqa: BLE001 - the client gets the reason; the node keeps serving
            if not self.context.ok():  # no client can hear of it; the trainer saved its last whole step
                self.get_logger().info(f"{spec.output_policy}: stopped by the shutdown ({error})")
                return result
            if isinstance(error, GoalFailed):
                result.steps_used, result.message = error.steps_used, f"training failed: {error}"
            else:
                result.message = f"training failed: {type(error).__name__}: {error}"
            self.get_logger().error(result.message)
            goal_handle.abort()
            return result

        result.learned, result.steps_used, result.message = outcome.learned, outcome.steps_used, outcome.message
        if outcome.score is not None:
            result.score = TaskScore(task=outcome.score.task, successes=outcome.score.successes,
                                     episodes=outcome.score.episodes)
            self.policies.record_score(spec.output_policy, outcome.score.task, outcome.score.successes)
        self.get_logger().info(f"{spec.output_policy}: {outcome.message}")
        if not self.context.ok():
            return result  # shutting down: nothing can be published any more
        result.episodes = [EpisodeOutcome(task=e.task, episode_return=e.episode_return, length=e.length,
                                          success=e.success) for e in outcome.episodes]
        if goal_handle.is_cancel_requested:
            goal_handle.canceled()
        elif outcome.completed:
            goal_handle.succeed()
        else:
            goal_handle.abort()
        return result

    def close(self) -> None:
        """Give a running Train goal a moment to stop at a step and write its checkpoint."""
        deadline = time.monotonic() + CLOSE_TIMEOUT_SEC
        while self._goal_taken and time.monotonic() < deadline:
            time.sleep(0.05)

    def _stop_reason(self, goal_handle) -> str:
        if goal_handle.is_cancel_requested:
            return "canceled"
        if not self.context.ok():
            return "the learner is shutting down"
        return ""

    def _publish_progress(self, goal_handle, spec: TrainGoal, progress: TrainProgress) -> None:
        # float32 fields take Python floats only: with rclpy's field checks off (Jazzy's default) an
        # int reaches the C conversion unchecked and is read as 0.0 (the "every score is 0" bug).
        latest_score, recent_success_rate = float(progress.latest_score), float(progress.recent_success_rate)
        goal_handle.publish_feedback(Train.Feedback(
            steps=progress.steps, episodes=progress.episodes, recent_success_rate=recent_success_rate,
            latest_score=latest_score,
        ))
        message = TrainingProgress(
            output_policy=spec.output_policy, task=spec.task, goal_steps=progress.steps,
            step_budget=spec.step_budget, learner_steps=self.trainer.total_steps, episodes=progress.episodes,
            recent_success_rate=recent_success_rate, latest_score=latest_score,
            env_steps_per_second=float(progress.steps_per_second),
            mean_episode_return=float(progress.mean_episode_return), actor_loss=float(progress.actor_loss),
            critic_loss=float(progress.critic_loss), entropy_coefficient=float(progress.entropy_coefficient),
            q_parent_action=progress.instruments.q_parent_action,
            q_current_action=progress.instruments.q_current_action,
            action_distance=progress.instruments.action_distance, policy_entropy=progress.instruments.policy_entropy,
        )
        message.header.stamp = self.get_clock().now().to_msg()
        self.progress_pub.publish(message)

    def on_list_policies(self, request: ListPolicies.Request, response: ListPolicies.Response):
        response.policies = [
            PolicyInfo(name=r.name, task=r.task, parent=r.parent, steps_trained=r.steps_trained,
                       last_score=r.last_score, last_score_task=r.last_score_task,
                       updated=Time(sec=_epoch_seconds(r.updated)))
            for r in self.policies.records()
        ]
        return response

    @answers_errors("copy_policy", {PolicyExists: CopyPolicy.Response.ERROR_EXISTS,
                                    REFUSED: CopyPolicy.Response.ERROR_REFUSED,
                                    Exception: CopyPolicy.Response.ERROR_INTERNAL})
    def on_copy_policy(self, request: CopyPolicy.Request, response: CopyPolicy.Response) -> CopyPolicy.Response:
        self.policies.copy(request.source, request.destination)
        response.success = True
        self.get_logger().info(f"copied policy {request.source} to {request.destination}")
        return response

    def _publish_evaluation(self, policy: str, scores: list[TaskScore], purpose: str) -> None:
        result = EvaluationResult(policy=policy, learner_steps=self.trainer.total_steps, purpose=purpose, scores=scores)
        result.header.stamp = self.get_clock().now().to_msg()
        self.evaluations_pub.publish(result)


def _epoch_seconds(iso_time: str) -> int:
    return int(datetime.fromisoformat(iso_time).timestamp())


def main(args=None) -> int:
    # A Train goal and an Evaluate request block on sim/step responses, which
    # other threads must take.
    return spin_node(LearnerNode, args, num_threads=6)


if __name__ == "__main__":
    raise SystemExit(main())

"""sim_node: N PyBullet grasp envs behind a batched, lockstep reset/step service.

Services: ``sim/reset`` (glocal_interfaces/srv/ResetEnvs), ``sim/step``
(glocal_interfaces/srv/StepEnvs). Topics: ``glocal/episodes`` (one
EpisodeRecord per finished episode, reliable, seq-numbered), ``clock``, and
for viewers, at ``viewer_rate_hz``, the robot model, TF and the object of the
env named by ``viewer_env`` (``sim_node.viewer``).

Time: the sim has its own clock, which starts at 0 and advances by one
control period (``substeps`` x physics step, 1/24 s) per lockstep
``sim/step`` call; it is published on ``clock`` after every step. With
``use_sim_time:=true`` every stamp the node sends (episodes, viewer topics)
is that clock, and the viewer topics are sent each time it passes a multiple
of 1 / ``viewer_rate_hz``: a seeded run then sends the same stamps every
time. The default is ``use_sim_time:=false``, as for any ROS node: stamps
are wall-clock and the viewer topics follow a wall-clock timer, which keeps
a viewer up to date while the sim waits between requests.

With ``workers`` > 1 the envs are split over worker processes that step
their shares in parallel (``sim_node.parallel``); by default one per core.

Evaluation has envs of its own: resets and steps of phase eval go to
``eval_envs`` envs (numbered after the training envs in the episode
records), split over ``workers`` processes of their own. They are made
right after start-up, on the sim's callback group (a request waits for
them), while the other nodes of a graph start: made at the first
evaluation instead, they kept a graph quiet for as long as that takes (12 s
on a loaded 2-core machine), which a launch's watchdog reads as a stall. A deterministic episode needs no learner between
steps but the policy's one call per batch, so the more envs a step carries
the less the round trip weighs: ``bench eval``. ``eval_envs:=0`` serves
evaluations on the training envs.
"""

from __future__ import annotations

import os

from pathlib import Path

from builtin_interfaces.msg import Time
from glocal_interfaces.msg import EpisodeRecord
from glocal_interfaces.srv import ResetEnvs, StepEnvs
from rclpy.callback_groups import MutuallyExclusiveCallbackGroup
from rclpy.clock import Clock as RclpyClock, ClockType
from rclpy.node import Node
from rclpy.time import Time as RclpyTime
from rosgraph_msgs.msg import Clock

from glocal_ros.paths import objects_dir
from glocal_ros.sim_contract import DEFAULT_EVAL_ENVS, PHASE_EVAL, EpisodeLog
from node_common import names, qos
from node_common.arrays import from_float32_field, to_float32_field
from node_common.params import declare
from node_common.runner import spin_node
from node_common.services import answers_errors
from sim_node.batch import BatchedEnvs
from sim_node.parallel import ProcessBatchedEnvs
from sim_node.grasp_env import GraspEnv, GraspEnvConfig
from sim_node.viewer import WORLD_FRAME, ViewerPublisher


class SimClock:
    """The sim's time: ``period_ns`` per lockstep step, from 0."""

    def __init__(self, period_ns: int):
        self.period_ns = period_ns
        self.now_ns = 0

    def advance(self) -> None:
        self.now_ns += self.period_ns

    def stamp(self) -> Time:
        return RclpyTime(nanoseconds=self.now_ns).to_msg()


class SimNode(Node):
    def __init__(self) -> None:
        super().__init__("sim_node")
        num_envs = declare(self, "num_envs", 4, "envs stepped in lockstep per /sim/step call", min_value=1, max_value=256)
        initial_task = declare(self, "initial_task", "A0", "task of every env until a reset names another")
        gui = declare(self, "gui", False, "open the PyBullet window for env 0")
        objects = declare(self, "objects_dir", "", "folder of <TASK>/model.urdf objects (a novel task NAME@PROXY's: "
                          "NAME/model.urdf); empty: the package's assets")
        max_steps = declare(self, "max_steps", GraspEnvConfig.max_steps, "T: steps per episode before truncation",
                            min_value=1, max_value=10_000)
        self.viewer_env = declare(self, "viewer_env", 0, "env whose state is published for viewers",
                                  min_value=0, max_value=255)
        viewer_rate = declare(self, "viewer_rate_hz", 10.0, "rate of the viewer topics (TF, joint_states, object "
                              "pose and marker, grasp_state), in sim time with use_sim_time; 0 = off",
                              min_value=0.0, max_value=240.0)
        if self.viewer_env >= num_envs:
            raise ValueError(f"viewer_env {self.viewer_env} must be below num_envs {num_envs}")

        workers = declare(self, "workers", 0, "processes stepping the envs in parallel (training's and "
                          "evaluation's each); 0: one per CPU core, at most the envs; 1: all envs in this process", min_value=0, max_value=256)
        workers = workers or os.cpu_count() or 1
        seed = declare(self, "seed", -1, "-1: episodes from the OS's entropy; else env k's first episode gets "
                       "seed + k and the rest follow from it, so a run is repeatable", min_value=-1,
                       max_value=2**31 - 1)
        eval_envs = declare(self, "eval_envs", DEFAULT_EVAL_ENVS, "envs of evaluation (phase eval) resets and "
                            "steps, over workers of their own, made at the first; 0: the training envs serve them",
                            min_value=0, max_value=256)
        seed = None if seed < 0 else seed
        config = GraspEnvConfig(max_steps=max_steps)
        objects = objects or str(objects_dir())

        def make_batch(count: int, first_index: int = 0, with_gui: bool = False):
            processes = min(count, workers)
            if processes > 1:
                return ProcessBatchedEnvs(count, processes, initial_task, objects, config, with_gui, seed, first_index)
            return BatchedEnvs(lambda i: GraspEnv(initial_task, objects, config,
                                                  render_mode="human" if with_gui and i == 0 else None),
                               count, initial_task, first_index, seed)

        self.batch = make_batch(num_envs, with_gui=gui)
        self._eval_batch = None
        self._make_eval_batch = (lambda: make_batch(eval_envs, first_index=num_envs)) if eval_envs else None
        self.episode_seq = 0
        self.sim_clock = SimClock(round(config.substeps * config.timestep * 1e9))
        self.use_sim_time = bool(self.get_parameter("use_sim_time").value)

        # pybullet clients are not thread-safe: one group serialises every env access.
        sim_group = MutuallyExclusiveCallbackGroup()
        self.create_service(ResetEnvs, names.SIM_RESET, self.on_reset, callback_group=sim_group)
        self.create_service(StepEnvs, names.SIM_STEP, self.on_step, callback_group=sim_group)
        self.episodes_pub = self.create_publisher(EpisodeRecord, names.EPISODES, qos.EPISODES)
        self.clock_pub = self.create_publisher(Clock, names.CLOCK, qos.CLOCK)
        self.viewer: ViewerPublisher | None = None
        self.viewer_period_ns = 0
        self.next_viewer_ns = 0
        if viewer_rate > 0:
            self.viewer = ViewerPublisher(self, Path(objects))
            self.viewer.publish_static(self.batch.snapshot(self.viewer_env), self.stamp())
            self.viewer_period_ns = round(1e9 / viewer_rate)
            if not self.use_sim_time:
                self.create_timer(1.0 / viewer_rate, self.publish_viewer_state, callback_group=sim_group)
        if self._make_eval_batch is not None:
            self._eval_timer = self.create_timer(0.01, self.make_eval_batch, callback_group=sim_group,
                                                 clock=RclpyClock(clock_type=ClockType.STEADY_TIME))
        self.get_logger().info(
            f"{num_envs} envs in {min(num_envs, workers)} process{'es' if min(num_envs, workers) > 1 else ''} on "
            f"task {initial_task}, {eval_envs or 'no'} evaluation envs of their own, "
            f"obs {self.batch.obs_dim}, action {self.batch.action_dim}"
        )

    def make_eval_batch(self) -> None:
        """Once, after start-up: the evaluation envs. A failure is logged; the first evaluation tries again
        and answers with it."""
        self.destroy_timer(self._eval_timer)
        try:
            self.batch_of(PHASE_EVAL)
        except Exception as error:  # noqa: BLE001 - the node keeps serving; the request says what failed
            self.get_logger().error(f"the evaluation envs could not be made: {type(error).__name__}: {error}")

    def batch_of(self, phase: int):
        """The envs that serve ``phase``: the evaluation envs (made now if not yet) or the training ones."""
        if phase != PHASE_EVAL or self._make_eval_batch is None:
            return self.batch
        if self._eval_batch is None:
            self._eval_batch = self._make_eval_batch()
            self.get_logger().info(f"{self._eval_batch.num_envs} evaluation envs made")
        return self._eval_batch

    @answers_errors("reset")
    def on_reset(self, request: ResetEnvs.Request, response: ResetEnvs.Response) -> ResetEnvs.Response:
        batch = self.batch_of(request.phase)
        response.num_envs, response.obs_dim = batch.num_envs, batch.obs_dim
        response.action_dim = batch.action_dim
        observations, interrupted = batch.reset(
            request.env_indices, request.tasks, request.seeds, request.phase, request.policy_name
        )
        self._publish_episodes(interrupted)
        response.observations = to_float32_field(observations)
        response.success = True
        return response

    @answers_errors("step")
    def on_step(self, request: StepEnvs.Request, response: StepEnvs.Response) -> StepEnvs.Response:
        batch = self.batch_of(request.phase)
        response.num_envs, response.obs_dim = batch.num_envs, batch.obs_dim
        result = batch.step(
            from_float32_field(request.actions), request.next_tasks, request.phase,
            request.policy_name, request.global_step, request.env_indices,
        )
        self.sim_clock.advance()
        self.clock_pub.publish(Clock(clock=self.sim_clock.stamp()))
        self._publish_episodes(result.finished)
        if self.viewer is not None and self.use_sim_time and self.sim_clock.now_ns >= self.next_viewer_ns:
            self.publish_viewer_state()
            self.next_viewer_ns = self.sim_clock.now_ns + self.viewer_period_ns
        response.observations = to_float32_field(result.observations)
        response.rewards = to_float32_field(result.rewards)
        response.terminated = result.terminated.tolist()
        response.truncated = result.truncated.tolist()
        response.is_success = result.is_success.tolist()
        response.terminal_observations = to_float32_field(result.terminal_observations)
        response.tasks = result.tasks
        response.success = True
        return response

    def _publish_episodes(self, logs: list[EpisodeLog]) -> None:
        for log in logs:
            self.episodes_pub.publish(self._episode_record(log))

    def _episode_record(self, log: EpisodeLog) -> EpisodeRecord:
        record = EpisodeRecord()
        record.header.stamp = self.stamp()
        record.header.frame_id = WORLD_FRAME
        record.seq = self.episode_seq
        self.episode_seq += 1
        record.task, record.env_index, record.phase = log.task, log.env_index, log.phase
        record.policy_name, record.global_step, record.seed = log.policy_name, log.global_step, log.seed
        record.length, record.obs_dim, record.action_dim = log.length, self.batch.obs_dim, self.batch.action_dim
        record.observations = to_float32_field(log.observations)
        if log.actions:
            record.actions = to_float32_field(log.actions)
        record.rewards = to_float32_field(log.rewards)
        record.joint_names = self.batch.joint_names
        record.joint_positions = to_float32_field(log.joint_positions)
        record.success, record.truncated, record.interrupted = log.success, log.truncated, log.interrupted
        return record

    def stamp(self) -> Time:
        """Now: the sim's clock with use_sim_time, else the node's (wall) clock."""
        return self.sim_clock.stamp() if self.use_sim_time else self.get_clock().now().to_msg()

    def publish_viewer_state(self) -> None:
        self.viewer.publish(self.batch.snapshot(self.viewer_env), self.viewer_env, self.batch.joint_names,
                            self.stamp())

    def close(self) -> None:
        self.batch.close()
        if self._eval_batch is not None:
            self._eval_batch.close()


def main(args=None) -> int:
    return spin_node(SimNode, args)


if __name__ == "__main__":
    raise SystemExit(main())

"""sim_node: N PyBullet grasp envs behind a batched, lockstep reset/step service.

Services: ``sim/reset`` (glocal_interfaces/srv/ResetEnvs), ``sim/step``
(glocal_interfaces/srv/StepEnvs). Topics: ``glocal/episodes`` (one
EpisodeRecord per finished episode, reliable, seq-numbered), and for viewers,
throttled and best effort, ``joint_states``, ``glocal/object_pose`` and
``glocal/grasp_state`` of the env named by ``viewer_env``.

With ``workers`` > 1 the envs are split over worker processes that step
their shares in parallel (``sim_node.parallel``); by default one per core.
"""

from __future__ import annotations

import os

from geometry_msgs.msg import PoseStamped
from glocal_interfaces.msg import EpisodeRecord, GraspState
from glocal_interfaces.srv import ResetEnvs, StepEnvs
from rclpy.callback_groups import MutuallyExclusiveCallbackGroup
from rclpy.node import Node
from sensor_msgs.msg import JointState

from glocal_ros.paths import objects_dir
from glocal_ros.sim_contract import EpisodeLog
from node_common import names, qos
from node_common.arrays import from_float32_field, to_float32_field
from node_common.params import declare
from node_common.runner import spin_node
from node_common.services import answers_errors
from sim_node.batch import BatchedEnvs
from sim_node.parallel import ProcessBatchedEnvs
from sim_node.grasp_env import GraspEnv, GraspEnvConfig

WORLD_FRAME = "world"


class SimNode(Node):
    def __init__(self) -> None:
        super().__init__("sim_node")
        num_envs = declare(self, "num_envs", 4, "envs stepped in lockstep per /sim/step call", min_value=1, max_value=256)
        initial_task = declare(self, "initial_task", "A0", "task of every env until a reset names another")
        gui = declare(self, "gui", False, "open the PyBullet window for env 0")
        objects = declare(self, "objects_dir", "", "folder of <TASK>/model.urdf objects; empty: the package's assets")
        max_steps = declare(self, "max_steps", GraspEnvConfig.max_steps, "T: steps per episode before truncation",
                            min_value=1, max_value=10_000)
        self.viewer_env = declare(self, "viewer_env", 0, "env whose state is published for viewers",
                                  min_value=0, max_value=255)
        viewer_rate = declare(self, "viewer_rate_hz", 10.0, "rate of joint_states, object_pose and grasp_state; 0 = off",
                              min_value=0.0, max_value=240.0)
        if self.viewer_env >= num_envs:
            raise ValueError(f"viewer_env {self.viewer_env} must be below num_envs {num_envs}")

        workers = declare(self, "workers", 0, "processes stepping the envs in parallel; 0: one per CPU core, "
                          "at most num_envs; 1: all envs in this process", min_value=0, max_value=256)
        workers = min(num_envs, workers or os.cpu_count() or 1)
        seed = declare(self, "seed", -1, "-1: episodes from the OS's entropy; else env k's first episode gets "
                       "seed + k and the rest follow from it, so a run is repeatable", min_value=-1,
                       max_value=2**31 - 1)
        seed = None if seed < 0 else seed
        config = GraspEnvConfig(max_steps=max_steps)
        objects = objects or str(objects_dir())
        if workers > 1:
            self.batch = ProcessBatchedEnvs(num_envs, workers, initial_task, objects, config, gui, seed)
        else:
            self.batch = BatchedEnvs(
                lambda i: GraspEnv(initial_task, objects, config, render_mode="human" if gui and i == 0 else None),
                num_envs, initial_task, seed=seed,
            )
        self.episode_seq = 0

        # pybullet clients are not thread-safe: one group serialises every env access.
        sim_group = MutuallyExclusiveCallbackGroup()
        self.create_service(ResetEnvs, names.SIM_RESET, self.on_reset, callback_group=sim_group)
        self.create_service(StepEnvs, names.SIM_STEP, self.on_step, callback_group=sim_group)
        self.episodes_pub = self.create_publisher(EpisodeRecord, names.EPISODES, qos.EPISODES)
        self.joint_pub = self.create_publisher(JointState, names.JOINT_STATES, qos.VIEWER)
        self.pose_pub = self.create_publisher(PoseStamped, names.OBJECT_POSE, qos.VIEWER)
        self.grasp_pub = self.create_publisher(GraspState, names.GRASP_STATE, qos.VIEWER)
        if viewer_rate > 0:
            self.create_timer(1.0 / viewer_rate, self.publish_viewer_state, callback_group=sim_group)
        self.get_logger().info(
            f"{num_envs} envs in {workers} process{'es' if workers > 1 else ''} on task {initial_task}, "
            f"obs {self.batch.obs_dim}, action {self.batch.action_dim}"
        )

    @answers_errors("reset")
    def on_reset(self, request: ResetEnvs.Request, response: ResetEnvs.Response) -> ResetEnvs.Response:
        response.num_envs, response.obs_dim = self.batch.num_envs, self.batch.obs_dim
        response.action_dim = self.batch.action_dim
        observations, interrupted = self.batch.reset(
            request.env_indices, request.tasks, request.seeds, request.phase, request.policy_name
        )
        self._publish_episodes(interrupted)
        response.observations = to_float32_field(observations)
        response.success = True
        return response

    @answers_errors("step")
    def on_step(self, request: StepEnvs.Request, response: StepEnvs.Response) -> StepEnvs.Response:
        response.num_envs, response.obs_dim = self.batch.num_envs, self.batch.obs_dim
        result = self.batch.step(
            from_float32_field(request.actions), request.next_tasks, request.phase,
            request.policy_name, request.global_step,
        )
        self._publish_episodes(result.finished)
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
        record.header.stamp = self.get_clock().now().to_msg()
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

    def publish_viewer_state(self) -> None:
        snapshot = self.batch.snapshot(self.viewer_env)
        stamp = self.get_clock().now().to_msg()
        joints = JointState()
        joints.header.stamp = stamp
        joints.name = self.batch.joint_names
        joints.position = snapshot.joint_positions.astype(float).tolist()
        self.joint_pub.publish(joints)

        pose = PoseStamped()
        pose.header.stamp, pose.header.frame_id = stamp, WORLD_FRAME
        pose.pose.position.x, pose.pose.position.y, pose.pose.position.z = (float(v) for v in snapshot.object_position)
        (pose.pose.orientation.x, pose.pose.orientation.y,
         pose.pose.orientation.z, pose.pose.orientation.w) = (float(v) for v in snapshot.object_orientation)
        self.pose_pub.publish(pose)

        grasp = snapshot.grasp
        self.grasp_pub.publish(GraspState(
            header=pose.header, env_index=self.viewer_env, task=snapshot.task, step=grasp.step,
            left_finger_contact=grasp.left_contact, right_finger_contact=grasp.right_contact,
            gripper_opening=float(grasp.gripper_opening), object_lift=float(grasp.object_lift),
            success=snapshot.lifted,
        ))

    def close(self) -> None:
        self.batch.close()


def main(args=None) -> int:
    return spin_node(SimNode, args)


if __name__ == "__main__":
    raise SystemExit(main())

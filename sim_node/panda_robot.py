"""The Franka Emika Panda of pybullet_data, driven as a top-down gripper.

The arm is commanded in Cartesian space: a tool-centre-point (TCP) position, a
yaw about the vertical axis and an open/closed gripper. The TCP is the
``panda_grasptarget`` frame, between the finger pads, about 1.1 cm above the
fingertips. At yaw 0 the fingers close along the world y axis.

The fingers are coupled, as the Franka hand's are (one motor and a rack; the
URDF says ``panda_finger_joint2`` mimics ``panda_finger_joint1``): a gear
constraint of ratio -1 between the two prismatic joints, as PyBullet's own
Panda example makes it, holds them at the same travel while both motors
drive them. A finger that touches the object first therefore pushes it
towards the middle of the hand until the other finger closes on it, and
what the sim reports matches what a URDF consumer that honours the mimic
(robot_state_publisher) draws.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
import pybullet
import pybullet_data
from pybullet_utils.bullet_client import BulletClient

from sim_node.robot_description import PANDA_URDF

ARM_JOINT_INDICES: tuple[int, ...] = (0, 1, 2, 3, 4, 5, 6)
FINGER_JOINT_INDICES: tuple[int, int] = (9, 10)
LEFT_FINGER_LINK, RIGHT_FINGER_LINK = FINGER_JOINT_INDICES
TCP_LINK = 11

JOINT_NAMES: tuple[str, ...] = tuple(f"panda_joint{i}" for i in range(1, 8)) + (
    "panda_finger_joint1",
    "panda_finger_joint2",
)

# Null-space IK solution for the TCP at (0.5, 0, 0.15) m from the base, pointing
# down, yaw 0. Hard-coded rather than solved at start so every reset is the same.
HOME_ARM_POSITIONS: tuple[float, ...] = (0.0, 0.1433, 0.0, -2.3982, 0.0, 2.5411, 0.7854)

FINGER_MAX_POSITION = 0.04
"""Travel of one finger (m); the gripper opening is the sum of both."""
FINGERTIP_DEPTH = 0.0115
"""How far the fingertips reach below the TCP (m)."""

_ARM_FORCES = (87.0, 87.0, 87.0, 87.0, 12.0, 12.0, 12.0)
# Each physics step closes this fraction of a joint's position error: with 10
# substeps the arm covers about 90% of a commanded move within the env step.
_ARM_POSITION_GAIN = 0.2
_FINGER_FORCE = 20.0
# PyBullet's Panda example (pybullet_robots/panda/panda_sim.py) couples the fingers with these.
_FINGER_GEAR_RATIO = -1.0
_FINGER_GEAR_ERP = 0.1
_FINGER_GEAR_MAX_FORCE = 50.0
_LOWER_LIMITS = np.array((-2.9671, -1.8326, -2.9671, -3.1416, -2.9671, -0.0873, -2.9671))
_UPPER_LIMITS = np.array((2.9671, 1.8326, 2.9671, 0.0, 2.9671, 3.8223, 2.9671))
# The order of JOINT_NAMES.
_MOVABLE_JOINTS = ARM_JOINT_INDICES + FINGER_JOINT_INDICES
_ZERO_MOTION = [0.0] * len(_MOVABLE_JOINTS)
# Damped least squares keeps the step bounded near singularities; the
# null-space pull keeps the elbow near its home configuration.
_IK_DAMPING = 0.01
_HOME = np.array(HOME_ARM_POSITIONS)
_NULL_SPACE_GAIN = 0.1


def _top_down_matrix(yaw: float) -> np.ndarray:
    """Rotation of a TCP pointing down (z axis to -z), its x axis at heading ``yaw``."""
    cos_yaw, sin_yaw = math.cos(yaw), math.sin(yaw)
    return np.array(((cos_yaw, sin_yaw, 0.0), (sin_yaw, -cos_yaw, 0.0), (0.0, 0.0, -1.0)))


def _rotation_error(current: np.ndarray, target: np.ndarray) -> np.ndarray:
    """Small-angle rotation vector (world frame) that turns ``current`` into ``target``.

    Half the sum of the cross products of corresponding axes, computed as the
    skew-symmetric part of ``target @ current.T``.
    """
    product = target @ current.T
    return 0.5 * np.array(
        (product[2, 1] - product[1, 2], product[0, 2] - product[2, 0], product[1, 0] - product[0, 1])
    )


def yaw_of(quaternion: tuple[float, float, float, float]) -> float:
    """Heading of the frame's x axis in the horizontal plane (rad)."""
    x, y, z, w = quaternion
    return math.atan2(2.0 * (x * y + w * z), 1.0 - 2.0 * (y * y + z * z))


class PandaRobot:
    """A Panda with its base fixed at the world origin of one physics client.

    :param client: the physics client the robot lives in.
    """

    def __init__(self, client: BulletClient):
        self._client = client
        client.setAdditionalSearchPath(pybullet_data.getDataPath())
        self.body = client.loadURDF(PANDA_URDF, useFixedBase=True)
        # PyBullet numbers a link as its parent joint; the base (-1) is the URDF's root link.
        self._link_names = [client.getBodyInfo(self.body)[0].decode()] + [
            client.getJointInfo(self.body, joint)[12].decode() for joint in range(client.getNumJoints(self.body))
        ]
        base_inertial = client.getDynamicsInfo(self.body, -1)[3:5]
        self._base_link_from_inertial = client.invertTransform(*base_inertial)
        gear = client.createConstraint(self.body, LEFT_FINGER_LINK, self.body, RIGHT_FINGER_LINK,
                                       jointType=pybullet.JOINT_GEAR, jointAxis=(1, 0, 0),
                                       parentFramePosition=(0, 0, 0), childFramePosition=(0, 0, 0))
        client.changeConstraint(gear, gearRatio=_FINGER_GEAR_RATIO, erp=_FINGER_GEAR_ERP,
                                maxForce=_FINGER_GEAR_MAX_FORCE)
        self.reset()

    def reset(self) -> None:
        """Teleport to the home pose with the gripper open, at rest, and hold it there."""
        for joint, position in zip(ARM_JOINT_INDICES, HOME_ARM_POSITIONS):
            self._client.resetJointState(self.body, joint, position, targetVelocity=0.0)
        for joint in FINGER_JOINT_INDICES:
            self._client.resetJointState(self.body, joint, FINGER_MAX_POSITION, targetVelocity=0.0)
        self._drive_arm(HOME_ARM_POSITIONS)
        self._drive_fingers(FINGER_MAX_POSITION)

    def command(self, tcp_position: np.ndarray, yaw: float, close: bool) -> None:
        """Set motor targets that move the TCP towards a top-down pose; physics steps do the moving.

        The joint targets come from one damped least-squares step from the
        current joint positions: within millimetres for the short moves of an
        env step, and cheaper than PyBullet's iterative IK, which at its
        default tolerance stops centimetres short when the yaw changes too.
        """
        joints = self.joint_positions()
        linear, angular = self._client.calculateJacobian(
            self.body, TCP_LINK, (0.0, 0.0, 0.0), joints.tolist(), _ZERO_MOTION, _ZERO_MOTION
        )
        jacobian = np.vstack((linear, angular))[:, : len(ARM_JOINT_INDICES)]
        state = self._client.getLinkState(self.body, TCP_LINK, computeForwardKinematics=True)
        current = np.array(self._client.getMatrixFromQuaternion(state[5])).reshape(3, 3)
        error = np.concatenate((tcp_position - state[4], _rotation_error(current, _top_down_matrix(yaw))))

        arm = joints[: len(ARM_JOINT_INDICES)]
        pseudo_inverse = jacobian.T @ np.linalg.inv(jacobian @ jacobian.T + _IK_DAMPING**2 * np.eye(6))
        toward_home = _NULL_SPACE_GAIN * (_HOME - arm)
        step = pseudo_inverse @ (error - jacobian @ toward_home) + toward_home
        self._drive_arm(np.clip(arm + step, _LOWER_LIMITS, _UPPER_LIMITS))
        self._drive_fingers(0.0 if close else FINGER_MAX_POSITION)

    def tcp_pose(self) -> tuple[np.ndarray, float]:
        """TCP position (m, world frame) and yaw (rad)."""
        state = self._client.getLinkState(self.body, TCP_LINK, computeForwardKinematics=True)
        return np.array(state[4]), yaw_of(state[5])

    def joint_positions(self) -> np.ndarray:
        """Positions of the joints named in ``JOINT_NAMES``, in that order (rad, and m for fingers)."""
        return np.array([state[0] for state in self._client.getJointStates(self.body, _MOVABLE_JOINTS)])

    def link_poses(self) -> dict[str, tuple[tuple[float, ...], tuple[float, ...]]]:
        """World pose (position, quaternion xyzw) of every URDF link's frame, by link name.

        These are the frames of the URDF (what viewers place meshes in), not
        PyBullet's inertial frames: for the base that needs the inertial
        offset undone; for the other links PyBullet reports the link frame.
        """
        base = self._client.getBasePositionAndOrientation(self.body)
        poses = {self._link_names[0]: self._client.multiplyTransforms(*base, *self._base_link_from_inertial)}
        states = self._client.getLinkStates(self.body, range(len(self._link_names) - 1),
                                            computeForwardKinematics=True)
        for name, state in zip(self._link_names[1:], states):
            poses[name] = (state[4], state[5])
        return poses

    def gripper_opening(self) -> float:
        """Distance between the finger pads (m), 0 closed to 0.08 fully open."""
        states = self._client.getJointStates(self.body, FINGER_JOINT_INDICES)
        return states[0][0] + states[1][0]

    def _drive_arm(self, positions: Sequence[float]) -> None:
        self._client.setJointMotorControlArray(
            self.body,
            ARM_JOINT_INDICES,
            pybullet.POSITION_CONTROL,
            targetPositions=list(positions),
            forces=_ARM_FORCES,
            positionGains=[_ARM_POSITION_GAIN] * len(ARM_JOINT_INDICES),
        )

    def _drive_fingers(self, position: float) -> None:
        self._client.setJointMotorControlArray(
            self.body,
            FINGER_JOINT_INDICES,
            pybullet.POSITION_CONTROL,
            targetPositions=(position, position),
            forces=(_FINGER_FORCE, _FINGER_FORCE),
        )

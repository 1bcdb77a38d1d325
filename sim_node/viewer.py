"""What sim_node publishes for viewers (RViz, Foxglove, a bag): robot model, TF, the object, its state.

One env (``viewer_env``) is shown. Its robot is the URDF on
``robot_description`` (``sim_node.robot_description``), placed by TF as
robot_state_publisher would place it:

- ``/tf_static`` (latched): ``world`` -> the URDF's root link (where the sim
  put the robot's base) and every fixed joint's parent -> child, from the
  URDF's joint origins;
- ``/tf``: every movable joint's parent -> child, and ``world`` -> ``object``
  (the object's URDF link frame), all with one stamp per message.

The object is a ``visualization_msgs/Marker`` in frame ``object``: its
visual mesh as an embedded TRIANGLE_LIST (about 1,000 triangles, 70 KB), not a
``package://`` mesh resource, so that a bag shows the object without the
package installed where it is viewed; latched, and sent again whenever the
shown env's task changes. ``joint_states``, ``glocal/object_pose`` and
``glocal/grasp_state`` carry the same instant as ``/tf``.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import trimesh
from builtin_interfaces.msg import Time
from geometry_msgs.msg import Point, PoseStamped, TransformStamped
from glocal_interfaces.msg import GraspState
from rclpy.node import Node
from sensor_msgs.msg import JointState
from std_msgs.msg import String
from tf2_msgs.msg import TFMessage
from visualization_msgs.msg import Marker

from glocal_ros.paths import object_urdf
from glocal_ros.transforms import Transform
from glocal_ros.urdf import RobotModel, parse_urdf
from node_common import names, qos
from sim_node.batch import EnvSnapshot
from sim_node.robot_description import robot_description

WORLD_FRAME = "world"
OBJECT_FRAME = "object"
OBJECT_MARKER_NAMESPACE = "glocal_object"


def transform_msg(parent: str, child: str, transform: Transform, stamp: Time) -> TransformStamped:
    message = TransformStamped()
    message.header.stamp, message.header.frame_id, message.child_frame_id = stamp, parent, child
    t, r = message.transform.translation, message.transform.rotation
    t.x, t.y, t.z = transform.translation
    r.x, r.y, r.z, r.w = transform.rotation
    return message


def object_marker(urdf: Path, stamp: Time) -> Marker:
    """The object of ``urdf`` as a TRIANGLE_LIST marker in ``OBJECT_FRAME`` (its link frame).

    :raises ValueError: when the URDF has no mesh visual.
    """
    model = parse_urdf(urdf.read_text())
    visuals = [visual for link in model.links for visual in model.visuals[link]]
    if not visuals:
        raise ValueError(f"{urdf} has no mesh visual to show")
    marker = Marker()
    marker.header.stamp, marker.header.frame_id = stamp, OBJECT_FRAME
    marker.ns, marker.id = OBJECT_MARKER_NAMESPACE, 0
    marker.type, marker.action = Marker.TRIANGLE_LIST, Marker.ADD
    marker.pose.orientation.w = 1.0
    marker.scale.x = marker.scale.y = marker.scale.z = 1.0
    marker.frame_locked = True  # viewers move it with the object's TF
    rgba = next((visual.rgba for visual in visuals if visual.rgba), (0.8, 0.8, 0.8, 1.0))
    marker.color.r, marker.color.g, marker.color.b, marker.color.a = (float(v) for v in rgba)
    triangles = []
    for visual in visuals:
        mesh = trimesh.load(urdf.parent / visual.mesh, force="mesh", process=False)
        vertices = np.asarray(mesh.vertices) * visual.scale
        vertices = vertices @ visual.origin.matrix()[:3, :3].T + visual.origin.translation
        triangles.append(vertices[np.asarray(mesh.faces)].reshape(-1, 3))
    marker.points = [Point(x=x, y=y, z=z) for x, y, z in np.concatenate(triangles).tolist()]
    return marker


class ViewerPublisher:
    """The viewer topics of one node, and what was last sent on the latched ones.

    :param node: the node that publishes (sim_node).
    :param objects_dir: where ``<TASK>/model.urdf`` lives, for the object marker.
    """

    def __init__(self, node: Node, objects_dir: Path):
        self._node = node
        self._objects_dir = objects_dir
        description = robot_description()
        self.robot: RobotModel = parse_urdf(description)
        self._movable = [joint for joint in self.robot.joints if not joint.fixed]
        self._marker_task: str | None = None

        self._description_pub = node.create_publisher(String, names.ROBOT_DESCRIPTION, qos.DESCRIPTION)
        self._tf_static_pub = node.create_publisher(TFMessage, names.TF_STATIC, qos.DESCRIPTION)
        self._tf_pub = node.create_publisher(TFMessage, names.TF, qos.VIEWER)
        self._marker_pub = node.create_publisher(Marker, names.OBJECT_MARKER, qos.DESCRIPTION)
        self._joint_pub = node.create_publisher(JointState, names.JOINT_STATES, qos.VIEWER)
        self._pose_pub = node.create_publisher(PoseStamped, names.OBJECT_POSE, qos.VIEWER)
        self._grasp_pub = node.create_publisher(GraspState, names.GRASP_STATE, qos.VIEWER)
        self._description_pub.publish(String(data=description))

    def publish_static(self, snapshot: EnvSnapshot, stamp: Time) -> None:
        """``/tf_static``: where the robot stands in the world, and every fixed joint."""
        root = self.robot.root
        transforms = [transform_msg(WORLD_FRAME, root, Transform.of(*snapshot.link_poses[root]), stamp)]
        transforms += [transform_msg(joint.parent, joint.child, joint.origin, stamp)
                       for joint in self.robot.joints if joint.fixed]
        self._tf_static_pub.publish(TFMessage(transforms=transforms))

    def publish(self, snapshot: EnvSnapshot, env_index: int, joint_names: list[str], stamp: Time) -> None:
        """Every viewer topic for the state in ``snapshot``, stamped ``stamp``."""
        if snapshot.task != self._marker_task:
            self._marker_pub.publish(object_marker(object_urdf(self._objects_dir, snapshot.task), stamp))
            self._marker_task = snapshot.task
        world = {link: Transform.of(*pose) for link, pose in snapshot.link_poses.items()}
        transforms = [transform_msg(joint.parent, joint.child, world[joint.parent].inverse() * world[joint.child],
                                    stamp) for joint in self._movable]
        object_pose = Transform.of(snapshot.object_position, snapshot.object_orientation)
        transforms.append(transform_msg(WORLD_FRAME, OBJECT_FRAME, object_pose, stamp))
        self._tf_pub.publish(TFMessage(transforms=transforms))

        joints = JointState()
        joints.header.stamp = stamp
        joints.name = joint_names
        joints.position = snapshot.joint_positions.astype(float).tolist()
        self._joint_pub.publish(joints)

        pose = PoseStamped()
        pose.header.stamp, pose.header.frame_id = stamp, WORLD_FRAME
        position, orientation = pose.pose.position, pose.pose.orientation
        position.x, position.y, position.z = object_pose.translation
        orientation.x, orientation.y, orientation.z, orientation.w = object_pose.rotation
        self._pose_pub.publish(pose)

        grasp = snapshot.grasp
        self._grasp_pub.publish(GraspState(
            header=pose.header, env_index=env_index, task=snapshot.task, step=grasp.step,
            left_finger_contact=grasp.left_contact, right_finger_contact=grasp.right_contact,
            gripper_opening=float(grasp.gripper_opening), object_lift=float(grasp.object_lift),
            success=snapshot.lifted,
        ))

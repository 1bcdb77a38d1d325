"""What viewers get from sim_node: robot_description, TF that places every link where the sim has it,
the object marker, /clock, and viewer topics that a tutorial-style (default QoS) subscriber receives."""

import numpy as np
import pytest
from glocal_interfaces.srv import ResetEnvs, StepEnvs
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState
from std_msgs.msg import String
from tf2_msgs.msg import TFMessage
from visualization_msgs.msg import Marker

from conftest import wait_until
from glocal_ros.paths import objects_dir
from glocal_ros.transforms import Transform, resolve_frames
from glocal_ros.urdf import parse_urdf
from node_common import names, qos
from node_common.arrays import to_float32_field
from node_common.calls import call
from sim_node.grasp_env import GraspEnv, GraspEnvConfig
from sim_node.robot_description import robot_description
from sim_node.viewer import OBJECT_FRAME, WORLD_FRAME

CONTROL_PERIOD_NS = round(GraspEnvConfig().substeps * GraspEnvConfig().timestep * 1e9)


def tf_edges(messages) -> dict[str, tuple[str, Transform]]:
    edges = {}
    for message in messages:
        for transform in message.transforms:
            t, r = transform.transform.translation, transform.transform.rotation
            edges[transform.child_frame_id] = (transform.header.frame_id,
                                               Transform.of((t.x, t.y, t.z), (r.x, r.y, r.z, r.w)))
    return edges


def test_the_description_names_installed_meshes_and_keeps_the_simulated_robot():
    description = robot_description()
    assert "package://meshes/" not in description
    model = parse_urdf(description)
    meshes = {visual.mesh for visuals in model.visuals.values() for visual in visuals}
    assert meshes and all(mesh.startswith("package://glocal_ros/robots/franka_panda/meshes/") for mesh in meshes)
    env = GraspEnv("A0", objects_dir())
    try:
        env.reset(seed=0)
        assert set(env.link_poses()) == set(model.links)
    finally:
        env.close()


def test_static_and_moving_transforms_place_every_link_where_the_sim_has_it():
    """The TF tree the sim node sends (fixed joints from the URDF, movable ones from the sim) chains
    back to PyBullet's own world pose of every link, after the arm has moved."""
    from sim_node.viewer import transform_msg

    model = parse_urdf(robot_description())
    env = GraspEnv("A0", objects_dir())
    try:
        env.reset(seed=3)
        for _ in range(6):
            env.step(np.array([1.0, 0.5, 0.3, -0.4, -1.0], dtype=np.float32))
        simulated = {link: Transform.of(*pose) for link, pose in env.link_poses().items()}
    finally:
        env.close()
    stamp = JointState().header.stamp
    static = [transform_msg(WORLD_FRAME, model.root, simulated[model.root], stamp)]
    static += [transform_msg(j.parent, j.child, j.origin, stamp) for j in model.joints if j.fixed]
    moving = [transform_msg(j.parent, j.child, simulated[j.parent].inverse() * simulated[j.child], stamp)
              for j in model.joints if not j.fixed]
    placed = resolve_frames(tf_edges([TFMessage(transforms=static), TFMessage(transforms=moving)]), WORLD_FRAME)
    for link in model.links:
        np.testing.assert_allclose(placed[link].translation, simulated[link].translation, atol=1e-6, err_msg=link)
        # q and -q are the same rotation
        dot = abs(float(np.dot(placed[link].rotation, simulated[link].rotation)))
        assert dot == pytest.approx(1.0, abs=1e-6), link


@pytest.fixture
def sim_time_node(start_node, ros_node):
    process = start_node("sim_node", num_envs=2, max_steps=5, viewer_rate_hz=12.0, use_sim_time=True, workers=2)
    reset = ros_node.create_client(ResetEnvs, names.SIM_RESET)
    step = ros_node.create_client(StepEnvs, names.SIM_STEP)
    wait_until(lambda: reset.service_is_ready() and step.service_is_ready(), 120, "sim services",
               processes=[process])
    return process, reset, step


def test_viewers_get_the_robot_the_object_and_sim_time(sim_time_node, ros_node):
    process, reset, step = sim_time_node
    received = {name: [] for name in ("joint_states", "tf", "clock", "description", "tf_static", "marker")}
    # A tutorial-style subscription: default QoS (reliable, volatile, depth 10).
    ros_node.create_subscription(JointState, names.JOINT_STATES, received["joint_states"].append, 10)
    ros_node.create_subscription(TFMessage, names.TF, received["tf"].append, 10)
    ros_node.create_subscription(Clock, names.CLOCK, received["clock"].append, qos.CLOCK)
    # Late joiners of the latched topics get them at once.
    ros_node.create_subscription(String, names.ROBOT_DESCRIPTION, received["description"].append, qos.DESCRIPTION)
    ros_node.create_subscription(TFMessage, names.TF_STATIC, received["tf_static"].append, qos.DESCRIPTION)
    ros_node.create_subscription(Marker, names.OBJECT_MARKER, received["marker"].append, qos.DESCRIPTION)
    wait_until(lambda: received["description"] and received["tf_static"], 60, "latched description and tf_static",
               processes=[process])
    wait_until(lambda: ros_node.count_publishers(names.CLOCK) and ros_node.count_publishers(names.TF), 60,
               "publishers matched", processes=[process])

    assert call(reset, ResetEnvs.Request(tasks=["B1", "A0"], seeds=[4])).success
    steps = 12
    actions = to_float32_field(np.zeros((2, 5), dtype=np.float32))
    for _ in range(steps):
        assert call(step, StepEnvs.Request(actions=actions)).success
    wait_until(lambda: len(received["clock"]) >= steps, 60, "a /clock message per step", processes=[process])
    clock_ns = [c.clock.sec * 10**9 + c.clock.nanosec for c in received["clock"]]
    assert clock_ns == [CONTROL_PERIOD_NS * k for k in range(1, steps + 1)]

    # 12 steps of 1/24 s at 12 Hz of sim time: viewer state at steps 1, 3, 5, ..., 11.
    wait_until(lambda: len(received["tf"]) >= 6 and len(received["joint_states"]) >= 6 and received["marker"], 60,
               "TF, joint states and the marker", processes=[process])
    tf_ns = [m.transforms[0].header.stamp.sec * 10**9 + m.transforms[0].header.stamp.nanosec for m in received["tf"]]
    assert tf_ns == [CONTROL_PERIOD_NS * k for k in range(1, steps + 1, 2)]
    for message in received["tf"]:
        assert len({(t.header.stamp.sec, t.header.stamp.nanosec) for t in message.transforms}) == 1

    model = parse_urdf(received["description"][-1].data)
    edges = tf_edges(received["tf_static"] + received["tf"][-1:])
    placed = resolve_frames(edges, WORLD_FRAME, [*model.links, OBJECT_FRAME])  # raises for a frame off the tree
    assert placed[OBJECT_FRAME].translation[2] < 0.2  # on the table, in front of the robot
    assert received["joint_states"][-1].name[:7] == [f"panda_joint{i}" for i in range(1, 8)]

    marker = received["marker"][-1]
    assert (marker.header.frame_id, marker.type, marker.ns) == (OBJECT_FRAME, Marker.TRIANGLE_LIST, "glocal_object")
    points = np.array([(p.x, p.y, p.z) for p in marker.points])
    assert len(points) % 3 == 0 and len(points) >= 300
    assert np.ptp(points, axis=0).max() < 0.1, "an object that fits an 8 cm gripper, in metres"
    assert process.running

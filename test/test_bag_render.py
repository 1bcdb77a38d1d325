"""A smoke run's bag is self-contained for a viewer, and `glocal-ros bag render` draws it as the sim saw it.

One real `glocal-ros launch --preset smoke` (module fixture) leaves a bag
that must hold robot_description, /tf_static, /tf, /clock and the object
marker, with every link of the recorded URDF resolvable from ``world`` at
every /tf stamp. Frames rendered from the bag alone (TF chained, meshes
through the ament index, the object from its marker) are compared with the
sim's own image of the same stamp (its bodies set to the recorded joint
states and object pose), same camera, by the IoU of their robot and object
masks.

The thresholds, measured on three smoke bags (51 stamps compared): the
robot, object and foreground IoUs were exactly 1.000 every time (both
renderers draw the same meshes, at poses that agree to float precision, in
the same TinyRenderer), while the sim image of the previous /tf stamp (one
viewer period) scored 0.44-0.98, median 0.78, wherever the robot had moved,
and an object moved by 5 mm scored 0.74. ``ROBOT_IOU`` = 0.995 allows ~100
boundary pixels of the robot's ~23,000 to flip by rounding (none did) and
still rejects even the smallest one-step motion seen; ``OBJECT_IOU`` = 0.9
is looser because a partly hidden object covers only ~100 pixels, where
each boundary pixel weighs more, and still rejects a 5 mm offset.
"""

from __future__ import annotations

import dataclasses
import subprocess
import sys

import numpy as np
import pytest
from PIL import Image
from rosbags.highlevel import AnyReader

from conftest import REPO
from glocal_app import bag_render
from glocal_app.bag_render import BagViewError, mask_iou
from glocal_ros.recording import BagWriter, graph_typestore, message_counts
from glocal_ros.topics import CLOCK, OBJECT_MARKER, RECORDED_TOPICS, ROBOT_DESCRIPTION, TF, TF_STATIC
from glocal_ros.transforms import FrameLookupError, Transform, resolve_frames
from test_launch import launch

CLI = [sys.executable, "-m", "glocal_app.cli"]
ROBOT_IOU = 0.995
OBJECT_IOU = 0.9
#: Below this many object pixels in the sim image (hidden by the gripper) the object IoU says little.
VISIBLE_OBJECT_PIXELS = 100
#: Stamps spread over the run at which render and sim image are compared.
SAMPLES = 6
#: Stamps spread over the run among which the test looks for two far apart in joint space.
CONTRAST_STAMPS = 24


@pytest.fixture(scope="module")
def smoke_bag(tmp_path_factory):
    run_dir = tmp_path_factory.mktemp("render") / "run"
    # 1-3 minutes on 2 shared cores; under pytest-timeout's 600 s, so that a hung launch fails with its output.
    result = launch(run_dir, "--strategy", "glocal", "--seed", "0", timeout=500)
    assert result.returncode == 0, result.stdout + result.stderr
    return run_dir / "bag"


@pytest.fixture(scope="module")
def recording(smoke_bag):
    return bag_render.read_viewer_recording(smoke_bag)


def render_cli(bag, *args):
    return subprocess.run([*CLI, "bag", "render", str(bag), *map(str, args)], capture_output=True, text=True,
                          timeout=300, cwd=REPO)


def copy_bag(source, target, drop=(), edit_tf=None, namespace=""):
    """``source`` rewritten to ``target`` without the topics ``drop``; ``edit_tf`` changes each /tf message;
    every topic moved under ``namespace`` (as a recorder under that namespace names them)."""
    typestore = graph_typestore()
    specs = tuple(dataclasses.replace(spec, name=namespace + spec.name) for spec in RECORDED_TOPICS
                  if spec.name not in drop)
    writer = BagWriter(target, specs, typestore)
    with AnyReader([source], default_typestore=typestore) as reader:
        for connection, timestamp, raw in reader.messages():
            if connection.topic in drop:
                continue
            if connection.topic == TF.name and edit_tf is not None:
                message = reader.deserialize(raw, connection.msgtype)
                raw = typestore.serialize_cdr(edit_tf(message), connection.msgtype)
            writer.write(namespace + connection.topic, timestamp, bytes(raw))
    writer.close()
    return target


def test_the_bag_holds_what_a_viewer_needs(smoke_bag):
    counts = message_counts(smoke_bag)
    for topic in (TF.name, TF_STATIC.name, ROBOT_DESCRIPTION.name, CLOCK.name, OBJECT_MARKER.name):
        assert counts.get(topic, 0) > 0, f"no {topic} in the bag: {counts}"


def test_every_link_is_resolvable_from_world_at_every_tf_stamp(recording):
    assert len(recording.stamps) > 10
    links = recording.robot.links
    assert len(links) == 13  # the pybullet_data Panda, down to panda_grasptarget
    hand = []
    for stamp in recording.stamps:
        # Only /tf_static and the /tf transforms of exactly this stamp: nothing older stands in for a frame.
        poses = recording.world_poses(stamp, [*links, "object"])
        assert set(links) <= set(poses)
        hand.append(poses["panda_hand"].translation)
        markers = recording.markers_at(stamp)
        assert [m.ns for m in markers] == ["glocal_object"] and markers[0].frame == "object"
    # The robot moves through the episodes, not only stands there.
    assert np.ptp(np.array(hand), axis=0).max() > 0.05


def sampled_stamps(recording, samples=SAMPLES):
    return [recording.stamps[i] for i in np.linspace(0, len(recording.stamps) - 1, samples).round().astype(int)]


def test_rendered_frames_agree_with_the_sim_images_of_the_same_stamps(smoke_bag, recording):
    frames, states, sims = {}, {}, {}
    for stamp in sampled_stamps(recording):
        frames[stamp] = frame = bag_render.render_recording(recording, stamp)
        states[stamp] = state = bag_render.read_sim_state(smoke_bag, stamp)
        sims[stamp] = sim = bag_render.render_sim(state)
        assert frame.robot.mean() > 0.02, "the robot covers at least 2% of the image"
        assert mask_iou(frame.robot, sim.robot) >= ROBOT_IOU, stamp
        assert mask_iou(frame.foreground, sim.foreground) >= ROBOT_IOU, stamp
        if sim.object.sum() >= VISIBLE_OBJECT_PIXELS:
            assert mask_iou(frame.object, sim.object) >= OBJECT_IOU, stamp
    assert any(sim.object.sum() >= VISIBLE_OBJECT_PIXELS for sim in sims.values()), "the object is seen at all"

    # The threshold tells instants apart: the frame of one stamp against the sim image of the stamp whose
    # joints differ most from it, of CONTRAST_STAMPS spread over the run (the six sampled ones may all catch
    # the arm near its start pose: a run on a loaded machine once moved it less than 0.1 rad between them).
    for stamp in sampled_stamps(recording, CONTRAST_STAMPS):
        states.setdefault(stamp, bag_render.read_sim_state(smoke_bag, stamp))

    def joints(stamp):
        state = states[stamp]
        return np.array([state.joints[name] for name in sorted(state.joints)])

    first, second = max(((a, b) for a in states for b in states if a < b),
                        key=lambda pair: np.abs(joints(pair[0]) - joints(pair[1])).max())
    assert np.abs(joints(first) - joints(second)).max() > 0.1
    frame = frames.get(first) or bag_render.render_recording(recording, first)
    assert mask_iou(frame.robot, bag_render.render_sim(states[second]).robot) < ROBOT_IOU


def test_the_command_writes_the_frame_and_the_sim_image(smoke_bag, recording, tmp_path):
    stamp = sampled_stamps(recording)[1]
    result = render_cli(smoke_bag, "--out", tmp_path / "frame.png", "--sim-out", tmp_path / "sim.png",
                        "--stamp", stamp)
    assert result.returncode == 0, result.stdout + result.stderr
    assert "foreground IoU with the render" in result.stdout
    rendered = np.asarray(Image.open(tmp_path / "frame.png").convert("RGB"))
    sim = np.asarray(Image.open(tmp_path / "sim.png").convert("RGB"))
    assert rendered.shape == sim.shape == (480, 640, 3)

    # Not empty: where the robot is, the frame differs from what the camera sees without it.
    frame = bag_render.render_recording(recording, stamp)
    assert np.array_equal(rendered, frame.rgb), "the PNG is the frame"
    empty = bag_render.render_context()
    differs = np.abs(rendered.astype(int) - empty.rgb.astype(int)).sum(axis=2) > 30
    assert frame.robot.mean() > 0.02 and differs[frame.robot].mean() > 0.9
    # ... and so does the sim image: both show the robot in the same pixels, in the same colours.
    sim_frame = bag_render.render_sim(bag_render.read_sim_state(smoke_bag, stamp))
    both = frame.robot & sim_frame.robot
    assert np.abs(rendered[both].astype(int) - sim[both].astype(int)).mean() < 5


def test_an_unknown_time_or_stamp_picks_the_nearest_or_is_refused(smoke_bag, recording, tmp_path):
    assert recording.stamp_at(-5.0) == recording.stamps[0]
    assert recording.stamp_at(1e6) == recording.stamps[-1]
    result = render_cli(smoke_bag, "--out", tmp_path / "frame.png", "--stamp", recording.stamps[0] + 1)
    assert result.returncode == 1 and "no /tf message is stamped" in result.stderr


def test_a_bag_without_robot_description_or_tf_is_refused_naming_them(smoke_bag, tmp_path):
    bag = copy_bag(smoke_bag, tmp_path / "bag", drop=(ROBOT_DESCRIPTION.name, TF.name))
    result = render_cli(bag, "--out", tmp_path / "frame.png")
    assert result.returncode == 1, result.stdout + result.stderr
    assert "/robot_description" in result.stderr and "/tf" in result.stderr.replace("/tf_static", "")
    assert "Traceback" not in result.stderr and not (tmp_path / "frame.png").exists()

    missing = render_cli(tmp_path / "no-such-bag", "--out", tmp_path / "frame.png")
    assert missing.returncode == 1 and "no bag directory" in missing.stderr


def test_a_link_missing_from_tf_is_named(smoke_bag, recording, tmp_path):
    def drop_link3(message):
        return dataclasses.replace(message, transforms=[t for t in message.transforms
                                                        if t.child_frame_id != "panda_link3"])

    bag = copy_bag(smoke_bag, tmp_path / "bag", edit_tf=drop_link3)
    result = render_cli(bag, "--out", tmp_path / "frame.png")
    assert result.returncode == 1, result.stdout + result.stderr
    assert "'panda_link3' is not connected to 'world'" in result.stderr
    with pytest.raises(BagViewError, match="panda_link3"):
        bag_render.read_viewer_recording(bag).world_poses(recording.stamps[0])


def test_a_namespaced_bag_is_read_under_its_namespace(smoke_bag, recording, tmp_path):
    bag = copy_bag(smoke_bag, tmp_path / "bag", namespace="/robot1")
    namespaced = bag_render.read_viewer_recording(bag)
    assert namespaced.namespace == "/robot1" and namespaced.stamps == recording.stamps
    stamp = recording.stamps[len(recording.stamps) // 2]
    frame = bag_render.render_recording(namespaced, stamp)
    sim = bag_render.render_sim(bag_render.read_sim_state(bag, stamp))
    assert mask_iou(frame.foreground, sim.foreground) >= ROBOT_IOU


def test_frames_chain_like_a_tf_buffer():
    a_in_world = Transform.of((1.0, 0.0, 0.0), (0.0, 0.0, np.sin(np.pi / 4), np.cos(np.pi / 4)))  # yaw 90 degrees
    b_in_a = Transform.of((1.0, 0.0, 0.0), (0.0, 0.0, 0.0, 1.0))
    poses = resolve_frames({"a": ("world", a_in_world), "b": ("a", b_in_a)}, "world")
    assert np.allclose(poses["b"].translation, (1.0, 1.0, 0.0))
    with pytest.raises(FrameLookupError, match="'c' is not connected to 'world'.*no transform has 'x'"):
        resolve_frames({"c": ("x", b_in_a)}, "world")
    with pytest.raises(FrameLookupError, match="loop"):
        resolve_frames({"p": ("q", b_in_a), "q": ("p", b_in_a)}, "world")

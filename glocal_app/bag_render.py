"""``glocal-ros bag render``: one frame of a bag, drawn from what a viewer gets, as a PNG.

The contract, what this proves about a bag: everything a viewer (RViz,
Foxglove) needs to show the robot and the object is in the bag itself.
From the bag alone (its embedded message definitions, no glocal_interfaces)
this module reads

- ``robot_description`` (the last one): the URDF; its ``package://`` meshes
  are resolved through the ament index (``<prefix>/share/<package>/...``), as
  RViz resolves them, ``file://`` and plain absolute paths as they are;
- ``/tf_static`` (every message, later ones win per child frame, as tf2's
  static buffer keeps them) and ``/tf``: the world pose of a frame at a
  stamp chains the static transforms and the /tf transforms stamped exactly
  that stamp (the sim sends all of an instant's transforms under one stamp,
  so no interpolation is needed or done);
- ``/glocal/object_marker``: per (ns, id), the last marker whose header
  stamp is not after the chosen stamp (DELETE and DELETEALL honoured); a
  TRIANGLE_LIST placed at its frame's pose times ``marker.pose``, scaled by
  ``marker.scale``, in ``marker.color`` (per-vertex ``colors`` are not drawn;
  other marker types are refused).

It renders one frame with PyBullet's CPU TinyRenderer in DIRECT mode: each
link's visual meshes as visual-only bodies at the link's world pose, each
marker as a mesh visual shape, a table for context, one fixed camera
(``DEFAULT_CAMERA``) on the robot and the object.

``render_sim`` is the comparison: the sim's own bodies (the Panda of
pybullet_data through ``sim_node``'s ``GraspWorld``, the object's URDF from
the assets) set to the recorded state of the same stamp (``/joint_states``,
``/glocal/object_pose``, the task of ``/glocal/grasp_state``), taken with
the same camera. Both images come with segmentation masks of the robot and
the object, so that the two can be compared pixel for pixel
(``mask_iou``); ``test/test_bag_render.py`` does that on a smoke run's bag.

A bag recorded under a namespace (``/robot1/tf``, ...) is read the same:
the namespace is the prefix of its ``robot_description`` topic.
"""

from __future__ import annotations

import argparse
import bisect
import os
import sys
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from urllib.parse import unquote, urlparse

import numpy as np
import pybullet
from PIL import Image
from pybullet_utils.bullet_client import BulletClient
from rosbags.highlevel import AnyReader
from rosbags.typesys import Stores, get_typestore

from glocal_ros import topics
from glocal_ros.paths import object_urdf, objects_dir
from glocal_ros.recording import open_bag, topic_namespace
from glocal_ros.transforms import IDENTITY, FrameLookupError, Transform, resolve_frames
from glocal_ros.urdf import RobotModel, parse_urdf

WORLD_FRAME = "world"
#: Links and markers without a colour of their own.
DEFAULT_RGBA = (0.85, 0.85, 0.85, 1.0)
# visualization_msgs/Marker constants (the bag carries the definition, not these values by name).
_TRIANGLE_LIST = 11
_ADD, _DELETE, _DELETEALL = 0, 2, 3
#: Context only: a table as large as the sim's, its top at z = 0 where the robot stands. It is no
#: part of the bag, and neither image's robot/object masks include it.
_TABLE_HALF_EXTENTS = (0.6, 0.5, 0.025)
_TABLE_CENTER = (0.35, 0.0, -0.025)
_TABLE_RGBA = (0.75, 0.65, 0.5, 1.0)
#: A floor under the table (where the sim's floor plane is), so that the white robot stands out
#: against something darker than TinyRenderer's white background.
_FLOOR_HALF_EXTENTS = (4.0, 4.0, 0.01)
_FLOOR_CENTER = (0.0, 0.0, -0.71)
_FLOOR_RGBA = (0.55, 0.6, 0.68, 1.0)
# The light both images are lit by (TinyRenderer's direction towards the light), no shadows: the
# images differ only where the scenes do.
_LIGHT_DIRECTION = (0.4, -0.6, 1.0)


class BagViewError(ValueError):
    """The bag lacks what a viewer needs (the message names it), or the chosen instant is not in it."""


@dataclass(frozen=True)
class Camera:
    """A fixed pinhole camera, as PyBullet's ``computeViewMatrixFromYawPitchRoll`` places it."""

    target: tuple[float, float, float]
    distance: float
    yaw: float  # degrees
    pitch: float  # degrees
    fov: float = 50.0  # vertical, degrees
    near: float = 0.05
    far: float = 6.0

    def matrices(self, client: BulletClient, width: int, height: int) -> tuple[list[float], list[float]]:
        view = client.computeViewMatrixFromYawPitchRoll(cameraTargetPosition=self.target, distance=self.distance,
                                                        yaw=self.yaw, pitch=self.pitch, roll=0.0, upAxisIndex=2)
        projection = client.computeProjectionMatrixFOV(fov=self.fov, aspect=width / height, nearVal=self.near,
                                                       farVal=self.far)
        return view, projection


#: From the robot's side, so that the gripper does not hide the object half a metre in front of the
#: base: the whole arm at its home pose (about 0.9 m high) and the object spot.
DEFAULT_CAMERA = Camera(target=(0.35, 0.0, 0.32), distance=1.3, yaw=30.0, pitch=-22.0)


@dataclass(frozen=True)
class ObjectMesh:
    """A TRIANGLE_LIST marker as drawn: its frame, where in that frame, its triangles' corners and colour."""

    ns: str
    id: int
    frame: str
    pose: Transform  # marker.pose: the points' frame in ``frame``
    vertices: np.ndarray = field(repr=False)  # (3 * triangles, 3), scaled by marker.scale
    rgba: tuple[float, float, float, float]


@dataclass(frozen=True)
class _MarkerEvent:
    stamp: int  # header stamp, ns
    action: int
    key: tuple[str, int]
    mesh: ObjectMesh | None


@dataclass
class ViewerRecording:
    """What a viewer of the bag gets: the robot, TF over time, the object markers."""

    bag: Path
    namespace: str  # "" or e.g. "/robot1"
    description: str
    robot: RobotModel
    static: dict[str, tuple[str, Transform]]  # child -> (parent, transform), /tf_static merged
    tf: dict[int, dict[str, tuple[str, Transform]]]  # stamp (ns) -> child -> (parent, transform)
    stamps: list[int]  # the /tf stamps, ascending
    _markers: list[_MarkerEvent] = field(repr=False)

    def stamp_at(self, seconds: float) -> int:
        """The /tf stamp nearest to ``seconds`` after the first /tf stamp (the earlier one on a tie)."""
        wanted = self.stamps[0] + round(seconds * 1e9)
        index = bisect.bisect_left(self.stamps, wanted)
        candidates = self.stamps[max(0, index - 1):index + 1]
        return min(candidates, key=lambda stamp: (abs(stamp - wanted), stamp))

    def edges(self, stamp: int) -> dict[str, tuple[str, Transform]]:
        """The TF tree at ``stamp``: /tf_static and the /tf transforms of exactly that stamp."""
        if stamp not in self.tf:
            raise BagViewError(f"no /tf message is stamped {stamp} ns; the bag's /tf runs from {self.stamps[0]} "
                               f"to {self.stamps[-1]} ns")
        return {**self.static, **self.tf[stamp]}

    def world_poses(self, stamp: int, frames: list[str] | None = None) -> dict[str, Transform]:
        """World pose of every robot link (or of ``frames``) at ``stamp``; BagViewError naming a missing one."""
        try:
            return resolve_frames(self.edges(stamp), WORLD_FRAME, self.robot.links if frames is None else frames)
        except FrameLookupError as error:
            raise BagViewError(f"at /tf stamp {stamp} ns: {error}") from error

    def markers_at(self, stamp: int) -> list[ObjectMesh]:
        """The markers a viewer shows at ``stamp``: per (ns, id) the last one sent at or before it."""
        shown: dict[tuple[str, int], ObjectMesh] = {}
        for event in self._markers:  # in header-stamp order, recording order among equal stamps
            if event.stamp > stamp:
                break
            if event.action == _DELETEALL:
                shown.clear()
            elif event.action == _DELETE:
                shown.pop(event.key, None)
            elif event.mesh is not None:
                shown[event.key] = event.mesh
        return list(shown.values())


def _stamp(header) -> int:
    return int(header.stamp.sec) * 1_000_000_000 + int(header.stamp.nanosec)


def _transform(message) -> Transform:
    t, r = message.translation, message.rotation
    return Transform.of((t.x, t.y, t.z), (r.x, r.y, r.z, r.w))


def _pose(message) -> Transform:
    p, q = message.position, message.orientation
    if (q.x, q.y, q.z, q.w) == (0.0, 0.0, 0.0, 0.0):  # an unset orientation: viewers take it as identity
        return Transform.of((p.x, p.y, p.z), IDENTITY.rotation)
    return Transform.of((p.x, p.y, p.z), (q.x, q.y, q.z, q.w))


def _frame(name: str) -> str:
    return name.lstrip("/")  # tf2 frame ids carry no leading slash; tolerate one


@contextmanager
def _reader(bag: Path) -> Iterator[AnyReader]:
    """AnyReader on the bag's own message definitions (Jazzy's standard ones only if it has none)."""
    try:
        with open_bag(bag):  # a user-facing error for no bag, or a killed recorder's bag
            pass
    except ValueError as error:
        raise BagViewError(str(error)) from error
    with AnyReader([Path(bag)], default_typestore=get_typestore(Stores.ROS2_JAZZY)) as reader:
        yield reader


#: The topics a viewer of the bag needs, as the topic table names them at the root namespace.
VIEWER_TOPICS = (topics.ROBOT_DESCRIPTION, topics.TF_STATIC, topics.TF, topics.OBJECT_MARKER)


def _namespace(reader: AnyReader, namespace: str | None) -> str:
    """``namespace`` as a prefix, or the one namespace the bag's viewer topics are recorded under."""
    if namespace is not None:
        return "/" + namespace.strip("/") if namespace.strip("/") else ""
    found = sorted({namespace.rstrip("/") for connection in reader.connections for spec in VIEWER_TOPICS
                    if (namespace := topic_namespace(connection.topic, spec)) is not None})
    if len(found) > 1:
        raise BagViewError(f"the bag holds the viewer topics of several namespaces "
                           f"({', '.join(ns or '/' for ns in found)}): choose one with --namespace")
    return found[0] if found else ""


def _marker_event(marker) -> _MarkerEvent:
    key = (marker.ns, int(marker.id))
    if marker.action != _ADD:  # MODIFY (deprecated) is 0 too; DELETE and DELETEALL carry no geometry
        return _MarkerEvent(_stamp(marker.header), int(marker.action), key, None)
    if marker.type != _TRIANGLE_LIST:
        raise BagViewError(f"marker {marker.ns}/{marker.id} is of type {marker.type}: only TRIANGLE_LIST "
                           f"({_TRIANGLE_LIST}) is drawn")
    if len(marker.points) % 3 or not marker.points:
        raise BagViewError(f"marker {marker.ns}/{marker.id} has {len(marker.points)} points, not whole triangles")
    scale = np.array((marker.scale.x, marker.scale.y, marker.scale.z))
    vertices = np.array([(p.x, p.y, p.z) for p in marker.points]) * scale
    c = marker.color
    rgba = (c.r, c.g, c.b, c.a) if c.a > 0 else DEFAULT_RGBA
    mesh = ObjectMesh(marker.ns, int(marker.id), _frame(marker.header.frame_id), _pose(marker.pose), vertices,
                      tuple(float(v) for v in rgba))
    return _MarkerEvent(_stamp(marker.header), _ADD, key, mesh)


def read_viewer_recording(bag: Path, namespace: str | None = None) -> ViewerRecording:
    """Read what a viewer needs from ``bag``.

    :raises BagViewError: naming every viewer topic that is missing or empty
        (robot_description, /tf_static, /tf, the object marker), or a
        description that is no URDF.
    """
    bag = Path(bag)
    with _reader(bag) as reader:
        ns = _namespace(reader, namespace)
        names = {spec.name: ns + spec.name for spec in VIEWER_TOPICS}
        connections = [c for c in reader.connections if c.topic in names.values()]
        description: str | None = None
        static: dict[str, tuple[str, Transform]] = {}
        tf: dict[int, dict[str, tuple[str, Transform]]] = {}
        markers: list[_MarkerEvent] = []
        counts = dict.fromkeys(names.values(), 0)
        for connection, _, raw in reader.messages(connections=connections):
            message = reader.deserialize(raw, connection.msgtype)
            counts[connection.topic] += 1
            if connection.topic == names[topics.ROBOT_DESCRIPTION.name]:
                description = message.data
            elif connection.topic == names[topics.OBJECT_MARKER.name]:
                markers.append(_marker_event(message))
            else:
                is_static = connection.topic == names[topics.TF_STATIC.name]
                for transform in message.transforms:
                    edge = (_frame(transform.header.frame_id), _transform(transform.transform))
                    if is_static:
                        static[_frame(transform.child_frame_id)] = edge
                    else:
                        tf.setdefault(_stamp(transform.header), {})[_frame(transform.child_frame_id)] = edge
    missing = [topic for topic, count in counts.items() if count == 0]
    if missing:
        raise BagViewError(f"{bag} lacks what a viewer needs: no message on {', '.join(missing)}")
    try:
        robot = parse_urdf(description)
    except ValueError as error:
        raise BagViewError(f"{names[topics.ROBOT_DESCRIPTION.name]} of {bag}: {error}") from error
    markers.sort(key=lambda event: event.stamp)  # stable: recording order among equal stamps
    return ViewerRecording(bag, ns, description, robot, static, tf, sorted(tf), markers)


def resolve_mesh(uri: str) -> Path:
    """The file a viewer loads for a URDF mesh ``uri``: ``package://`` through the ament index.

    :raises BagViewError: when the package is not installed or the file is not there.
    """
    parsed = urlparse(uri)
    if parsed.scheme == "package":
        from ament_index_python.packages import PackageNotFoundError, get_package_share_directory

        # A bare venv has no AMENT_PREFIX_PATH; its own prefix is where `make setup` installs the share/.
        os.environ.setdefault("AMENT_PREFIX_PATH", sys.prefix)
        try:
            share = Path(get_package_share_directory(parsed.netloc))
        except PackageNotFoundError as error:
            raise BagViewError(f"mesh {uri}: package {parsed.netloc!r} is not in the ament index "
                               f"(AMENT_PREFIX_PATH)") from error
        path = share / unquote(parsed.path).lstrip("/")
    elif parsed.scheme == "file":
        path = Path(unquote(parsed.path))
    elif not parsed.scheme and Path(uri).is_absolute():
        path = Path(uri)
    else:
        raise BagViewError(f"mesh {uri}: a viewer cannot resolve it (neither package://, file:// nor absolute)")
    if not path.is_file():
        raise BagViewError(f"mesh {uri}: {path} does not exist")
    return path


@dataclass(frozen=True)
class Frame:
    """One rendered image, with which pixels show the robot, the object, and nothing at all."""

    rgb: np.ndarray  # (height, width, 3) uint8
    robot: np.ndarray  # (height, width) bool
    object: np.ndarray  # (height, width) bool
    background: np.ndarray  # (height, width) bool: no body (the table is neither this nor foreground)

    @property
    def foreground(self) -> np.ndarray:
        return self.robot | self.object

    def save(self, path: Path) -> None:
        path.parent.mkdir(parents=True, exist_ok=True)
        Image.fromarray(self.rgb).save(path, optimize=True)


def mask_iou(a: np.ndarray, b: np.ndarray) -> float:
    """Intersection over union of two boolean masks (1.0 when both are empty)."""
    union = np.count_nonzero(a | b)
    return 1.0 if union == 0 else np.count_nonzero(a & b) / union


def _client() -> BulletClient:
    return BulletClient(connection_mode=pybullet.DIRECT)


def _add_context(client: BulletClient) -> None:
    """The table and the floor: no part of the bag, there to show where the robot stands."""
    for half_extents, center, rgba in ((_TABLE_HALF_EXTENTS, _TABLE_CENTER, _TABLE_RGBA),
                                       (_FLOOR_HALF_EXTENTS, _FLOOR_CENTER, _FLOOR_RGBA)):
        visual = client.createVisualShape(pybullet.GEOM_BOX, halfExtents=half_extents, rgbaColor=rgba)
        client.createMultiBody(baseMass=0.0, baseVisualShapeIndex=visual, basePosition=center)


def _visual_body(client: BulletClient, visual: int, pose: Transform) -> int:
    return client.createMultiBody(baseMass=0.0, baseVisualShapeIndex=visual, basePosition=pose.translation,
                                  baseOrientation=pose.rotation)


def _snapshot(client: BulletClient, camera: Camera, width: int, height: int, robot: set[int],
              objects: set[int]) -> Frame:
    view, projection = camera.matrices(client, width, height)
    _, _, rgba, _, segmentation = client.getCameraImage(width, height, view, projection,
                                                        renderer=pybullet.ER_TINY_RENDERER,
                                                        lightDirection=_LIGHT_DIRECTION, shadow=0)
    rgb = np.asarray(rgba, dtype=np.uint8).reshape(height, width, 4)[:, :, :3]
    # Without ER_SEGMENTATION_MASK_OBJECT_AND_LINKINDEX the mask holds body ids (-1: background).
    ids = np.asarray(segmentation).reshape(height, width)
    return Frame(rgb.copy(), np.isin(ids, list(robot)), np.isin(ids, list(objects)), ids < 0)


def _mesh_shape(client: BulletClient, mesh: ObjectMesh) -> int:
    # Three corners per triangle with its face normal: flat-shaded, as RViz draws a TRIANGLE_LIST.
    corners = mesh.vertices.reshape(-1, 3, 3)
    normals = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    lengths = np.linalg.norm(normals, axis=1, keepdims=True)
    normals = np.repeat(normals / np.where(lengths > 0, lengths, 1.0), 3, axis=0)
    return client.createVisualShape(pybullet.GEOM_MESH, vertices=mesh.vertices.tolist(),
                                    indices=list(range(len(mesh.vertices))), normals=normals.tolist(),
                                    rgbaColor=mesh.rgba)


def render_recording(recording: ViewerRecording, stamp: int, camera: Camera = DEFAULT_CAMERA, width: int = 640,
                     height: int = 480) -> Frame:
    """The frame at /tf ``stamp`` of a bag, as a viewer would show it: robot links by TF, markers, a table.

    :raises BagViewError: when a link, a marker's frame or a mesh cannot be resolved at ``stamp``.
    """
    markers = recording.markers_at(stamp)
    if not markers:
        raise BagViewError(f"no object marker is shown at /tf stamp {stamp} ns (none sent at or before it)")
    links = recording.world_poses(stamp)
    frames = recording.world_poses(stamp, [marker.frame for marker in markers])
    client = _client()
    try:
        _add_context(client)
        robot = set()
        for link, pose in links.items():
            for visual in recording.robot.visuals.get(link, ()):
                shape = client.createVisualShape(pybullet.GEOM_MESH, fileName=str(resolve_mesh(visual.mesh)),
                                                 meshScale=visual.scale, rgbaColor=visual.rgba or DEFAULT_RGBA)
                robot.add(_visual_body(client, shape, pose * visual.origin))
        objects = {_visual_body(client, _mesh_shape(client, marker), frames[marker.frame] * marker.pose)
                   for marker in markers}
        return _snapshot(client, camera, width, height, robot, objects)
    finally:
        client.disconnect()


def render_context(camera: Camera = DEFAULT_CAMERA, width: int = 640, height: int = 480) -> Frame:
    """What the camera sees with neither robot nor object: what a frame's robot pixels must differ from."""
    client = _client()
    try:
        _add_context(client)
        return _snapshot(client, camera, width, height, set(), set())
    finally:
        client.disconnect()


@dataclass(frozen=True)
class SimState:
    """The recorded state of the viewer env at one stamp: what the sim image is set to."""

    stamp: int
    task: str
    joints: dict[str, float]
    object_pose: Transform  # the object's URDF link frame in the world


def _latest(stamped: list[tuple[int, object]], stamp: int, topic: str) -> object:
    """The message of ``stamped`` (ascending) with the greatest stamp not after ``stamp``."""
    index = bisect.bisect_right([s for s, _ in stamped], stamp)
    if index == 0:
        raise BagViewError(f"no {topic} message at or before stamp {stamp} ns")
    return stamped[index - 1][1]


def read_sim_state(bag: Path, stamp: int, namespace: str | None = None) -> SimState:
    """The recorded ``/joint_states``, ``/glocal/object_pose`` and task at ``stamp`` (the last not after it)."""
    wanted = (topics.JOINT_STATES, topics.OBJECT_POSE, topics.GRASP_STATE)
    with _reader(bag) as reader:
        ns = _namespace(reader, namespace)
        names = {ns + spec.name: spec.name for spec in wanted}
        found: dict[str, list[tuple[int, object]]] = {spec.name: [] for spec in wanted}
        for connection, _, raw in reader.messages(connections=[c for c in reader.connections if c.topic in names]):
            message = reader.deserialize(raw, connection.msgtype)
            found[names[connection.topic]].append((_stamp(message.header), message))
    missing = [ns + topic for topic, messages in found.items() if not messages]
    if missing:
        raise BagViewError(f"{bag} lacks the sim's state for a sim image: no message on {', '.join(missing)}")
    for messages in found.values():
        messages.sort(key=lambda item: item[0])
    joints = _latest(found[topics.JOINT_STATES.name], stamp, ns + topics.JOINT_STATES.name)
    pose = _latest(found[topics.OBJECT_POSE.name], stamp, ns + topics.OBJECT_POSE.name)
    grasp = _latest(found[topics.GRASP_STATE.name], stamp, ns + topics.GRASP_STATE.name)
    return SimState(stamp, grasp.task, dict(zip(joints.name, (float(p) for p in joints.position))),
                    _pose(pose.pose))


def render_sim(state: SimState, camera: Camera = DEFAULT_CAMERA, width: int = 640, height: int = 480,
               objects: Path | None = None) -> Frame:
    """The sim's own image of ``state``: its world (Panda, table, the task's object URDF) set to it.

    :raises BagViewError: when a recorded joint is not the robot's or the task's URDF is missing.
    """
    from sim_node.grasp_world import GraspWorld

    client = _client()
    try:
        world = GraspWorld(client, timestep=1.0 / 240.0)
        urdf = object_urdf(objects or objects_dir(), state.task)
        try:
            model = world.load_object(state.task, urdf)
        except FileNotFoundError as error:
            raise BagViewError(str(error)) from error
        body = world.robot.body
        indices = {client.getJointInfo(body, j)[1].decode(): j for j in range(client.getNumJoints(body))}
        unknown = sorted(set(state.joints) - set(indices))
        if unknown:
            raise BagViewError(f"/joint_states names joints the sim's robot lacks: {', '.join(unknown)}")
        for name, position in state.joints.items():
            client.resetJointState(body, indices[name], position)
        # The recorded pose is the link frame's; PyBullet places the body by its inertial frame.
        position, orientation = client.multiplyTransforms(state.object_pose.translation,
                                                          state.object_pose.rotation, *model.inertial_frame)
        client.resetBasePositionAndOrientation(model.body, position, orientation)
        return _snapshot(client, camera, width, height, {body}, {model.body})
    finally:
        client.disconnect()


def choose_stamp(recording: ViewerRecording, seconds: float | None, stamp: int | None) -> int:
    """``--stamp`` as given (a /tf stamp), ``--time`` the nearest /tf stamp, else the middle one."""
    if stamp is not None:
        recording.edges(stamp)  # BagViewError naming the bag's range when it is not a /tf stamp
        return stamp
    if seconds is not None:
        return recording.stamp_at(seconds)
    return recording.stamps[len(recording.stamps) // 2]


def cmd_bag_render(args: argparse.Namespace) -> int:
    """Render one instant of a bag to PNG (and the sim's image of it); exit code 1 when the bag cannot show it."""
    if args.width < 1 or args.height < 1:
        raise ValueError(f"--width and --height must be at least 1, got {args.width} x {args.height}")
    try:
        recording = read_viewer_recording(args.bag, args.namespace)
        stamp = choose_stamp(recording, args.time, args.stamp)
        frame = render_recording(recording, stamp, width=args.width, height=args.height)
        frame.save(args.out)
        offset = (stamp - recording.stamps[0]) / 1e9
        print(f"{args.out}: /tf stamp {stamp} ns ({offset:.3f} s after the first), {len(recording.robot.links)} "
              f"links, {len(recording.markers_at(stamp))} marker(s); {np.count_nonzero(frame.robot)} robot and "
              f"{np.count_nonzero(frame.object)} object pixels")
        if args.sim_out is not None:
            state = read_sim_state(args.bag, stamp, recording.namespace)
            sim = render_sim(state, width=args.width, height=args.height, objects=args.objects_dir)
            sim.save(args.sim_out)
            print(f"{args.sim_out}: the sim's image of task {state.task} at that stamp; foreground IoU with the "
                  f"render {mask_iou(frame.foreground, sim.foreground):.3f} (robot "
                  f"{mask_iou(frame.robot, sim.robot):.3f}, object {mask_iou(frame.object, sim.object):.3f})")
    except BagViewError as error:
        print(f"glocal-ros bag render: error: {error}", file=sys.stderr)
        return 1
    return 0

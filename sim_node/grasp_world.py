"""The scene of the grasp task: a Panda on a table, one object, a floor.

World frame: the robot base stands at the origin on the table top (z = 0);
objects are placed around ``OBJECT_SPOT``, half a metre in front of the robot.
Only the current task's object is loaded; switching tasks swaps the body.

Objects are single-link URDFs whose inertia is taken from the file. Poses of
an object are those of its URDF link frame, the frame its meshes are written
in. PyBullet itself tracks the principal-axes frame of the inertia, turned
away from the link frame whenever the inertia tensor is not diagonal.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from xml.etree import ElementTree

import numpy as np
import pybullet
from pybullet_utils.bullet_client import BulletClient

from sim_node.panda_robot import LEFT_FINGER_LINK, RIGHT_FINGER_LINK, PandaRobot

TABLE_TOP_Z = 0.0
OBJECT_SPOT = (0.5, 0.0)
"""Nominal object position on the table (x, y, m)."""

_TABLE_HALF_EXTENTS = (0.6, 0.5, 0.025)
_TABLE_CENTER = (0.35, 0.0, TABLE_TOP_Z - _TABLE_HALF_EXTENTS[2])
# Catches objects knocked off the table so they come to rest instead of falling forever.
_FLOOR_Z = -0.7
_DROP_CLEARANCE = 0.002
_SETTLE_CHUNK = 12
_REST_LINEAR_SPEED = 0.005
_REST_ANGULAR_SPEED = 0.02
_GRAVITY = -9.81
_IDENTITY_POSE = ((0.0, 0.0, 0.0), (0.0, 0.0, 0.0, 1.0))
# Points per circle when round primitives are turned into points.
_CIRCLE_POINTS = 32


@dataclass(frozen=True)
class ObjectModel:
    """The loaded object of a task."""

    task: str
    urdf: Path
    body: int
    inertial_frame: tuple[tuple[float, ...], tuple[float, ...]]
    """Pose of PyBullet's base frame (position, quaternion xyzw) in the link frame."""
    points: np.ndarray = field(repr=False, compare=False)
    """Vertices of the collision geometry in the link frame, (n, 3) (m)."""


class GraspWorld:
    """Table, floor, robot and the current task's object in one physics client.

    :param client: the physics client, owned by the caller.
    :param timestep: physics step (s).
    """

    def __init__(self, client: BulletClient, timestep: float):
        self.client = client
        # Sorting the broadphase pairs makes contact order, and so the whole
        # simulation, independent of which bodies touched in earlier episodes.
        client.setPhysicsEngineParameter(deterministicOverlappingPairs=1)
        client.setTimeStep(timestep)
        client.setGravity(0.0, 0.0, _GRAVITY)
        self.robot = PandaRobot(client)
        shape = client.createCollisionShape(pybullet.GEOM_BOX, halfExtents=_TABLE_HALF_EXTENTS)
        visual = client.createVisualShape(
            pybullet.GEOM_BOX, halfExtents=_TABLE_HALF_EXTENTS, rgbaColor=(0.75, 0.65, 0.5, 1.0)
        )
        self.table = client.createMultiBody(0.0, shape, visual, basePosition=_TABLE_CENTER)
        floor = client.createCollisionShape(pybullet.GEOM_PLANE)
        client.createMultiBody(0.0, floor, basePosition=(0.0, 0.0, _FLOOR_Z))
        self.object: ObjectModel | None = None
        self._link_from_base: tuple[tuple[float, ...], tuple[float, ...]] = _IDENTITY_POSE
        self._rest_z = 0.0
        self._initial_state: int | None = None

    def load_object(self, task: str, urdf: Path) -> ObjectModel:
        """Replace the current object, if any, by the one in ``urdf``.

        :raises FileNotFoundError: when ``urdf`` or a mesh it names does not exist.
        :raises ValueError: when its collision geometry is not a box, cylinder,
            sphere or OBJ mesh.
        """
        if not urdf.is_file():
            raise FileNotFoundError(f"no object model for task {task}: {urdf} does not exist")
        points = collision_points(urdf)
        if self.object is not None:
            self.client.removeBody(self.object.body)
            self.client.removeState(self._initial_state)
            self.object = None
        body = self.client.loadURDF(
            str(urdf), (*OBJECT_SPOT, TABLE_TOP_Z + 1.0), flags=pybullet.URDF_USE_INERTIA_FROM_FILE
        )
        inertial_frame = tuple(self.client.getDynamicsInfo(body, -1)[3:5])
        self._link_from_base = self.client.invertTransform(*inertial_frame)
        self.object = ObjectModel(task, urdf, body, inertial_frame, points)
        self.robot.reset()
        # Every episode starts from this snapshot: restoring it also clears the
        # contact caches that teleporting bodies leaves behind.
        self._initial_state = self.client.saveState()
        return self.object

    def reset(self, x: float, y: float, yaw: float, settle_substeps: int, max_settle_substeps: int) -> None:
        """Put the robot home and drop the object, link frame upright, at ``(x, y)`` with ``yaw``.

        The object settles for at least ``settle_substeps`` physics steps and
        then until it is at rest, up to ``max_settle_substeps``. Its settled
        height becomes the reference for ``object_lift``.
        """
        model = self._require_object()
        self.client.restoreState(self._initial_state)
        self.robot.reset()
        z = TABLE_TOP_Z - model.points[:, 2].min() + _DROP_CLEARANCE
        link_orientation = pybullet.getQuaternionFromEuler((0.0, 0.0, yaw))
        position, orientation = self.client.multiplyTransforms(
            (x, y, z), link_orientation, *model.inertial_frame
        )
        self.client.resetBasePositionAndOrientation(model.body, position, orientation)
        self.client.resetBaseVelocity(model.body, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0))
        self.step(settle_substeps)
        # Objects that tip over on landing need longer than the minimum.
        for _ in range(settle_substeps, max_settle_substeps, _SETTLE_CHUNK):
            linear, angular = self.client.getBaseVelocity(model.body)
            if np.linalg.norm(linear) < _REST_LINEAR_SPEED and np.linalg.norm(angular) < _REST_ANGULAR_SPEED:
                break
            self.step(_SETTLE_CHUNK)
        self._rest_z = self.object_pose()[0][2]

    def step(self, substeps: int) -> None:
        """Advance the physics by ``substeps`` steps."""
        for _ in range(substeps):
            self.client.stepSimulation()

    def object_pose(self) -> tuple[np.ndarray, np.ndarray]:
        """Position (m) and orientation (quaternion xyzw) of the object's link frame, world frame."""
        base = self.client.getBasePositionAndOrientation(self._require_object().body)
        position, orientation = self.client.multiplyTransforms(*base, *self._link_from_base)
        return np.array(position), np.array(orientation)

    def object_lift(self, position: np.ndarray) -> float:
        """Height of the object's link frame above where it settled after the reset (m)."""
        return float(position[2] - self._rest_z)

    def object_points(self) -> np.ndarray:
        """Vertices of the object's collision geometry, world frame, (n, 3) (m)."""
        position, orientation = self.object_pose()
        rotation = np.array(self.client.getMatrixFromQuaternion(orientation)).reshape(3, 3)
        return self._require_object().points @ rotation.T + position

    def finger_contacts(self) -> tuple[bool, bool]:
        """Whether the left and the right finger touch the object."""
        body = self._require_object().body
        return (
            bool(self.client.getContactPoints(self.robot.body, body, LEFT_FINGER_LINK)),
            bool(self.client.getContactPoints(self.robot.body, body, RIGHT_FINGER_LINK)),
        )

    def camera_image(self, width: int, height: int) -> np.ndarray:
        """RGB image (height, width, 3, uint8) from a fixed camera looking at the object spot."""
        view = self.client.computeViewMatrixFromYawPitchRoll(
            cameraTargetPosition=(*OBJECT_SPOT, TABLE_TOP_Z),
            distance=0.9,
            yaw=50.0,
            pitch=-35.0,
            roll=0.0,
            upAxisIndex=2,
        )
        projection = self.client.computeProjectionMatrixFOV(
            fov=60.0, aspect=width / height, nearVal=0.05, farVal=5.0
        )
        _, _, rgba, _, _ = self.client.getCameraImage(width, height, view, projection)
        return np.asarray(rgba, dtype=np.uint8).reshape(height, width, 4)[:, :, :3]

    def _require_object(self) -> ObjectModel:
        if self.object is None:
            raise RuntimeError("no object loaded")
        return self.object


def collision_points(urdf: Path) -> np.ndarray:
    """Points spanning the collision geometry of ``urdf``, in its link frame, (n, 3) (m).

    Mesh vertices as they are; boxes by their corners; cylinders and spheres
    by circles of points. Their convex hull is the object's (within 0.5% of a
    radius for round shapes), which is what grasp widths depend on.
    """
    points = []
    for collision in ElementTree.parse(urdf).getroot().iter("collision"):
        origin = collision.find("origin")
        xyz = _floats(origin, "xyz", "0 0 0")
        rpy = _floats(origin, "rpy", "0 0 0")
        quaternion = pybullet.getQuaternionFromEuler(rpy)
        rotation = np.array(pybullet.getMatrixFromQuaternion(quaternion)).reshape(3, 3)
        shape = collision.find("geometry")[0]
        points.append(_shape_points(shape, urdf.parent) @ rotation.T + xyz)
    if not points:
        raise ValueError(f"{urdf} has no collision geometry")
    return np.concatenate(points)


def _floats(element: ElementTree.Element | None, name: str, default: str) -> np.ndarray:
    text = default if element is None else element.get(name, default)
    return np.array(text.split(), dtype=float)


def _shape_points(shape: ElementTree.Element, directory: Path) -> np.ndarray:
    angles = np.linspace(0.0, 2 * math.pi, _CIRCLE_POINTS, endpoint=False)
    circle = np.stack((np.cos(angles), np.sin(angles)), axis=1)
    if shape.tag == "box":
        half = _floats(shape, "size", "0 0 0") / 2
        corners = np.array([(sx, sy, sz) for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)], dtype=float)
        return corners * half
    if shape.tag == "cylinder":
        radius, half_length = float(shape.get("radius")), float(shape.get("length")) / 2
        ring = radius * circle
        return np.concatenate([_at_height(ring, z) for z in (-half_length, half_length)])
    if shape.tag == "sphere":
        radius = float(shape.get("radius"))
        latitudes = np.linspace(-math.pi / 2, math.pi / 2, _CIRCLE_POINTS // 2 + 1)
        rings = [_at_height(math.cos(latitude) * circle, math.sin(latitude)) for latitude in latitudes]
        return radius * np.concatenate(rings)
    if shape.tag == "mesh" and shape.get("filename", "").lower().endswith(".obj"):
        path = directory / shape.get("filename")
        if not path.is_file():
            raise FileNotFoundError(f"collision mesh {path} does not exist")
        with path.open() as lines:
            vertices = [line.split()[1:4] for line in lines if line.startswith("v ")]
        return np.array(vertices, dtype=float) * _floats(shape, "scale", "1 1 1")
    raise ValueError(
        f"unsupported collision geometry <{shape.tag} {dict(shape.attrib)}>: "
        "use box, cylinder, sphere or an OBJ mesh"
    )


def _at_height(circle: np.ndarray, z: float) -> np.ndarray:
    return np.column_stack((circle, np.full(len(circle), z)))

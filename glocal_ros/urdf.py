"""The parts of a URDF that viewers use: the joint tree and each link's visual meshes.

ROS-free. The sim node reads the joint tree of the robot it publishes
(which transforms go to /tf_static, which to /tf); the bag renderer reads
the joint tree and the visuals of the ``robot_description`` a bag recorded.
Only what those two need is read: no limits, inertia or collision geometry.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from xml.etree import ElementTree

from glocal_ros.transforms import IDENTITY, Transform, rpy_quaternion

#: Joint types whose child never moves relative to its parent: their transforms are static.
FIXED_JOINT_TYPES = frozenset({"fixed"})


@dataclass(frozen=True)
class Joint:
    name: str
    type: str  # revolute, prismatic, fixed, continuous, ...
    parent: str  # link names
    child: str
    origin: Transform  # the child's frame in the parent's at joint position 0

    @property
    def fixed(self) -> bool:
        return self.type in FIXED_JOINT_TYPES


@dataclass(frozen=True)
class Visual:
    mesh: str  # the filename as written (package://, file:// or relative)
    origin: Transform  # the mesh's frame in its link's
    scale: tuple[float, float, float] = (1.0, 1.0, 1.0)
    rgba: tuple[float, float, float, float] | None = None


@dataclass(frozen=True)
class RobotModel:
    name: str
    links: tuple[str, ...]
    joints: tuple[Joint, ...]
    visuals: dict[str, tuple[Visual, ...]] = field(default_factory=dict)  # link -> its mesh visuals

    @property
    def root(self) -> str:
        """The one link that is no joint's child."""
        children = {joint.child for joint in self.joints}
        roots = [link for link in self.links if link not in children]
        if len(roots) != 1:
            raise ValueError(f"robot {self.name!r} has {len(roots)} root links ({', '.join(roots)}), not one")
        return roots[0]


def _origin(element: ElementTree.Element | None) -> Transform:
    if element is None:
        return IDENTITY
    xyz = [float(v) for v in element.get("xyz", "0 0 0").split()]
    rpy = [float(v) for v in element.get("rpy", "0 0 0").split()]
    return Transform.of(xyz, rpy_quaternion(*rpy))


def _rgba(visual: ElementTree.Element, materials: dict[str, tuple[float, ...]]) -> tuple[float, ...] | None:
    """The visual's colour as urdfdom (RViz) and PyBullet resolve it.

    A material name known already (top level, or defined in an earlier
    link's visual) wins, even over a colour given here; a named material
    first defined inside a visual joins ``materials`` for the links after
    it. The pybullet_data Panda relies on that: link0 defines
    ``panda_white``, the other links only name it.
    """
    material = visual.find("material")
    if material is None:
        return None
    name = material.get("name", "")
    if name and name in materials:
        return materials[name]
    color = material.find("color")
    if color is None:
        return None
    rgba = tuple(float(v) for v in color.get("rgba", "1 1 1 1").split())
    if name:
        materials[name] = rgba
    return rgba


def parse_urdf(text: str) -> RobotModel:
    """Read a URDF document; ValueError (naming what is wrong) when it is not one."""
    try:
        robot = ElementTree.fromstring(text)
    except ElementTree.ParseError as error:
        raise ValueError(f"not a URDF document: {error}") from error
    if robot.tag != "robot":
        raise ValueError(f"not a URDF document: its root element is <{robot.tag}>, not <robot>")
    materials = {}
    for material in robot.findall("material"):
        color = material.find("color")
        if color is not None:
            materials[material.get("name", "")] = tuple(float(v) for v in color.get("rgba", "1 1 1 1").split())
    links, visuals = [], {}
    for link in robot.findall("link"):
        name = link.get("name")
        links.append(name)
        meshes = []
        for visual in link.findall("visual"):
            mesh = visual.find("geometry/mesh")
            if mesh is None:
                continue  # boxes, cylinders and spheres: the Panda and the objects have none
            scale = tuple(float(v) for v in mesh.get("scale", "1 1 1").split())
            meshes.append(Visual(mesh.get("filename"), _origin(visual.find("origin")), scale,
                                 _rgba(visual, materials)))
        visuals[name] = tuple(meshes)
    joints = []
    for joint in robot.findall("joint"):
        parent, child = joint.find("parent"), joint.find("child")
        if parent is None or child is None:
            raise ValueError(f"joint {joint.get('name')!r} lacks a parent or child link")
        joints.append(Joint(joint.get("name"), joint.get("type"), parent.get("link"), child.get("link"),
                            _origin(joint.find("origin"))))
    return RobotModel(robot.get("name", ""), tuple(links), tuple(joints), visuals)

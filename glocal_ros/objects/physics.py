"""Mass properties, V-HACD collision hulls and the URDF the simulator loads."""

from __future__ import annotations

import contextlib
import os
import tempfile
from dataclasses import dataclass
from pathlib import Path
from typing import Iterator

import numpy as np
import pybullet as p
import trimesh

from glocal_ros.objects.meshing import write_obj
from glocal_ros.objects.metrics import FRICTION_COEFFICIENT


@dataclass(frozen=True)
class MassConfig:
    """Plastic-like solid. 600 kg/m^3 is a 3D print in PLA (1240 kg/m^3) at
    partial infill; the clip keeps every object within what the Panda gripper
    lifts comfortably and comparable across tasks."""

    density: float = 600.0
    min_mass: float = 0.05
    max_mass: float = 0.15


@dataclass(frozen=True)
class FrictionConfig:
    """Contact parameters written into the URDF ``<contact>`` block.

    Bullet's friction at a contact is the product of the two bodies'
    coefficients, and the Panda's fingers have 1.0 (pybullet_data's
    panda.urdf), so the object's ``lateral`` is the grasp's mu: the grasp
    metric's (``FRICTION_COEFFICIENT``), so that a grasp the metric counts
    outside the friction cone slips in the simulator too. (Until generator
    2.0.0 it was 1.0, and almost any grasp held.)
    """

    lateral: float = FRICTION_COEFFICIENT
    spinning: float = 0.001
    rolling: float = 0.0001


@dataclass(frozen=True)
class VhacdConfig:
    """pybullet V-HACD settings, chosen for few hulls (simulation speed).

    ``depth`` bounds the number of clipping stages, so at most 2**depth
    hulls before merging; if the result still has more than ``max_hulls``,
    the decomposition is repeated with a smaller depth.
    """

    resolution: int = 200_000
    depth: int = 4
    concavity: float = 0.0025
    max_vertices_per_hull: int = 24
    max_hulls: int = 8


@dataclass(frozen=True)
class MassProperties:
    volume: float
    mass: float
    inertia: np.ndarray


def mass_properties(solid: trimesh.Trimesh, config: MassConfig) -> MassProperties:
    """Mass from volume x density (clipped), inertia about the mesh origin scaled to that mass.

    ``solid`` must be watertight with its centre of mass at the origin.
    """
    volume = float(solid.volume)
    mass = float(np.clip(config.density * volume, config.min_mass, config.max_mass))
    unit = solid.copy()
    unit.density = 1.0
    inertia = np.asarray(unit.moment_inertia) * (mass / volume)
    return MassProperties(volume=volume, mass=mass, inertia=inertia)


@contextlib.contextmanager
def _quiet_stdout() -> Iterator[None]:
    # pybullet's V-HACD prints its progress from C; only an fd-level
    # redirect silences it.
    saved = os.dup(1)
    try:
        with open(os.devnull, "w") as devnull:
            os.dup2(devnull.fileno(), 1)
            yield
    finally:
        os.dup2(saved, 1)
        os.close(saved)


def convex_decomposition(solid: trimesh.Trimesh, out_path: Path, config: VhacdConfig) -> tuple[int, int]:
    """Run V-HACD on ``solid`` and write the hulls (one OBJ object each) to ``out_path``.

    Returns (hull count, total hull vertices).
    """
    with tempfile.TemporaryDirectory() as tmp:
        source = Path(tmp) / "solid.obj"
        write_obj(solid, source, digits=6)
        depth = config.depth
        while True:
            with _quiet_stdout():
                p.vhacd(
                    str(source),
                    str(out_path),
                    str(Path(tmp) / "vhacd.log"),
                    resolution=config.resolution,
                    depth=depth,
                    concavity=config.concavity,
                    maxNumVerticesPerCH=config.max_vertices_per_hull,
                )
            hulls, vertices = _count_hulls(out_path)
            if hulls <= config.max_hulls or depth <= 1:
                return hulls, vertices
            depth -= 1


def _count_hulls(obj_path: Path) -> tuple[int, int]:
    hulls = vertices = 0
    with open(obj_path) as f:
        for line in f:
            if line.startswith("o "):
                hulls += 1
            elif line.startswith("v "):
                vertices += 1
    return hulls, vertices


def write_urdf(
    path: Path,
    name: str,
    props: MassProperties,
    friction: FrictionConfig,
    rgba: tuple[float, float, float, float] = (0.9, 0.55, 0.2, 1.0),
) -> None:
    """URDF with ``visual.obj`` / ``collision.obj`` next to it.

    The link frame is the centre of mass, so the inertial origin is zero.
    pybullet recomputes inertia from the collision shape unless loaded with
    ``flags=p.URDF_USE_INERTIA_FROM_FILE``; pass it to use these values.
    """
    i = props.inertia
    colour = " ".join(f"{c:g}" for c in rgba)
    path.write_text(
        f"""<?xml version="1.0"?>
<robot name="{name}">
  <link name="{name}">
    <contact>
      <lateral_friction value="{friction.lateral:g}"/>
      <spinning_friction value="{friction.spinning:g}"/>
      <rolling_friction value="{friction.rolling:g}"/>
    </contact>
    <inertial>
      <origin xyz="0 0 0" rpy="0 0 0"/>
      <mass value="{props.mass:.6g}"/>
      <inertia ixx="{i[0, 0]:.6e}" ixy="{i[0, 1]:.6e}" ixz="{i[0, 2]:.6e}" iyy="{i[1, 1]:.6e}" iyz="{i[1, 2]:.6e}" izz="{i[2, 2]:.6e}"/>
    </inertial>
    <visual>
      <origin xyz="0 0 0" rpy="0 0 0"/>
      <geometry><mesh filename="visual.obj" scale="1 1 1"/></geometry>
      <material name="{name}_colour"><color rgba="{colour}"/></material>
    </visual>
    <collision>
      <origin xyz="0 0 0" rpy="0 0 0"/>
      <geometry><mesh filename="collision.obj" scale="1 1 1"/></geometry>
    </collision>
  </link>
</robot>
"""
    )

"""Small primitive objects written as URDF, for env tests independent of the generated set."""

from __future__ import annotations

from pathlib import Path

BOX_TASK, CYLINDER_TASK = "A0", "B3"


def write_object(objects_dir: Path, task: str, geometry: str, inertia: tuple[float, float, float]) -> None:
    """A 100 g single-link URDF with friction 1 (the generated objects have 0.5: these stay easy to grasp)."""
    ixx, iyy, izz = inertia
    (objects_dir / task).mkdir(parents=True, exist_ok=True)
    (objects_dir / task / "model.urdf").write_text(
        f"""<?xml version="1.0"?>
<robot name="{task}">
  <link name="base">
    <contact><lateral_friction value="1.0"/></contact>
    <inertial>
      <mass value="0.1"/>
      <inertia ixx="{ixx}" ixy="0" ixz="0" iyy="{iyy}" iyz="0" izz="{izz}"/>
    </inertial>
    <visual><geometry>{geometry}</geometry></visual>
    <collision><geometry>{geometry}</geometry></collision>
  </link>
</robot>
"""
    )


def write_test_objects(objects_dir: Path) -> Path:
    """A0: a 4 x 6 x 5 cm box; B3: a cylinder of radius 2.8 cm, 6 cm tall."""
    x, y, z = 0.04, 0.06, 0.05
    box_inertia = (0.1 * (y * y + z * z) / 12, 0.1 * (x * x + z * z) / 12, 0.1 * (x * x + y * y) / 12)
    write_object(objects_dir, BOX_TASK, f'<box size="{x} {y} {z}"/>', box_inertia)
    r, h = 0.028, 0.06
    side = 0.1 * (3 * r * r + h * h) / 12
    cylinder = f'<cylinder radius="{r}" length="{h}"/>'
    write_object(objects_dir, CYLINDER_TASK, cylinder, (side, side, 0.1 * r * r / 2))
    return objects_dir

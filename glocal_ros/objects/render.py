"""Contact sheet of the 7x7 object grid, rendered with pybullet's TinyRenderer."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pybullet as p
from PIL import Image, ImageDraw, ImageFont

from glocal_ros.tasks import ALL_TASKS, COMPLEXITY_LEVELS, DIFFICULTY_LEVELS

_TILE = 160
_MARGIN = 28
# One fixed camera for every tile, so relative sizes on the sheet are real.
_CAMERA_DISTANCE = 0.19
_COLOUR = (0.95, 0.55, 0.2, 1.0)


def render_mesh(client: int, mesh_path: Path, size: int = _TILE) -> np.ndarray:
    """RGB image (size x size x 3, uint8) of one mesh seen from above at an angle."""
    shape = p.createVisualShape(p.GEOM_MESH, fileName=str(mesh_path), rgbaColor=_COLOUR, physicsClientId=client)
    body = p.createMultiBody(baseMass=0, baseVisualShapeIndex=shape, physicsClientId=client)
    view = p.computeViewMatrixFromYawPitchRoll(
        cameraTargetPosition=(0, 0, 0), distance=_CAMERA_DISTANCE, yaw=35, pitch=-40, roll=0, upAxisIndex=2
    )
    proj = p.computeProjectionMatrixFOV(fov=40, aspect=1.0, nearVal=0.01, farVal=1.0)
    _, _, rgba, _, _ = p.getCameraImage(
        size,
        size,
        viewMatrix=view,
        projectionMatrix=proj,
        renderer=p.ER_TINY_RENDERER,
        lightDirection=(0.4, -0.6, 1.0),
        shadow=0,
        physicsClientId=client,
    )
    p.removeBody(body, physicsClientId=client)
    return np.asarray(rgba, dtype=np.uint8).reshape(size, size, 4)[:, :, :3]


def render_contact_sheet(objects_dir: Path, png_path: Path, tasks: tuple[str, ...] = ALL_TASKS) -> Path:
    """Render ``<objects_dir>/<TASK>/visual.obj`` for every task into one labelled grid PNG.

    Rows are difficulty A..G (top to bottom), columns complexity 0..6; a
    missing task leaves its tile blank.
    """
    objects_dir, png_path = Path(objects_dir), Path(png_path)
    n_rows, n_cols = len(DIFFICULTY_LEVELS), len(COMPLEXITY_LEVELS)
    sheet = Image.new("RGB", (_MARGIN + n_cols * _TILE, _MARGIN + n_rows * _TILE), "white")
    draw = ImageDraw.Draw(sheet)
    font = ImageFont.load_default()
    client = p.connect(p.DIRECT)
    try:
        for task in tasks:
            mesh_path = objects_dir / task / "visual.obj"
            if not mesh_path.exists():
                continue
            row, col = DIFFICULTY_LEVELS.index(task[0]), COMPLEXITY_LEVELS.index(task[1])
            x, y = _MARGIN + col * _TILE, _MARGIN + row * _TILE
            sheet.paste(Image.fromarray(render_mesh(client, mesh_path)), (x, y))
            draw.text((x + 4, y + 4), task, fill="black", font=font)
    finally:
        p.disconnect(client)
    for col, digit in enumerate(COMPLEXITY_LEVELS):
        draw.text((_MARGIN + col * _TILE + _TILE // 2 - 4, 8), digit, fill="black", font=font)
    for row, letter in enumerate(DIFFICULTY_LEVELS):
        draw.text((10, _MARGIN + row * _TILE + _TILE // 2 - 6), letter, fill="black", font=font)
    for i in range(n_cols + 1):
        draw.line([(_MARGIN + i * _TILE, _MARGIN), (_MARGIN + i * _TILE, sheet.height)], fill=(200, 200, 200))
    for i in range(n_rows + 1):
        draw.line([(_MARGIN, _MARGIN + i * _TILE), (sheet.width, _MARGIN + i * _TILE)], fill=(200, 200, 200))
    png_path.parent.mkdir(parents=True, exist_ok=True)
    sheet.save(png_path)
    return png_path

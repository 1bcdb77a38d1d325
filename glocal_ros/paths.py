"""Where the project's data lives, in a source checkout and when installed.

A source checkout (or an editable install) keeps ``assets/`` and
``msg_schemas/`` next to the packages; an installed package (colcon, or
``setup.py install_data``) has them under ``share/glocal_ros`` and
``share/glocal_interfaces`` of its prefix.
"""

from __future__ import annotations

import hashlib
import os
import sys
from pathlib import Path

from glocal_ros.tasks import object_name

SOURCE_ROOT = Path(__file__).resolve().parent.parent


def _installed_share(package: str) -> Path | None:
    prefixes = [p for p in os.environ.get("AMENT_PREFIX_PATH", "").split(os.pathsep) if p] + [sys.prefix]
    for prefix in prefixes:
        share = Path(prefix) / "share" / package
        if share.is_dir():
            return share
    return None


def assets_dir() -> Path:
    """``assets/``: object set, priors, parameter presets."""
    if (SOURCE_ROOT / "assets").is_dir():
        return SOURCE_ROOT / "assets"
    share = _installed_share("glocal_ros")
    if share is None or not (share / "assets").is_dir():
        raise FileNotFoundError("no assets/ in the source tree nor in share/glocal_ros of AMENT_PREFIX_PATH")
    return share / "assets"


def objects_dir() -> Path:
    return assets_dir() / "objects"


def object_urdf(objects: Path, task: str) -> Path:
    """The URDF of ``task``'s object in the object set ``objects`` (the layout `assets generate` writes); a
    novel task's object is its name's directory (``glocal_ros.tasks.object_name``)."""
    return Path(objects) / object_name(task) / "model.urdf"


def object_fingerprint(name: str, objects: Path | None = None) -> str:
    """A hash of the files of the object ``name`` (a grid task, or a novel object's name) in the object set
    ``objects`` (None: the shipped set): the files an env loads, so equal fingerprints are the same object."""
    digest = hashlib.sha256()
    for path in sorted((Path(objects or objects_dir()) / name).iterdir()):
        if path.is_file():
            digest.update(path.name.encode() + b"\0" + path.read_bytes() + b"\0")
    return digest.hexdigest()[:16]


def ros_home() -> Path:
    """``$ROS_HOME``, ``~/.ros`` when unset (as ROS 2 itself decides): where nodes keep state by default."""
    return Path(os.environ.get("ROS_HOME", Path.home() / ".ros"))


def interface_definitions_dir() -> Path:
    """The .msg files of glocal_interfaces (message definitions for recording)."""
    if (SOURCE_ROOT / "msg_schemas" / "msg").is_dir():
        return SOURCE_ROOT / "msg_schemas" / "msg"
    share = _installed_share("glocal_interfaces")
    if share is None:
        raise FileNotFoundError("glocal_interfaces is not installed: run `make setup`")
    return share / "msg"

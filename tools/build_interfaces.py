"""Build the interface packages into this Python's prefix: ``glocal_interfaces``
(msg_schemas/) and ``tf2_msgs`` (tools/tf2_msgs/: TFMessage as upstream, which
the ROS 2 wheels lack).

Run with the virtual environment's interpreter: the ROS wheels' bootstrapper
has then already put the ROS libraries on ``LD_LIBRARY_PATH``, which the
rosidl generators that CMake runs need.

The ROS 2 Jazzy wheels ship CMake config files that name the wheel builder's
Python (``/opt/python/cp311-cp311/...``); they are rewritten to this Python's
include directory and NumPy's before configuring. Each package's build is
skipped when it was installed from the same sources (a content hash).
"""

from __future__ import annotations

import argparse
import hashlib
import subprocess
import sys
import sysconfig
from pathlib import Path

WHEEL_BUILDER_PYTHON_INCLUDE = "/opt/python/cp311-cp311/include/python3.11"
WHEEL_BUILDER_NUMPY_INCLUDE = "/opt/python/cp311-cp311/lib/python3.11/site-packages/numpy/_core/include"


def sources_digest(source_dir: Path) -> str:
    digest = hashlib.sha256()
    for path in sorted(p for p in source_dir.rglob("*") if p.is_file()):
        digest.update(str(path.relative_to(source_dir)).encode())
        digest.update(path.read_bytes())
    return digest.hexdigest()


def rewrite_wheel_builder_paths(prefix: Path) -> int:
    """Point the wheels' CMake files at this machine's Python and NumPy headers."""
    import numpy

    replacements = {
        WHEEL_BUILDER_PYTHON_INCLUDE: sysconfig.get_paths()["include"],
        WHEEL_BUILDER_NUMPY_INCLUDE: numpy.get_include(),
    }
    rewritten = 0
    for cmake_file in (prefix / "share").rglob("*.cmake"):
        text = cmake_file.read_text()
        if "/opt/python/cp311-cp311" not in text:
            continue
        for old, new in replacements.items():
            text = text.replace(old, new)
        cmake_file.write_text(text)
        rewritten += 1
    return rewritten


REPO = Path(__file__).resolve().parent.parent
#: Built in this order: (name, source folder).
PACKAGES: tuple[tuple[str, Path], ...] = (
    ("tf2_msgs", REPO / "tools" / "tf2_msgs"),
    ("glocal_interfaces", REPO / "msg_schemas"),
)


def build(package: str, source: Path, build_dir: Path, force: bool) -> None:
    """Configure, build and install one interface package into this Python's prefix, unless up to date."""
    prefix = Path(sys.prefix)
    stamp = prefix / "share" / package / "sources.sha256"
    digest = sources_digest(source)
    if not force and stamp.exists() and stamp.read_text().strip() == digest:
        print(f"{package} is up to date in {prefix}")
        return
    cmake = ["cmake"]
    subprocess.run(
        cmake
        + [
            "-S", str(source), "-B", str(build_dir),
            f"-DCMAKE_PREFIX_PATH={prefix}",
            f"-DCMAKE_INSTALL_PREFIX={prefix}",
            f"-DPython3_EXECUTABLE={sys.executable}",
            "-DBUILD_TESTING=OFF",
            "-DCMAKE_BUILD_TYPE=Release",
        ],
        check=True,
    )
    subprocess.run(cmake + ["--build", str(build_dir), "--parallel", "2"], check=True)
    subprocess.run(cmake + ["--install", str(build_dir)], check=True)
    stamp.write_text(digest + "\n")
    print(f"{package} installed into {prefix}")


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--build", type=Path, default=Path(sys.prefix) / "build",
                        help="folder of the CMake build trees, one per package")
    parser.add_argument("--force", action="store_true", help="rebuild even if the sources did not change")
    args = parser.parse_args()

    print(f"rewrote wheel-builder paths in {rewrite_wheel_builder_paths(Path(sys.prefix))} CMake files")
    for package, source in PACKAGES:
        build(package, source, args.build / package, args.force)
    return 0


if __name__ == "__main__":
    sys.exit(main())

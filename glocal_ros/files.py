"""Writing files so that a process killed at any moment leaves the old or the new content, whole; reading
``.npz`` archives as data only."""

from __future__ import annotations

import os
import tempfile
import zipfile
from pathlib import Path
from typing import BinaryIO, Callable

import numpy as np


def atomic_write(path: Path, write: Callable[[BinaryIO], object]) -> None:
    """Write ``path`` through ``write(stream)`` on a temporary file, fsync, then an atomic rename.

    An ``OSError`` (a full disk) names ``path``: the errors of a write through a
    stream (zip, numpy) name no file, and "No space left on device" alone does
    not say which store filled up.
    """
    try:
        handle, temporary = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.")
    except OSError as error:
        raise _naming(error, path) from error
    os.fchmod(handle, 0o644)  # mkstemp's 0600 would hide shared or committed files from others
    try:
        with os.fdopen(handle, "wb") as stream:
            write(stream)
            stream.flush()
            os.fsync(stream.fileno())
        os.replace(temporary, path)
    except BaseException as error:
        Path(temporary).unlink(missing_ok=True)
        if isinstance(error, OSError) and str(path) not in str(error):
            raise _naming(error, path) from error
        raise


def _naming(error: OSError, path: Path) -> OSError:
    """``error`` again (its built-in class: FileNotFoundError stays one), its message naming ``path``."""
    kind = type(error) if type(error).__module__ == "builtins" else OSError
    return kind(error.errno, f"cannot write {path}: {error.strerror or error}")


def read_npz(path: Path) -> dict[str, np.ndarray]:
    """Every array of the ``.npz`` archive ``path``, read without unpickling anything.

    ``np.load(..., allow_pickle=False)`` refuses a pickle and an object array (the only way a ``.npy`` holds
    one); a member that is no ``.npy`` is refused here too (numpy would hand over its raw bytes). Any of
    those, a truncated or unreadable file, is a ``ValueError`` naming ``path``.
    """
    try:
        archive = np.load(path, allow_pickle=False)
        if not isinstance(archive, np.lib.npyio.NpzFile):
            raise ValueError("a single array, not an .npz archive")
        with archive:
            arrays = {name: archive[name] for name in archive.files}
    except (OSError, EOFError, ValueError, zipfile.BadZipFile) as error:
        raise ValueError(f"{path}: {error}") from error
    for name, value in arrays.items():
        if not isinstance(value, np.ndarray):
            raise ValueError(f"{path}: member {name!r} is not an array")
    return arrays

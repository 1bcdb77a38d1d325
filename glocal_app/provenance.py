"""Which code made a run: the git commit of this package's source, recorded at each launch of the run.

A run may be launched more than once (a resume), by other code each time.
``RUN_DIR/code.jsonl`` gets one line per launch: when, the commit of the git
checkout this package runs from (``"unknown"`` where it runs from no
checkout, e.g. a colcon or pip install), and whether that checkout had
changes not committed (``"dirty"``, tracked files only: untracked runs and
results do not count). Tables over runs (``bench curriculum``) name the code
of every run from it, so that runs made by different code are not
mistaken for runs of one.

Nothing is refused on a commit: a run resumed by other code goes on, and its
lines say so.
"""

from __future__ import annotations

import json
import subprocess
import time
from pathlib import Path
from typing import Sequence

CODE_FILE = "code.jsonl"
UNKNOWN_COMMIT = "unknown"
#: The source tree: the folder holding the ``glocal_app`` package.
SOURCE_DIR = Path(__file__).resolve().parent.parent


def code_version(source: Path = SOURCE_DIR) -> dict[str, object]:
    """The commit of the checkout at ``source`` and whether its tracked files differ from it."""
    def git(*args: str) -> str | None:
        try:
            result = subprocess.run(["git", "-C", str(source), *args], capture_output=True, text=True, timeout=30)
        except (OSError, subprocess.TimeoutExpired):
            return None
        return result.stdout.strip() if result.returncode == 0 else None

    commit = git("rev-parse", "HEAD")
    if commit is None:
        return {"commit": UNKNOWN_COMMIT, "dirty": False}
    return {"commit": commit, "dirty": bool(git("status", "--porcelain", "--untracked-files=no"))}


def record_code_version(run_dir: Path, source: Path = SOURCE_DIR) -> dict[str, object]:
    """Append this launch's code version to ``run_dir``'s ``CODE_FILE``; the line written."""
    line = {"launched": time.strftime("%Y-%m-%dT%H:%M:%S%z"), **code_version(source)}
    with (run_dir / CODE_FILE).open("a") as stream:
        stream.write(json.dumps(line) + "\n")
    return line


def run_code_versions(run_dir: Path) -> list[dict[str, object]]:
    """The code version of each launch of ``run_dir``, oldest first ([] for a run made before they were kept);
    a torn last line is left out."""
    path = run_dir / CODE_FILE
    if not path.is_file():
        return []
    versions = []
    for text in path.read_text().splitlines():
        try:
            versions.append(json.loads(text))
        except json.JSONDecodeError:
            continue
    return versions


def describe_code(versions: Sequence[dict[str, object]]) -> str:
    """The commits of a run's launches in short, in order, each once: ``1a2b3c4d``, ``1a2b3c4d (dirty)``,
    ``1a2b3c4d, then 5e6f7a8b``; "not recorded" for none."""
    if not versions:
        return "not recorded"
    names = [str(version["commit"])[:8] + (" (dirty)" if version.get("dirty") else "") for version in versions]
    return ", then ".join(dict.fromkeys(names))

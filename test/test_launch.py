"""`glocal-ros launch --preset smoke`: the graph starts, decides, records, and stops cleanly."""

import subprocess
import sys

from rosbags.highlevel import AnyReader

from conftest import REPO
from glocal_ros.recording import graph_typestore


def test_smoke_launch_records_the_run(tmp_path):
    run_dir = tmp_path / "run"
    result = subprocess.run(
        [sys.executable, "-m", "glocal_ros.cli", "launch", "--preset", "smoke", "--seed", "1", "--out", str(run_dir)],
        capture_output=True, text=True, timeout=300, cwd=REPO,
    )
    assert result.returncode == 0, result.stdout + result.stderr
    assert "training_global" in result.stdout and "global task" in result.stdout

    with AnyReader([run_dir / "bag"], default_typestore=graph_typestore()) as reader:
        states = [reader.deserialize(raw, c.msgtype) for c, _, raw in reader.messages()
                  if c.topic == "/glocal/curriculum_state"]
        episodes = [reader.deserialize(raw, c.msgtype) for c, _, raw in reader.messages()
                    if c.topic == "/glocal/episodes"]
    assert states[-1].global_task and states[-1].iteration == 1
    assert [e.seq for e in episodes] == list(range(len(episodes)))
    evaluated = [e for e in episodes if e.phase == 1 and not e.interrupted]
    assert {e.task for e in evaluated} == {"A0", "A1", "B0", "C3", "G6"}

    # A second launch into the same run directory keeps the first bag.
    again = subprocess.run(
        [sys.executable, "-m", "glocal_ros.cli", "launch", "--preset", "smoke", "--out", str(run_dir)],
        capture_output=True, text=True, timeout=300, cwd=REPO,
    )
    assert again.returncode == 0, again.stdout + again.stderr
    assert (run_dir / "bag.1" / "metadata.yaml").is_file() and (run_dir / "bag" / "metadata.yaml").is_file()

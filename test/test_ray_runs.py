"""`glocal-ros experiment --ray` and `bench curriculum --ray`: runs as Ray tasks, and the input they refuse.

The real test starts a Ray instance on this machine (``--ray local``: what a
cluster of one node does) and runs two smoke runs through it, one CPU each,
so that they run side by side, each on its own free domain of the node. The
same two runs done here, one after another, are the reference: a run is
repeatable answer for answer (its seed reaches every node), so everything an
experiment writes from its runs is the same, byte for byte: each run's
``run.json``, journal and final state, and the report (its text with OUT's
path put aside, and its figures).

Refusals are checked before anything starts, and OUT left as it was.
"""

from __future__ import annotations

import io
import subprocess
import sys
import tarfile
from pathlib import Path

import pytest

from conftest import REPO, free_port
from glocal_app.processes import RUN_FILE, STATE_FILE
from glocal_app.ray_runs import DEFAULT_GCS_PORT, pack_run, parse_address, unpack_run
from glocal_ros.recording import message_counts
from test_launch import graph_env

CLI = [sys.executable, "-m", "glocal_app.cli"]
#: Two tiny runs: the smoke preset at the smallest budget it allows (one baseline evaluation).
RUNS = ["--preset", "smoke", "--strategies", "glocal,random", "--seeds", "0", "--budget", "100"]


def glocal_ros(*args: str, timeout: float = 120) -> subprocess.CompletedProcess:
    return subprocess.run([*CLI, *args], capture_output=True, text=True, timeout=timeout, cwd=REPO, env=graph_env())


def snapshot(folder: Path) -> dict[str, bytes]:
    return {str(path.relative_to(folder)): path.read_bytes() for path in sorted(folder.rglob("*")) if path.is_file()}


def test_addresses_are_host_and_gcs_port():
    assert parse_address("10.0.0.5") == ("10.0.0.5", DEFAULT_GCS_PORT)
    assert parse_address("head.lab:6380") == ("head.lab", 6380)
    for bad, message in (("ray://head:10001", "Ray Client addresses are not supported"),
                         ("head:port", "expected HOST:PORT"), (":6379", "expected HOST:PORT"),
                         ("head:70000", "expected HOST:PORT")):
        with pytest.raises(ValueError, match=message):
            parse_address(bad)


def test_a_run_comes_back_whole_and_replaces_what_was_there(tmp_path):
    run = tmp_path / "node" / "glocal-seed0"
    (run / "curriculum").mkdir(parents=True)
    (run / RUN_FILE).write_text("{}\n")
    (run / "curriculum" / "journal.jsonl").write_text("two\nlines\n")
    out_run = tmp_path / "out" / "glocal-seed0"
    (out_run / "bag").mkdir(parents=True)
    (out_run / "bag" / "left-over").write_text("an earlier launch")

    unpack_run(pack_run(run), out_run)
    assert snapshot(out_run) == snapshot(run)
    assert [path.name for path in out_run.parent.iterdir()] == ["glocal-seed0"], "no staging folder left"

    other = io.BytesIO()
    with tarfile.open(fileobj=other, mode="w") as tar:
        tar.add(run, arcname="random-seed0")
    with pytest.raises(ValueError, match=r"an archive of \['random-seed0'\] is not the run glocal-seed0"):
        unpack_run(other.getvalue(), out_run)
    assert snapshot(out_run) == snapshot(run)


@pytest.mark.parametrize("command", [["experiment"], ["bench", "curriculum"]])
def test_an_unreachable_ray_address_is_refused_before_anything_starts(tmp_path, command):
    address = f"127.0.0.1:{free_port()}"
    out, results = tmp_path / "runs", tmp_path / "results" / "curriculum.md"
    extra = ["--results", str(results)] if command[0] == "bench" else []
    result = glocal_ros(*command, *RUNS, "--out", str(out), "--ray", address, *extra)
    assert result.returncode == 2, result.stdout + result.stderr
    assert f"no Ray cluster answers at {address}" in result.stderr and "Traceback" not in result.stderr
    assert not out.exists() and not results.parent.exists()


def test_an_out_of_other_settings_and_a_cluster_too_small_are_refused_and_out_kept(tmp_path):
    out = tmp_path / "runs"
    # An earlier launch of one of these runs, unfinished (no state): the experiment would resume it.
    (out / "glocal-seed0").mkdir(parents=True)
    (out / "glocal-seed0" / RUN_FILE).write_text(
        '{"strategy": "glocal", "preset": "smoke", "seed": 0, "step_budget": 100}\n')
    before = snapshot(out)

    # Another budget: experiment's own refusal, before Ray is even asked.
    other = glocal_ros("experiment", *RUNS[:-1], "300", "--out", str(out), "--ray", f"127.0.0.1:{free_port()}")
    assert other.returncode == 2 and "holds the run" in other.stderr, other.stderr

    # A Ray instance of this machine's CPUs, asked for runs of more CPUs than any node has.
    small = glocal_ros("experiment", *RUNS, "--out", str(out), "--ray", "local", "--ray-cpus-per-run", "512")
    assert small.returncode == 2, small.stdout + small.stderr
    assert "fewer than the 512 one run needs (--ray-cpus-per-run)" in small.stderr, small.stderr
    assert "sent to Ray" not in small.stdout
    assert snapshot(out) == before


@pytest.mark.slow
def test_runs_on_ray_come_back_and_report_as_the_same_runs_done_here(tmp_path):
    here, on_ray = tmp_path / "here", tmp_path / "on-ray"
    local = glocal_ros("experiment", *RUNS, "--out", str(here), timeout=600)
    assert local.returncode == 0, local.stdout + local.stderr
    command = ["experiment", *RUNS, "--out", str(on_ray), "--ray", "local", "--ray-cpus-per-run", "1"]
    ray = glocal_ros(*command, timeout=600)
    assert ray.returncode == 0, ray.stdout + ray.stderr
    assert ray.stdout.count("sent to Ray") == 2 and ray.stdout.count("exit code 0 on") == 2, ray.stdout

    for run in ("glocal-seed0", "random-seed0"):
        for file in (RUN_FILE, STATE_FILE, STATE_FILE.parent / "journal.jsonl"):
            assert (on_ray / run / file).read_bytes() == (here / run / file).read_bytes(), (run, file)
        assert (on_ray / run / "bag" / "metadata.yaml").is_file(), "the recorder was stopped cleanly"
        launch_log = next((on_ray / run / "logs").glob("launch-*.log")).read_text()
        assert "(a free one; set ROS_DOMAIN_ID to choose)" in launch_log
    reports = [(out / "report" / "report.md").read_text().replace(str(out), "OUT") for out in (here, on_ray)]
    assert reports[0] == reports[1]
    figures = sorted(path.name for path in (here / "report").glob("*.png"))
    assert figures and all((here / "report" / name).read_bytes() == (on_ray / "report" / name).read_bytes()
                           for name in figures)

    # The same command again: the finished run is not sent; the one made unfinished (its state gone, its
    # journal kept) is sent with its directory, resumes there from its journal without a goal, and comes back.
    (on_ray / "random-seed0" / STATE_FILE).unlink()
    again = glocal_ros(*command, timeout=600)
    assert again.returncode == 0, again.stdout + again.stderr
    assert "glocal-seed0: finished before" in again.stdout and again.stdout.count("sent to Ray") == 1, again.stdout
    assert "random-seed0: sent to Ray with its run directory (resumes)" in again.stdout
    resumed = on_ray / "random-seed0"
    assert (resumed / STATE_FILE).read_bytes() == (here / "random-seed0" / STATE_FILE).read_bytes()
    assert (resumed / "bag" / "metadata.yaml").is_file() and (resumed / "bag.1" / "metadata.yaml").is_file()
    assert message_counts(resumed / "bag.1").get("/glocal/task_assignment", 0) == 0, "replayed, no goal sent again"

"""Which code made a run (``glocal_app.provenance``): the commit of a checkout, whether it has changes, one line per
launch, and how a table names them."""

import json
import subprocess

from glocal_app.provenance import (CODE_FILE, UNKNOWN_COMMIT, code_version, describe_code, record_code_version,
                                   run_code_versions)


def git(folder, *args):
    subprocess.run(["git", "-C", str(folder), *args], check=True, capture_output=True,
                   env={"GIT_AUTHOR_NAME": "t", "GIT_AUTHOR_EMAIL": "t@t", "GIT_COMMITTER_NAME": "t",
                        "GIT_COMMITTER_EMAIL": "t@t", "PATH": "/usr/bin:/bin"})


def test_each_launch_records_the_checkouts_commit_and_whether_tracked_files_changed(tmp_path):
    source, run_dir = tmp_path / "source", tmp_path / "run"
    source.mkdir()
    run_dir.mkdir()
    git(source, "init", "-q")
    (source / "module.py").write_text("x = 1\n")
    git(source, "add", "module.py")
    git(source, "commit", "-qm", "first")
    first = subprocess.run(["git", "-C", str(source), "rev-parse", "HEAD"], capture_output=True, text=True).stdout.strip()
    (source / "results.md").write_text("untracked: not a change of the code\n")
    assert code_version(source) == {"commit": first, "dirty": False}

    record_code_version(run_dir, source)
    (source / "module.py").write_text("x = 2\n")
    record_code_version(run_dir, source)
    git(source, "commit", "-qam", "second")
    record_code_version(run_dir, source)
    with (run_dir / CODE_FILE).open("a") as stream:
        stream.write('{"commit": "torn')  # a launch killed while writing its line

    versions = run_code_versions(run_dir)
    assert [(v["commit"] == first, v["dirty"]) for v in versions] == [(True, False), (True, True), (False, False)]
    assert all(json.loads(line) for line in (run_dir / CODE_FILE).read_text().splitlines()[:3])
    second = versions[2]["commit"]
    assert describe_code(versions) == f"{first[:8]}, then {first[:8]} (dirty), then {second[:8]}"


def test_code_outside_a_checkout_is_unknown_and_a_run_without_records_says_so(tmp_path):
    assert code_version(tmp_path) == {"commit": UNKNOWN_COMMIT, "dirty": False}
    assert run_code_versions(tmp_path) == [] and describe_code([]) == "not recorded"
    assert describe_code([{"commit": "abc", "dirty": False}] * 2) == "abc"

"""`glocal-ros bench curriculum`: its table from recorded runs, its refusals, and a real run through the graph.

The table tests read real MCAP bags written with the recorder's writer (test_report's synthetic
runs: the curriculum states a run publishes); the last test runs two strategies of the smoke
preset through the whole graph, keeps them, and restores them on a bench that lacks them.
"""

from __future__ import annotations

import json
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
from rosbags.rosbag2 import Reader

from conftest import REPO
from glocal_app.benches.curriculum import KEPT_TOPICS, PAPER_LEARNED_AT_4M, keep_run
from glocal_app.processes import RUN_FILE, STATE_FILE, RunOptions
from glocal_app.provenance import CODE_FILE, code_version, describe_code, run_code_versions
from glocal_ros.analysis.estimates import improvement_interval, iqm_interval
from glocal_ros.analysis.report import improvement_cell, p_value_cell
from glocal_ros.analysis.runs import welch_p_value
from glocal_ros.bag_repair import bag_is_intact
from glocal_ros.recording import BagWriter
from glocal_ros.tasks import ALL_TASKS
from glocal_ros.topics import CURRICULUM_STATE
from test_launch import graph_env
from test_report import INTERVAL, PNG_MAGIC, TS, SyntheticRun, glocal_run, write_bag, write_run

CLI = [sys.executable, "-m", "glocal_app.cli"]


def bench(*args: str, timeout: float = 120) -> subprocess.CompletedProcess:
    return subprocess.run([*CLI, "bench", "curriculum", *args], capture_output=True, text=True, timeout=timeout,
                          cwd=REPO, env=graph_env())


def random_run(seed: int) -> SyntheticRun:
    """A baseline on the same tasks as ``glocal_run``: 2 objects, then a third late for seed 1."""
    learned = [("A0", 0), ("A3", 1200 + 1000 * seed)] + ([("B2", 3500)] if seed == 1 else [])
    return SyntheticRun("random", seed, list(ALL_TASKS), learned, [])


def record(out: Path, run: SyntheticRun, preset: str = "bench") -> Path:
    run_dir = write_run(out / f"{run.strategy}-seed{run.seed}", run)
    (run_dir / RUN_FILE).write_text(json.dumps(RunOptions(preset).settings(run.strategy, run.seed)))
    return run_dir


def message_counts(bag: Path) -> dict[str, int]:
    with Reader(bag) as reader:
        return {connection.topic: connection.msgcount for connection in reader.connections}


def milestone_row(table: str, heading: str, first_cell: str) -> list[str]:
    section = table.split(heading, 1)[1]
    line = next(line for line in section.splitlines() if line.startswith(f"| {first_cell} |"))
    return [cell.strip() for cell in line.strip("|").split("|")]


def test_the_table_has_milestones_ratios_t_tests_cost_and_the_paper(tmp_path):
    out, other = tmp_path / "runs", tmp_path / "other-day"
    runs = [glocal_run(0), glocal_run(1), random_run(0)]
    for run in runs:
        record(out, run)
    record(other, random_run(1))  # merged in: a run made elsewhere
    results = tmp_path / "results" / "curriculum.md"

    result = bench("--tabulate", "--out", str(out), "--merge", str(other), "--results", str(results))
    assert result.returncode == 0, result.stdout + result.stderr
    table = results.read_text()
    assert "bench curriculum --tabulate" in table  # the command that made it
    runs.append(random_run(1))

    def learned_at(strategy: str, step: int) -> list[int]:
        return [count for run in runs if run.strategy == strategy for at, count in run.milestones() if at == step]

    glocal, random = milestone_row(table, "## Learned objects at each milestone", "glocal"), \
        milestone_row(table, "## Learned objects at each milestone", "random")
    for column, step in enumerate(range(INTERVAL, 4 * INTERVAL + 1, INTERVAL), start=2):
        for cells, strategy in ((glocal, "glocal"), (random, "random")):
            values = learned_at(strategy, step)
            expected = f"{sum(values) / len(values):.1f} ({min(values):.1f}-{max(values):.1f})"
            assert cells[column] == expected, (strategy, step, cells)
    ratio = milestone_row(table, "## GloCAL / baseline", "glocal / random")
    at_4k = sum(learned_at("glocal", 4 * INTERVAL)) / sum(learned_at("random", 4 * INTERVAL))
    assert ratio[-1] == f"{at_4k:.2f}x"
    p_row = milestone_row(table, "Welch's t-test", "random")
    assert p_row[1:] == [p_value_cell(welch_p_value(learned_at("glocal", step), learned_at("random", step)))
                         for step in range(INTERVAL, 4 * INTERVAL + 1, INTERVAL)]
    steps = range(INTERVAL, 4 * INTERVAL + 1, INTERVAL)
    iqm_row = milestone_row(table, "### Interquartile mean", "random")
    assert iqm_row[1:] == ["2", *(iqm_interval(learned_at("random", step)).cell() for step in steps)]
    assert iqm_row[-1] == "2.5 [2.0, 3.0]"  # 2 seeds: the interval is their range
    improvement = milestone_row(table, "### Probability of improvement of glocal", "random")
    assert improvement[1:] == [improvement_cell(improvement_interval(learned_at("glocal", step),
                                                                     learned_at("random", step)))
                               for step in steps]
    assert "Few seeds: with 2 runs" in table
    cost = milestone_row(table, "## Cost per strategy", "glocal")
    assert cost[1] == "2/2"  # finished
    paper = milestone_row(table, "## Beside the paper", "random")
    assert paper[1] == f"{PAPER_LEARNED_AT_4M['random']}/49 (84%)"
    figures = results.parent / "curriculum"
    for name in ("learned_vs_steps.png", "milestones_violin.png", "milestones_iqm.png", "learned_grid.png"):
        assert (figures / name).read_bytes().startswith(PNG_MAGIC)
        assert f"(curriculum/{name})" in table


def test_runs_at_other_tasks_or_budgets_are_not_tabulated_together(tmp_path):
    out = tmp_path / "runs"
    record(out, glocal_run(0))
    record(out, SyntheticRun("random", 0, [t for t in ALL_TASKS if t[0] in "ABC"], [("A0", 0)], []))
    result = bench("--tabulate", "--out", str(out), "--results", str(tmp_path / "curriculum.md"))
    assert result.returncode == 2 and "not runs at equal settings" in result.stderr, result.stderr
    assert not (tmp_path / "curriculum.md").exists()


def test_a_resumed_run_whose_first_bag_was_cut_is_repaired_then_kept(tmp_path, capsys):
    run_dir = record(tmp_path / "runs", glocal_run(0))
    (run_dir / STATE_FILE).parent.mkdir()
    (run_dir / STATE_FILE).write_text("{}\n")
    # The first launch killed: its bag as the recorder leaves it (no summary, no metadata.yaml); resumed in bag.1.
    first, rest = glocal_run(0).messages(True)[:8], glocal_run(0).messages(True)[8:]
    shutil.rmtree(run_dir / "bag")
    whole = tmp_path / "whole"
    writer = BagWriter(whole, typestore=TS)
    for topic, stamp, data in first:
        writer.write(topic, stamp, data)
    writer.flush()
    shutil.copytree(whole, run_dir / "bag")
    writer.close()
    write_bag(run_dir / "bag.1", rest)
    assert not bag_is_intact(run_dir / "bag")

    kept = keep_run(run_dir, tmp_path / "kept")

    assert "bag: cut by a killed launch, repaired" in capsys.readouterr().out
    assert (run_dir / "bag.damaged").is_dir()  # the original, beside the repaired bag
    def kept_messages(bag: Path) -> dict[str, int]:  # a repaired bag has no channel that held no message
        return {t: n for t, n in message_counts(bag).items() if n and t in {spec.name for spec in KEPT_TOPICS}}

    assert kept_messages(kept / "bag") == kept_messages(whole)
    assert kept_messages(kept / "bag.1") == kept_messages(run_dir / "bag.1")
    assert kept_messages(kept / "bag")[CURRICULUM_STATE.name] > 0


@pytest.mark.parametrize("arguments, error", [
    (["--strategies", "glocal,greedy"], "unknown strategies ['greedy']"),
    (["--seeds", "0,one"], "expected comma-separated non-negative integers"),
    (["--budget", "50"], "below one evaluation of preset smoke (eval_interval 30, baseline_eval_interval 100)"),
    (["--merge", "nowhere"], "nowhere holds no run"),
    (["--preset", "tiny"], "unknown preset 'tiny'"),
])
def test_bad_input_is_refused_before_any_node_starts(tmp_path, arguments, error):
    out = tmp_path / "runs"
    result = bench("--preset", "smoke", "--out", str(out), "--results", str(tmp_path / "c.md"), *arguments)
    assert result.returncode == 2 and error in result.stderr, result.stderr
    assert not out.exists() and not (tmp_path / "c.md").exists()


def test_an_out_holding_runs_of_other_settings_is_refused_and_kept(tmp_path):
    out = tmp_path / "runs"
    # Not a run this bench would start, but one its table would read: of the demo preset.
    stranger = record(out, random_run(7), preset="demo")
    before = sorted(path.relative_to(out) for path in out.rglob("*"))
    result = bench("--preset", "smoke", "--strategies", "glocal", "--seeds", "0", "--out", str(out),
                   "--results", str(tmp_path / "c.md"))
    assert result.returncode == 2 and f"{stranger} is a run of preset demo" in result.stderr, result.stderr
    assert "learner profile glocal_ros (its preset's), not of preset smoke" in result.stderr, result.stderr
    assert sorted(path.relative_to(out) for path in out.rglob("*")) == before
    # Another profile than the kept runs' is refused naming both.
    result = bench("--preset", "demo", "--profile", "paper", "--strategies", "glocal", "--seeds", "0", "--out",
                   str(out), "--results", str(tmp_path / "c.md"))
    assert result.returncode == 2 and "learner profile glocal_ros (its preset's), not of preset demo" in \
        result.stderr and "and learner profile paper:" in result.stderr, result.stderr
    # The same for the runs a bench keeps: they would be restored into its --out.
    result = bench("--preset", "smoke", "--strategies", "glocal", "--seeds", "0", "--out", str(tmp_path / "new"),
                   "--keep", str(out), "--results", str(tmp_path / "c.md"))
    assert result.returncode == 2 and f"{stranger} is a run of preset demo" in result.stderr, result.stderr
    assert not (tmp_path / "new").exists()
    experiment = subprocess.run([*CLI, "experiment", "--preset", "smoke", "--strategies", "glocal,random",
                                 "--seeds", "0,7", "--out", str(out)], capture_output=True, text=True, timeout=120,
                                cwd=REPO, env=graph_env())
    # experiment refuses the run directory it would resume, before its first run (glocal-seed0) starts.
    assert experiment.returncode == 2 and "holds the run" in experiment.stderr, experiment.stderr
    assert sorted(path.relative_to(out) for path in out.rglob("*")) == before


def test_two_strategies_through_the_graph_kept_then_restored_and_not_run_again(tmp_path):
    out, results = tmp_path / "runs", tmp_path / "results" / "curriculum.md"
    arguments = ["--preset", "smoke", "--strategies", "glocal,random", "--seeds", "0", "--budget", "200",
                 "--out", str(out), "--results", str(results)]
    result = bench(*arguments, timeout=900)
    assert result.returncode == 0, result.stdout + result.stderr
    table = results.read_text()
    assert "200 training steps per run" in table  # --budget reached the curriculum
    for strategy in ("glocal", "random"):
        assert json.loads((out / f"{strategy}-seed0" / RUN_FILE).read_text())["step_budget"] == 200
        cost = milestone_row(table, "## Cost per strategy", strategy)
        assert cost[1] == "1/1" and float(cost[-1]) >= 0, cost
    assert milestone_row(table, "## GloCAL / baseline", "glocal / random")
    assert (results.parent / "curriculum" / "report.md").is_file()

    # Each finished run is kept beside the table, its bags reduced to the curriculum's and learner's topics.
    kept = results.parent / "curriculum-runs"
    for strategy in ("glocal", "random"):
        run, copy = out / f"{strategy}-seed0", kept / f"{strategy}-seed0"
        assert (copy / RUN_FILE).read_text() == (run / RUN_FILE).read_text()
        assert (copy / STATE_FILE).read_text() == (run / STATE_FILE).read_text()
        recorded, copied = message_counts(run / "bag"), message_counts(copy / "bag")
        assert copied == {topic: n for topic, n in recorded.items() if topic in {spec.name for spec in KEPT_TOPICS}}
        assert copied[CURRICULUM_STATE.name] > 0 and len(copied) < len(recorded)
        # The code that made it, kept with it and named in the table.
        assert (copy / CODE_FILE).read_text() == (run / CODE_FILE).read_text()
        (version,) = run_code_versions(run)
        assert version["commit"] == code_version()["commit"]
        assert milestone_row(table, "## The code of each run", f"{strategy}-seed0") == [
            f"{strategy}-seed0", describe_code([version])]

    # Another machine: the kept runs, not the runs themselves. Nothing runs again, and the table is the same.
    shutil.rmtree(out)
    first_table = table
    again = bench(*arguments, timeout=300)
    assert again.returncode == 0, again.stdout + again.stderr
    assert again.stdout.count("restored from") == again.stdout.count("finished before") == 2, again.stdout
    table = results.read_text()
    for heading, row in (("## Learned objects at each milestone", "glocal"),
                         ("## Learned objects at each milestone", "random"), ("## GloCAL / baseline", "glocal / random"),
                         ("## The code of each run", "glocal-seed0")):
        assert milestone_row(table, heading, row) == milestone_row(first_table, heading, row)

"""`glocal-ros bench learner` with tiny numbers: the table's shape, never its timings."""

from pathlib import Path

from glocal_app.cli import build_parser, cmd_bench_learner
from glocal_app.benches.learner import LearnerBenchRow, learner_bench_report, run_learner_bench


def test_bench_learner_reports_one_row_per_env_count():
    log: list[str] = []
    rows = run_learner_bench([1], steps=150, rounds=1, log=log.append)

    (row,) = rows
    assert (row.num_envs, row.workers) == (1, 1)
    assert row.in_process > 0 and row.through_ros > 0 and row.learner_node > 0
    assert row.ratio > 0 and row.learner_node_ratio > 0
    assert [len(run) for run in row.rounds] == [1, 1, 1]
    assert len(log) == 4  # three measurements and the summary

    report = learner_bench_report(rows, "glocal-ros bench learner --envs 1", steps=150, rounds=1)
    lines = report.splitlines()
    assert lines[0].startswith("# bench learner")
    assert "Command: `glocal-ros bench learner --envs 1`" in report
    table = [line for line in lines if line.startswith("|")]
    assert len(table) == 3  # header, alignment, one row
    assert all(line.count("|") == 7 for line in table)  # six columns
    cells = [cell.strip() for cell in table[2].strip("|").split("|")]
    assert cells[0] == "1" and cells[2].endswith("(1)")
    assert all(float(cell.split()[0]) > 0 for cell in cells[1:])
    assert any(line.startswith("- N=1: in-process ") for line in lines)


def test_bench_learner_without_learner_node_shows_a_dash():
    row = LearnerBenchRow(2, 80.0, 72.0, None, 2, ((80.0,), (72.0,)))
    report = learner_bench_report([row], "glocal-ros bench learner --no-learner-node", steps=10, rounds=1)
    (line,) = [line for line in report.splitlines() if line.startswith("| 2 ")]
    assert [cell.strip() for cell in line.strip("|").split("|")] == ["2", "80.0", "72.0 (2)", "-", "0.90", "-"]


def test_bench_learner_command_line():
    args = build_parser().parse_args(["bench", "learner", "--envs", "1,2", "--steps", "100", "--rounds", "2",
                                      "--no-learner-node", "--out", "x.md"])
    assert args.func is cmd_bench_learner
    assert (args.envs, args.steps, args.rounds, args.no_learner_node, args.out) == ("1,2", 100, 2, True, Path("x.md"))

"""`glocal-ros bench learner`, `bench backends` and `bench transfer` with tiny numbers: the tables' shape, never
timings or scores."""

from pathlib import Path

import pytest

from glocal_app.benches.backends import BACKENDS, BackendsBenchRow, backends_bench_report, run_backends_bench
from glocal_app.benches.learner import LearnerBenchRow, learner_bench_report, run_learner_bench
from glocal_app.benches.transfer import (TransferGoal, TransferSettings, read_transfer_goals, run_transfer_bench,
                                        run_transfer_graph, transfer_bench_report)
from glocal_app.cli import build_parser, cmd_bench_backends, cmd_bench_learner, cmd_bench_transfer
from glocal_ros.paths import assets_dir
from learner_node.policy_store import PolicyStore


def test_bench_learner_reports_one_row_per_env_count():
    log: list[str] = []
    # learner_node reports progress about once a second: enough steps for several reports at the 64x64
    # network's 200 env steps/s on an idle machine (150 steps gave 2 reports, too few to time).
    rows = run_learner_bench([1], steps=1000, rounds=1, log=log.append)

    (row,) = rows
    assert (row.num_envs, row.workers) == (1, 1)
    assert row.in_process > 0 and row.through_ros > 0 and row.learner_node > 0
    assert row.ratio > 0 and row.learner_node_ratio > 0 and row.env_floor > 0 and row.floor_ratio > 0
    assert [len(run) for run in row.rounds] == [1, 1, 1, 1]
    assert len(log) == 5  # four measurements and the summary

    report = learner_bench_report(rows, "glocal-ros bench learner --envs 1", steps=1000, rounds=1)
    lines = report.splitlines()
    assert lines[0].startswith("# bench learner")
    assert "Command: `glocal-ros bench learner --envs 1`" in report
    table = [line for line in lines if line.startswith("|")]
    assert len(table) == 3  # header, alignment, one row
    assert all(line.count("|") == 9 for line in table)  # eight columns
    cells = [cell.strip() for cell in table[2].strip("|").split("|")]
    assert cells[0] == "1" and cells[2].endswith("(1)")
    assert all(float(cell.split()[0]) > 0 for cell in cells[1:])
    assert any(line.startswith("- N=1: in-process ") for line in lines)


def test_bench_learner_without_learner_node_shows_a_dash():
    row = LearnerBenchRow(2, 80.0, 72.0, None, 2, ((80.0,), (72.0,), (144.0,)), env_floor=144.0)
    report = learner_bench_report([row], "glocal-ros bench learner --no-learner-node", steps=10, rounds=1)
    (line,) = [line for line in report.splitlines() if line.startswith("| 2 ")]
    assert [cell.strip() for cell in line.strip("|").split("|")] == \
        ["2", "80.0", "72.0 (2)", "-", "144.0", "0.90", "-", "0.50"]  # the graph is via sim_node here


def test_bench_learner_command_line():
    args = build_parser().parse_args(["bench", "learner", "--envs", "1,2", "--steps", "100", "--rounds", "2",
                                      "--no-learner-node", "--out", "x.md"])
    assert args.func is cmd_bench_learner
    assert (args.envs, args.steps, args.rounds, args.no_learner_node, args.out, args.profile) == \
        ("1,2", 100, 2, True, Path("x.md"), "glocal_ros")


def test_bench_backends_times_both_libraries_learning_on_the_grasp_env():
    (row,) = run_backends_bench([2], steps=20, rounds=1)
    assert row.num_envs == 2 and set(row.rounds) == set(BACKENDS)
    assert all(len(rates) == 1 and rates[0] > 0 for rates in row.rounds.values())

    report = backends_bench_report([row], "glocal-ros bench backends --envs 2", steps=20, rounds=1)
    assert report.splitlines()[0].startswith("# bench backends")
    assert "Command: `glocal-ros bench backends --envs 2`" in report
    table = [line for line in report.splitlines() if line.startswith("|")]
    assert len(table) == 3 and all(line.count("|") == 5 for line in table)
    assert any(line.startswith("- N=2: stable-baselines3 ") for line in report.splitlines())


def test_bench_backends_ratio_is_sbx_over_stable_baselines3_of_the_medians():
    row = BackendsBenchRow(4, {"stable-baselines3": (100.0, 150.0, 120.0), "sbx": (300.0, 200.0, 240.0)})
    assert row.ratio == pytest.approx(2.0)
    report = backends_bench_report([row], "glocal-ros bench backends", steps=10, rounds=3)
    (line,) = [line for line in report.splitlines() if line.startswith("| 4 ")]
    assert [cell.strip() for cell in line.strip("|").split("|")] == ["4", "120.0", "240.0", "2.00"]
    assert "(ratios in the same round: 3.00, 1.33, 2.00)" in report


def test_bench_backends_command_line_and_an_unknown_backend():
    from glocal_app.benches.backends import sac_class

    args = build_parser().parse_args(["bench", "backends", "--envs", "1,4", "--network", "256x256"])
    assert args.func is cmd_bench_backends and (args.envs, args.network) == ("1,4", "256x256")
    with pytest.raises(SystemExit):
        build_parser().parse_args(["bench", "backends", "--network", "32x32"])
    with pytest.raises(ValueError, match="stable-baselines3, sbx"):
        sac_class("tensorflow")


def test_bench_transfer_runs_every_arm_on_the_same_episodes_and_tabulates_them(tmp_path):
    """Real goals in spawned workers, tiny: 2 recipes x 2 priors (the shipped one, and a copy of it in a store
    of priors) x 1 task x 1 seed, budget 8, an evaluation every 4 steps."""
    prior_store = tmp_path / "priors"
    PolicyStore(prior_store).add_copy(PolicyStore(assets_dir() / "priors"), "prior", "prior-copy")
    settings = TransferSettings(step_budget=8, eval_interval=4, eval_episodes=2, num_envs=2)
    log: list[str] = []
    goals = run_transfer_bench(["random-first", "policy-first"], ["A0"], [5], settings, jobs=2, log=log.append,
                               priors=["prior", "prior-copy"], prior_store=prior_store)

    assert [(g.recipe, g.prior, g.task, g.seed) for g in goals] == [
        ("random-first", "prior", "A0", 5), ("policy-first", "prior", "A0", 5),
        ("random-first", "prior-copy", "A0", 5), ("policy-first", "prior-copy", "A0", 5)]
    for goal in goals:
        assert [steps for steps, _ in goal.curve] == [0, 4, 8]
        assert all(0 <= score <= 2 for _, score in goal.curve) and goal.wall_s > 0
    assert len({goal.start for goal in goals}) == 1, "every arm starts from the same weights on the same episodes"
    assert len(log) == 4

    report = transfer_bench_report(goals, "glocal-ros bench transfer --tasks A0", settings, jobs=2)
    assert report.startswith("# bench transfer")
    assert "Command: `glocal-ros bench transfer --tasks A0`" in report
    rows = [line for line in report.splitlines()
            if line.startswith(("| glocal_ros | random-first |", "| glocal_ros | policy-first |"))]
    assert len(rows) == 8  # one summary row and one goal row per arm
    assert all(line.count("|") == 14 for line in rows[:4])  # thirteen summary columns
    assert all(line.count("|") == 12 for line in rows[4:])  # profile, recipe, prior, task, seed, 3 scores, to B, drop, s

    # The same goals through a sim_node and a learner_node: the same episodes, so the same start.
    (through_graph,) = run_transfer_graph(["policy-first"], ["A0"], [5], settings, log=log.append,
                                          priors=["prior-copy"], prior_store=prior_store)
    assert (through_graph.arm, through_graph.task, through_graph.seed) == \
        (("glocal_ros", "policy-first", "prior-copy"), "A0", 5)
    assert [steps for steps, _ in through_graph.curve] == [0, 4, 8]
    assert through_graph.start == goals[1].start
    assert "through the graph" in transfer_bench_report([through_graph], "x", settings, jobs=1, graph=True)


def test_a_transfer_report_is_read_back_and_tabulated_with_another(tmp_path, capsys):
    """``--tabulate``: the goals of earlier reports, read from their per-goal tables, in one report."""
    settings = TransferSettings(step_budget=1000, eval_interval=500)

    def goal(recipe, seed, *scores):
        return TransferGoal(recipe, "B1", seed, tuple(zip((0, 500, 1000), scores)), 20, settings.threshold, 12.0)

    first = tmp_path / "first.md"
    first.write_text(transfer_bench_report([goal("a", 0, 3, 9, 16), goal("a", 1, 17, 18, 2)], "x", settings, 2))
    second = tmp_path / "second.md"
    second.write_text(transfer_bench_report([goal("b", 0, 3, 1, 4)], "y", settings, 2))
    assert read_transfer_goals(first, settings) == [goal("a", 0, 3, 9, 16), goal("a", 1, 17, 18, 2)]

    out = tmp_path / "both.md"
    args = build_parser().parse_args(["bench", "transfer", "--budget", "1000", "--tabulate", str(first), str(second),
                                      "--out", str(out)])
    assert cmd_bench_transfer(args) == 0
    report = out.read_text()
    assert f"the goals of `{first}`, `{second}`" in report
    summary = {line.split("|")[2].strip(): [cell.strip() for cell in line.strip("|").split("|")]
               for line in report.splitlines()
               if line.startswith(("| glocal_ros | a | prior | 2 ", "| glocal_ros | b | prior | 1 "))}
    # goals, passed B, median steps to B, started below B, of those passed, their median steps to B, collapses
    assert summary["a"][3:10] == ["2", "2", "500", "1", "1", "1000", "1"]
    assert summary["b"][3:10] == ["1", "0", "never", "1", "0", "never", "0"]

    # Another budget, or a file without the table: refused, naming the file, nothing written.
    out.unlink()
    for bad in (["--budget", "1500", "--tabulate", str(first)], ["--budget", "1000", "--tabulate", str(out)],
                ["--budget", "1000", "--tabulate", str(first), str(first)]):
        assert cmd_bench_transfer(build_parser().parse_args(["bench", "transfer", *bad, "--out", str(out)])) == 1
        assert not out.exists()
    errors = capsys.readouterr().err
    assert f"{first}: its goals were scored at steps 0, 500, 1000" in errors
    assert "(profile, recipe, prior, task, seed) = glocal_ros, a, prior, B1, 0 is in the reports more than once" \
        in errors


def test_a_transfer_curve_gives_steps_to_b_and_collapse():
    def goal(*curve):
        return TransferGoal("r", "A1", 0, tuple(curve), eval_episodes=20, threshold=15, wall_s=1.0)

    recovered = goal((0, 12), (500, 9), (1000, 16), (1500, 7), (2000, 18))
    assert recovered.steps_to_b == 1000  # the first score above B
    assert recovered.drop_points == 25.0 and recovered.collapsed  # 12 -> 7 after 1k steps: 25 points of 100
    early_dip = goal((0, 12), (500, 2), (1000, 12))
    assert early_dip.drop_points == 0 and not early_dip.collapsed  # the first 1k steps do not count
    assert early_dip.steps_to_b is None
    assert goal((0, 16), (1000, 17)).steps_to_b == 0  # a prior above B already


@pytest.mark.parametrize("change, message", [
    (dict(recipes=["rlpd"]), "unknown fine-tuning recipe"),
    (dict(profiles=["sb2"]), "unknown learner profile 'sb2'"),
    (dict(profiles=["paper"]), "recipe 'random-first' contradicts learner profile 'paper'"),
    (dict(profiles=["glocal_ros", "glocal_ros"], recipes=["default"]), "must not repeat"),
    (dict(priors=["no-such-prior"]), "no prior 'no-such-prior'"),
    (dict(priors=["../prior"]), "invalid policy name"),
    (dict(priors=[]), "a prior"),
    (dict(priors=["prior", "prior"]), "must not repeat"),
    (dict(prior_store=Path("/no/such/store")), "is not a directory"),
    (dict(tasks=["Z9"]), "Z9"),
    (dict(settings=TransferSettings(step_budget=1000, eval_interval=300)), "multiple of the envs"),
    (dict(settings=TransferSettings(eval_episodes=0)), "at least 1"),
    (dict(seeds=[]), "a seed"),
    (dict(seeds=[1, 1]), "must not repeat"),
    (dict(seeds=[-1]), "seeds must lie in"),
])
def test_bench_transfer_refuses_bad_input_before_any_goal_runs(change, message):
    arguments = dict(recipes=["random-first"], tasks=["A0"], seeds=[0], settings=TransferSettings(), jobs=1)
    arguments.update(change)
    ran: list[str] = []
    with pytest.raises(ValueError, match=message):
        run_transfer_bench(**arguments, log=ran.append)
    assert ran == []


def test_bench_transfer_command_line():
    args = build_parser().parse_args(["bench", "transfer", "--recipes", "policy-first", "--tasks", "A0,B1",
                                      "--seeds", "0,1", "--budget", "1000", "--eval-interval", "250", "--jobs", "1"])
    assert args.func is cmd_bench_transfer
    assert (args.recipes, args.tasks, args.seeds, args.budget, args.eval_interval, args.eval_episodes, args.envs,
            args.out) == ("policy-first", "A0,B1", "0,1", 1000, 250, 20, 4, Path("bench/results/transfer.md"))
    assert (args.priors, args.prior_store, args.profiles) == ("prior", None, "glocal_ros")
    assert build_parser().parse_args(["bench", "transfer"]).recipes == "default"
    args = build_parser().parse_args(["bench", "transfer", "--priors", "prior,prior-64x64", "--prior-store", "p"])
    assert (args.priors, args.prior_store) == ("prior,prior-64x64", Path("p"))

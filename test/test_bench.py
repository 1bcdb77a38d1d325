"""`glocal-ros bench learner`, `bench backends` and `bench transfer` with tiny numbers: the tables' shape, never
timings or scores."""

import re
from dataclasses import replace
from pathlib import Path

import pytest

from glocal_app.benches.backends import BACKENDS, BackendsBenchRow, backends_bench_report, run_backends_bench
from glocal_app.benches.learner import LearnerBenchRow, learner_bench_report, run_learner_bench
from glocal_app.benches.transfer import (INSTRUMENTS, TransferGoal, TransferSettings, read_transfer_goals,
                                        run_transfer_bench, run_transfer_graph, transfer_bench_report)
from glocal_app.bench_cli import cmd_bench_backends, cmd_bench_learner, cmd_bench_transfer
from glocal_app.cli import build_parser
from glocal_ros.paths import assets_dir
from learner_node.policy_store import PolicyStore


def test_bench_learner_reports_one_row_per_env_count():
    log: list[str] = []
    # learner_node reports progress about once a second: enough steps for several reports at the 64x64
    # network's 200 env steps/s on an idle machine (150 steps gave 2 reports, too few to time).
    rows = run_learner_bench([1], steps=1000, rounds=1, log=log.append)

    (row,) = rows
    assert (row.profile, row.num_envs, row.workers) == ("glocal_ros", 1, 1)
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
    assert all(line.count("|") == 10 for line in table)  # nine columns
    cells = [cell.strip() for cell in table[2].strip("|").split("|")]
    assert cells[:2] == ["glocal_ros", "1"] and cells[3].endswith("(1)")
    assert all(float(cell.split()[0]) > 0 for cell in cells[2:])
    assert any(line.startswith("- glocal_ros, N=1: in-process ") for line in lines)


def test_bench_learner_without_learner_node_shows_a_dash():
    row = LearnerBenchRow("paper", 2, 80.0, 72.0, None, 2, ((80.0,), (72.0,), (144.0,)), env_floor=144.0)
    report = learner_bench_report([row], "glocal-ros bench learner --no-learner-node", steps=10, rounds=1)
    (line,) = [line for line in report.splitlines() if line.startswith("| paper ")]
    assert [cell.strip() for cell in line.strip("|").split("|")] == \
        ["paper", "2", "80.0", "72.0 (2)", "-", "144.0", "0.90", "-", "0.50"]  # the graph is via sim_node here


def test_a_curves_write_is_timed(tmp_path):
    from glocal_app.benches.learner import seconds_per_curves_write

    assert 0 < seconds_per_curves_write(tmp_path / "curves", writes=20) < 1
    assert (tmp_path / "curves" / "progress.csv").read_text().count("\n") == 21  # the header and each write


def test_bench_learner_reports_what_the_curves_cost():
    row = LearnerBenchRow("glocal_ros", 4, 300.0, 280.0, None, 2, ((300.0, 310.0), (280.0, 281.0), (800.0, 790.0),
                                                                   (291.0, 304.0)), env_floor=795.0, with_curves=297.5,
                          curves_write=0.0002)
    assert row.variant_names == ("in-process", "via sim_node", "env floor", "in-process with curves")
    report = learner_bench_report([row], "glocal-ros bench learner --curves", steps=10, rounds=2)
    (line,) = [line for line in report.splitlines() if line.startswith("| glocal_ros | 4 | 300.0 | 297.5")]
    assert [cell.strip() for cell in line.strip("|").split("|")] == \
        ["glocal_ros", "4", "300.0", "297.5", "0.992", "0.970, 0.981", "0.11", "0.200", "0.0200%"]  # 4/297.5 - 4/300 s
    assert "in-process with curves 291.0, 304.0" in report


def test_bench_learner_command_line():
    args = build_parser().parse_args(["bench", "learner", "--envs", "1,2", "--steps", "100", "--rounds", "2",
                                      "--no-learner-node", "--out", "x.md"])
    assert args.func is cmd_bench_learner
    assert (args.envs, args.steps, args.rounds, args.no_learner_node, args.out, args.profiles, args.curves) == \
        ("1,2", 100, 2, True, Path("x.md"), ["glocal_ros", "paper"], False)
    with pytest.raises(SystemExit):
        build_parser().parse_args(["bench", "learner", "--profiles", "glocal_ros,sb2"])


def test_bench_physics_splits_a_control_step_and_measures_the_variants_side_by_side():
    from glocal_app.benches.physics import SOLVER_ITERATIONS, physics_bench_report, run_physics_bench

    (result,) = run_physics_bench(["A0"], steps=120, rounds=1, log=lambda line: None)
    assert all(seconds >= 0 for seconds in result.parts.values()) and result.parts["physics in steps"] > 0
    # Stepping the physics is most of a control step, even with cProfile's cost on the Python parts.
    assert result.parts["physics in steps"] > 0.3 * sum(result.parts.values())
    assert set(result.rates) == {"as it is", "BulletClient (bound at every call)",
                                 *(f"{n} solver iterations" for n in SOLVER_ITERATIONS[1:])}
    assert all(rate > 0 for rate in result.rates.values()) and all(us > 0 for us in result.substep_us.values())
    report = physics_bench_report([result], "glocal-ros bench physics", 1)
    assert "| physics in steps | " in report and "| 10 solver iterations | " in report
    assert "yes: not taken" in report


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
        # Each of the goal's own evaluations with its instruments (step 0 is scored outside the goal).
        assert [(steps, sorted(values)) for steps, values in goal.instruments] == \
            [(4, sorted(INSTRUMENTS)), (8, sorted(INSTRUMENTS))]
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
    assert sum(line.startswith("| action distance | glocal_ros |") for line in report.splitlines()) == 4

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

    measured = replace(goal("a", 0, 3, 9, 16), instruments=(
        (500, {"action distance": 0.25, "Q gap": -1.5, "entropy": 2.0}),
        (1000, {"action distance": 0.5, "Q gap": 0.125, "entropy": -3.0})))
    first = tmp_path / "first.md"
    first.write_text(transfer_bench_report([measured, goal("a", 1, 17, 18, 2)], "x", settings, 2))
    second = tmp_path / "second.md"
    second.write_text(transfer_bench_report([goal("b", 0, 3, 1, 4)], "y", settings, 2))
    assert read_transfer_goals(first, settings) == [measured, goal("a", 1, 17, 18, 2)], "instruments read back too"

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
    (dict(settings=TransferSettings(objects_dir=Path("/no/such/objects"))), "holds no model.urdf for A0"),
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
    assert (args.priors, args.prior_store, args.profiles) == ("prior", None, ["glocal_ros"])
    assert build_parser().parse_args(["bench", "transfer"]).recipes == "default"
    args = build_parser().parse_args(["bench", "transfer", "--priors", "prior,prior-64x64", "--prior-store", "p"])
    assert (args.priors, args.prior_store, args.objects_dir) == ("prior,prior-64x64", Path("p"), None)
    assert build_parser().parse_args(["bench", "transfer", "--objects-dir", "o"]).objects_dir == Path("o")


# ---- bench cost ----------------------------------------------------------------------------------------------

def cost_goal(task, seed, steps_to_b, cap=15_000, interval=1_000, episodes=100):
    """A hand-made cost-map goal: scores below B (75 of 100) until ``steps_to_b``, there above it and stopped;
    ``None``: below B at every evaluation up to the cap."""
    last = cap if steps_to_b is None else steps_to_b
    curve = tuple((steps, 80 if steps == steps_to_b else 10) for steps in range(0, last + 1, interval))
    return TransferGoal("default", task, seed, curve, episodes, 0.75 * episodes, 30.0)


#: Six objects, two seeds each: A1 passes at step 0, D3/G5/G6 are not learned within the cap on some seed.
COST_GOALS = [cost_goal("A1", 0, 0), cost_goal("A1", 1, 0), cost_goal("A2", 0, 0), cost_goal("A2", 1, 1000),
              cost_goal("B4", 0, 1000), cost_goal("B4", 1, 2000), cost_goal("D3", 0, 5000), cost_goal("D3", 1, None),
              cost_goal("G5", 0, None), cost_goal("G5", 1, None), cost_goal("G6", 0, 14000), cost_goal("G6", 1, None)]


def test_the_cost_map_statistics_count_a_goal_not_learned_as_above_the_cap():
    import math

    from scipy.stats import spearmanr

    from glocal_app.benches.cost import (cost_settings, letter_spearman, object_medians, passed_at_start,
                                         row_medians, targets)

    assert cost_goal("G5", 0, None).steps_to_b is None and cost_goal("A2", 1, 1000).curve[-1] == (1000, 80)
    # Per object: the median of its two seeds, their mean; not learned when either is.
    assert object_medians(COST_GOALS) == {"A1": 0, "A2": 500, "B4": 1500, "D3": math.inf, "G5": math.inf,
                                          "G6": math.inf}
    # Per row: the median over all the row's goals, one vote each (G: 14000 and three not learned).
    assert row_medians(COST_GOALS) == {"A": 0, "B": 1500, "D": math.inf, "G": math.inf}
    assert row_medians([cost_goal("G6", 0, 14000), cost_goal("G6", 1, 16000), cost_goal("G5", 0, None)]) == \
        {"G": 16000}
    # Spearman over the objects' medians, not learned ranked above every learned one and tied among themselves.
    rho, count = letter_spearman(COST_GOALS)
    assert count == 6
    assert rho == pytest.approx(spearmanr([0, 0, 1, 3, 6, 6], [0, 500, 1500, 10**9, 10**9, 10**9])[0])
    assert letter_spearman([cost_goal("A1", 0, 0), cost_goal("D1", 0, 3000), cost_goal("G1", 0, None)]) == (1.0, 3)
    assert math.isnan(letter_spearman(COST_GOALS[:4])[0])  # two objects: no correlation
    assert passed_at_start(COST_GOALS) == ["A1"]  # A2 passed at step 0 on one seed of two only

    spearman, easy, hard, start = targets(COST_GOALS, cost_settings())
    assert spearman.met is (rho >= 0.8) and spearman.measured == f"{rho:+.2f} over 6 objects"
    assert easy.met is False and easy.measured == "A 0, B 1,500"
    assert hard.met is True and hard.measured == "G not learned within the cap of 15,000"
    assert start.met is True and start.measured == "1 of 6 tested (the target's share of 6: 1.8): A1"
    # Rows not tested: nothing to judge on.
    (spearman, easy, hard, _) = targets([cost_goal("C1", 0, 3000)], cost_settings())
    assert easy.met is None and easy.measured == "A untested, B untested" and hard.met is None
    assert spearman.met is False and spearman.measured.startswith("not measurable")
    # A cap below the target's 15,000: G not learned meets the target's words, and the report says why it tells
    # nothing.
    short = targets([cost_goal("G1", 0, None, cap=8000)], cost_settings(step_budget=8000))[2]
    assert short.met is True and "a cap of 8,000 < 15,000" in short.measured


def test_the_cost_report_and_heat_map_show_not_learned_as_such(tmp_path):
    from glocal_app.benches.cost import cost_figure, cost_report, cost_settings

    settings = cost_settings()
    tasks = ["A1", "A2", "B4", "D3", "E0", "G5", "G6"]  # E0: selected, not finished
    figure = cost_figure(COST_GOALS, settings, tmp_path / "cost.png")
    assert figure.stat().st_size > 20_000
    report = cost_report(COST_GOALS, "glocal-ros bench cost --tasks x", settings, tasks, [0, 1], 2, figure, tmp_path)
    assert report.startswith("# bench cost")
    assert "Command: `glocal-ros bench cost --tasks x`" in report and "Figure: `cost.png`" in report
    assert "Goals finished: 12 of 14 (a partial map" in report
    assert "| row A and B medians <= 1,000 steps | A 0, B 1,500 | missed |" in report
    assert "| row G median >= 15,000 steps or not learned within the cap | G not learned within the cap of " \
           "15,000 | met |" in report
    assert "| G | 2 | 4 | 1 | 0 | not learned | 30 |" in report  # objects, goals, learned, at step 0, median, s
    assert "| D | - | - | - | not learned | - | - | - |" in report  # the map's row D: D3 only
    assert "| A | - | 0 | 500 | - | - | - | - |" in report
    assert "| G6 | 14000 | - | not learned |" in report  # per object: each seed, then the median
    assert "| G6 | 1 | " + " ".join(f"{s}:10" for s in range(0, 15001, 1000)) + " | - | 30 |" in report
    assert "Cost of the map: 83,000 training steps" in report


def test_the_per_row_selection_covers_every_column_and_bad_selections_are_refused():
    from collections import Counter

    from glocal_app.benches.cost import per_row_tasks, select_tasks
    from glocal_ros.tasks import ALL_TASKS

    three = select_tasks("per-row:3")
    assert three == per_row_tasks(3) and len(three) == 21 and "A0" not in three
    assert set(Counter(task[0] for task in three).values()) == {3}
    assert set(Counter(task[1] for task in three).values()) == {3}  # every column, three times
    assert select_tasks("per-row:7") == list(ALL_TASKS) == select_tasks("all")
    assert len(set(task[1] for task in select_tasks("per-row:1"))) == 7
    assert select_tasks("b1, a0") == ["A0", "B1"]
    for bad, message in (("per-row:0", "1..7"), ("per-row:8", "1..7"), ("per-row:x", "per-row:K"),
                         ("Z9", "Z9"), ("A0,A0", "must not repeat"), ("", "no task")):
        with pytest.raises(ValueError, match=message):
            select_tasks(bad)


def test_the_goal_log_drops_a_torn_line_and_refuses_other_settings(tmp_path):
    from glocal_app.benches.cost import GOALS_FILE, GoalLog, cost_settings, finished_goals, goal_record, run_key
    from glocal_ros.paths import object_fingerprint

    settings = cost_settings(step_budget=2000)
    key = run_key(settings)
    log = GoalLog(tmp_path)
    for goal in (cost_goal("A1", 0, 0, cap=2000), cost_goal("G6", 0, None, cap=2000)):
        log.append(goal_record(goal, key, object_fingerprint(goal.task)))
    path = tmp_path / GOALS_FILE
    whole = path.read_text()
    path.write_text(whole + '{"task": "B2", "se')  # killed mid-write
    goals = finished_goals(tmp_path, settings)
    assert sorted(goals) == [("A1", 0), ("G6", 0)]
    assert goals[("G6", 0)].steps_to_b is None and goals[("G6", 0)].curve[-1] == (2000, 10)
    log.drop_torn_line()
    assert path.read_text() == whole

    with pytest.raises(ValueError, match=r"other settings \(step_budget 2000 \(now 3000\)\).*another --work-dir"):
        finished_goals(tmp_path, cost_settings(step_budget=3000))
    log.append(goal_record(cost_goal("A1", 0, 0, cap=2000), key, object_fingerprint("A1")))
    with pytest.raises(ValueError, match="goal A1 seed 0 is in it twice"):
        finished_goals(tmp_path, settings)
    path.write_text(whole.replace(object_fingerprint("G6"), "0" * 16))
    with pytest.raises(ValueError, match="the object of G6 has changed"):
        finished_goals(tmp_path, settings)
    path.write_text("not json\n")
    with pytest.raises(ValueError, match="line 1: not a goal of bench cost"):
        finished_goals(tmp_path, settings)


def test_a_cost_map_from_another_prior_store_is_another_map(tmp_path):
    """A set of another A0 needs a prior trained on it (``train-prior --objects-dir``): the key names the
    prior the goals start from, so goals from the shipped prior are refused in a map from another."""
    from glocal_app.benches.cost import GoalLog, cost_settings, finished_goals, goal_record, run_key
    from glocal_ros.paths import object_fingerprint

    store = tmp_path / "priors"
    PolicyStore(store).add_copy(PolicyStore(assets_dir() / "priors"), "prior", "prior")
    updated = PolicyStore(store).update("prior", last_score=1.0).updated  # now: not the shipped prior's time
    settings = cost_settings(step_budget=2000)
    shipped, other = run_key(settings), run_key(settings, prior_store=store)
    assert other["prior"] == f"prior (model-1.npz, {updated})" != shipped["prior"]
    (tmp_path / "work").mkdir()
    GoalLog(tmp_path / "work").append(goal_record(cost_goal("A1", 0, 0, cap=2000), shipped, object_fingerprint("A1")))
    assert list(finished_goals(tmp_path / "work", settings)) == [("A1", 0)]
    with pytest.raises(ValueError, match=re.escape(f"other settings (prior {shipped['prior']} (now {other['prior']})")):
        finished_goals(tmp_path / "work", settings, prior_store=store)


def test_a_cost_map_of_another_recipe_is_another_map(tmp_path):
    """A map per fine-tuning recipe (issue 45's remedies on every object): the profile's own recipe keeps the
    key maps had before recipes could be chosen, another recipe is named in it, and each refuses the other's
    goals; a recipe the learner does not know is refused before anything runs."""
    from glocal_app.benches.cost import (GoalLog, check_cost, cost_settings, finished_goals, goal_record,
                                         held_cost_map, run_key)
    from glocal_ros.paths import object_fingerprint

    settings, wsrl = cost_settings(step_budget=2000), "task-inputs-wsrl-2000"
    own, other = run_key(settings), run_key(settings, recipe=wsrl)
    assert "recipe" not in own and other == {**own, "recipe": wsrl}
    for work, key in ((tmp_path / "own", own), (tmp_path / "wsrl", other)):
        work.mkdir()
        GoalLog(work).append(goal_record(cost_goal("A1", 0, 0, cap=2000), key, object_fingerprint("A1")))
    assert finished_goals(tmp_path / "wsrl", settings, recipe=wsrl)[("A1", 0)].recipe == wsrl
    assert [goal.recipe for goal in held_cost_map(tmp_path / "wsrl")[1]] == [wsrl]
    with pytest.raises(ValueError, match=re.escape(f"other settings (recipe default (now {wsrl}))")):
        finished_goals(tmp_path / "own", settings, recipe=wsrl)
    with pytest.raises(ValueError, match=re.escape(f"other settings (recipe {wsrl} (now default))")):
        finished_goals(tmp_path / "wsrl", settings)
    with pytest.raises(ValueError, match="unknown fine-tuning recipe 'no-such-recipe'"):
        check_cost(["A1"], [0], settings, 1, recipe="no-such-recipe")


def test_a_recipes_map_is_judged_against_another_read_back_from_its_report(tmp_path):
    """Issue 45's targets on the goals two maps share: the other map is read back from its report, and one of
    other settings, or a file that is no report, is refused."""
    from dataclasses import replace

    from glocal_app.benches.cost import (check_against, cost_report, cost_settings, read_cost_report,
                                         against_targets)

    settings, wsrl = cost_settings(), "task-inputs-wsrl-2000"
    report = cost_report(COST_GOALS, "glocal-ros bench cost", settings, ["A1", "A2", "B4", "D3", "G5", "G6"],
                         [0, 1], 2, None, tmp_path)
    (tmp_path / "own.md").write_text(report)
    own = read_cost_report(tmp_path / "own.md")
    assert (own.profile, own.recipe, own.settings) == ("glocal_ros", "default", settings)
    assert own.goals == COST_GOALS  # every curve, and the wall-clock to the second
    check_against(own, settings, "glocal_ros")
    with pytest.raises(ValueError, match=r"other settings \(cap 15000 \(here 60000\)\)"):
        check_against(own, cost_settings(step_budget=60_000), "glocal_ros")
    with pytest.raises(ValueError, match="not a report of bench cost"):
        read_cost_report(_written(tmp_path / "other.md", "# bench transfer\n"))

    # A recipe that passes every goal the default trained at 1,000 steps, at twice the wall-clock, and never
    # dips: a goal below B at the start (10 of 100), one evaluation above it.
    def faster(goal):
        if goal.steps_to_b == 0:
            return replace(goal, recipe=wsrl)
        return replace(goal, recipe=wsrl, curve=((0, goal.start), (1000, 80)), wall_s=2 * goal.wall_s)

    recipe_goals = [faster(goal) for goal in COST_GOALS]
    unchanged, halved, median, quick, dips, wall = against_targets(recipe_goals, own.goals, settings)
    assert unchanged.met is None and halved.met is None  # rows C, E and F untested
    # Started below B: A2 seed 1, B4, D3, G5 and G6 (9 goals); the default's 1,000 1,000 2,000 5,000 14,000 and
    # four not learned.
    assert (median.met, median.measured) == (True, "1,000 over 9 (against 14,000)")
    assert (quick.met, quick.measured) == (False, "9 of 9 goals that started below B (against 4)")
    assert dips.met is True and dips.measured.startswith("0 of 9 goals that started below B, median drop 0")
    # 9,000 steps in 540 s against 83,000 in 270 s.
    assert wall.met is False and wall.measured == f"60.0 s per 1,000 steps against 3.3: {60 / (270 / 83):.2f} times"
    lines = cost_report(recipe_goals, "glocal-ros bench cost --recipe x", settings, ["A1"], [0, 1], 2, None,
                        tmp_path, recipe=wsrl, against=own)
    assert "## Against `own.md` (recipe default)" in lines and "fine-tuning recipe task-inputs-wsrl-2000" in lines
    assert "| G5 | 0 | 10 | 1000 | - | 0 | 0 | 60 | 30 |" in lines
    assert read_cost_report(_written(tmp_path / "wsrl.md", lines)).recipe == wsrl


def _written(path, text):
    path.write_text(text)
    return path


def test_bench_cost_runs_real_goals_stopped_at_b_resumes_and_tabulates(tmp_path, capsys, monkeypatch):
    """Real goals (PyBullet, SAC) through the command, tiny: the paper profile's prior (trained on A0, raw task
    inputs elsewhere), a cap of 16 steps scored every 8 over 2 episodes. One task, then the same work dir with a
    second task: only that one runs."""
    import json

    from glocal_app.cli import main

    work, out = tmp_path / "work", tmp_path / "cost.md"
    flags = ["--profile", "paper", "--seeds", "3", "--step-budget", "16", "--eval-interval", "8",
             "--eval-episodes", "2", "--envs", "2", "--jobs", "1", "--work-dir", str(work), "--out", str(out)]

    def cost(*args):
        monkeypatch.setattr("sys.argv", ["glocal-ros", "bench", "cost", *args])
        return main(["bench", "cost", *args])

    assert cost("--tasks", "A0", *flags) == 0
    first = (work / "goals.jsonl").read_text()
    assert len(first.splitlines()) == 1
    assert "0 of 1 goals finished before" in capsys.readouterr().out

    assert cost("--tasks", "G6,A0", *flags) == 0
    printed = capsys.readouterr().out
    assert "1 of 2 goals finished before" in printed and "1 to run" in printed
    lines = (work / "goals.jsonl").read_text().splitlines()
    assert len(lines) == 2 and lines[0] == first.strip()  # A0 kept, not run again
    for record in map(json.loads, lines):
        steps = [s for s, _ in record["curve"]]
        passed = [score > 1.5 for _, score in record["curve"]]
        # Stopped at its first score above B, else scored at every interval up to the cap.
        assert not any(passed[:-1])
        assert passed[-1] or steps == [0, 8, 16]
        assert steps == list(range(0, steps[-1] + 1, 8))
        assert record["key"]["profile"] == "paper" and record["key"]["threshold"] == 1.5
    report = out.read_text()
    assert "Command: `glocal-ros bench cost --tasks G6,A0" in report and "Goals finished: 2 of 2." in report
    assert "| A0 | 3 | " in report and "| G6 | 3 | " in report
    assert out.with_suffix(".png").stat().st_size > 20_000

    # Everything finished: the same command runs nothing; --tabulate neither, and says so.
    assert cost("--tasks", "G6,A0", *flags) == 0
    assert "2 of 2 goals finished before (in" in capsys.readouterr().out
    out.unlink()
    assert cost("--tasks", "all", *flags, "--tabulate") == 0
    assert "tabulated from" in out.read_text() and "Goals finished: 2 of 49 (a partial map" in out.read_text()
    assert (work / "goals.jsonl").read_text().splitlines() == lines

    # Against a map's own report (the goals trained too little to tell anything: a row each, and G6 passed at
    # step 0 on its 2 episodes or trained); a report of other settings is refused before anything runs.
    kept = out.with_name("kept.md")
    out.rename(kept)
    assert cost("--tasks", "G6,A0", *flags, "--tabulate", "--against", str(kept)) == 0
    report = out.read_text()
    against = report.split("## Against `kept.md` (recipe default)")[1]
    assert "| rows A, B, C, D: medians still 0 | A 0 (against 0), B untested (against untested)" in against
    assert against.count("| G6 | 3 |") == (0 if "| G6 | 3 | 0:2 |" in report else 1)
    capsys.readouterr()
    with pytest.raises(SystemExit) as exit:
        cost("--tasks", "G6,A0", *flags[:-1], str(out.with_name("refused.md")), "--step-budget", "24",
             "--against", str(kept))
    assert exit.value.code == 2 and "other settings (cap 16 (here 24))" in capsys.readouterr().err
    assert not out.with_name("refused.md").exists() and (work / "goals.jsonl").read_text().splitlines() == lines

    # The same work dir with another cap: refused before anything runs.
    with pytest.raises(SystemExit) as exit:
        cost("--tasks", "G6,A0", *flags[:4], "--step-budget", "24", *flags[6:])
    assert exit.value.code == 2
    assert "holds goals of other settings (step_budget 16 (now 24))" in capsys.readouterr().err
    assert (work / "goals.jsonl").read_text().splitlines() == lines
    assert cost("--tasks", "B1", *flags, "--tabulate") == 1
    assert "no finished goal of these tasks and seeds" in capsys.readouterr().err


def test_a_stepping_stone_is_the_object_of_the_row_above_and_ratios_say_what_they_can():
    from glocal_app.benches.stones import ratio_text, stone_of

    assert (stone_of("G3"), stone_of("B0")) == ("F3", "A0")
    with pytest.raises(ValueError, match="A4 is in row A"):
        stone_of("A4")
    inf = float("inf")
    assert ratio_text(500, 2000) == "0.25" and ratio_text(3000, 1000) == "3.00"
    assert (ratio_text(inf, inf), ratio_text(1000, inf), ratio_text(inf, 1000)) == \
        ("neither learned", "learned only from the stone", "learned only from the prior")
    assert (ratio_text(0, 0), ratio_text(1000, 0)) == ("both 0", "the prior passes at once")


def test_bench_stones_chains_real_goals_in_a_cost_maps_work_dir_and_resumes(tmp_path, capsys, monkeypatch):
    """Real goals, tiny (the cost command test's settings): the stone A0 from the paper prior, then B0 from what
    that goal stored; the goals from the prior on both join the map's goals.jsonl, the chain stones.jsonl."""
    import json

    from glocal_app.cli import main

    work, out = tmp_path / "work", tmp_path / "stones.md"
    flags = ["--targets", "B0", "--profile", "paper", "--seeds", "3", "--step-budget", "16", "--eval-interval", "8",
             "--eval-episodes", "2", "--envs", "2", "--jobs", "1", "--work-dir", str(work), "--out", str(out)]
    monkeypatch.setattr("sys.argv", ["glocal-ros", "bench", "stones", *flags])
    assert main(["bench", "stones", *flags]) == 0
    assert sorted(json.loads(line)["task"] for line in (work / "goals.jsonl").read_text().splitlines()) == \
        ["A0", "B0"]
    (chain,) = [json.loads(line) for line in (work / "stones.jsonl").read_text().splitlines()]
    assert (chain["task"], chain["stone"], chain["seed"]) == ("B0", "A0", 3)
    stone_learned = chain["stone_curve"][-1][1] > 1.5
    assert (chain["curve"] is not None) == stone_learned
    if stone_learned:
        assert chain["curve"][0][0] == 0 and chain["curve"][-1][0] <= 16
    report = out.read_text()
    assert "Command: `glocal-ros bench stones --targets B0" in report and "| B0 | 3 | " in report
    capsys.readouterr()

    assert main(["bench", "stones", *flags]) == 0  # everything finished: nothing runs
    printed = capsys.readouterr().out
    assert "2 of 2 goals finished before" in printed and "1 chains finished before" in printed
    with pytest.raises(SystemExit) as exit:
        main(["bench", "stones", *flags[:-2], "--targets", "A3", "--out", str(out)])
    assert exit.value.code == 2 and "A3 is in row A" in capsys.readouterr().err


@pytest.mark.parametrize("args, message", [
    (["--tasks", "Z9"], "unknown task 'Z9'"),
    (["--tasks", "per-row:9"], "objects per row must lie in 1..7"),
    (["--step-budget", "500", "--eval-interval", "1000"], "below one evaluation interval"),
    (["--eval-interval", "1002"], "multiple of the envs"),
    (["--eval-episodes", "0"], "at least 1"),
    (["--seeds", "1,1"], "must not repeat"),
    (["--jobs", "0"], "at least one job"),
    (["--tabulate", "--step-budget", "1500"], "divide the budget"),
    (["--prior-store", "/no/such/store"], "is not a directory"),
    (["--objects-dir", "/no/such/objects"], "holds no model.urdf"),
])
def test_bench_cost_refuses_bad_input_before_anything_runs(tmp_path, capsys, args, message):
    from glocal_app.cli import main

    with pytest.raises(SystemExit) as exit:
        main(["bench", "cost", "--work-dir", str(tmp_path / "work"), "--out", str(tmp_path / "cost.md"), *args])
    assert exit.value.code == 2 and message in capsys.readouterr().err
    assert not (tmp_path / "work").exists() and not (tmp_path / "cost.md").exists()


def test_bench_cost_command_line_defaults():
    from glocal_app.bench_cli import cmd_bench_cost

    args = build_parser().parse_args(["bench", "cost"])
    assert args.func is cmd_bench_cost
    assert (args.tasks, args.seeds, args.step_budget, args.eval_interval, args.eval_episodes, args.envs) == \
        ("per-row:3", [0, 1], 15_000, 1_000, 100, 4)
    assert (args.work_dir, args.out, args.tabulate, args.learner_profile) == \
        (Path("runs/bench-cost"), Path("bench/results/cost.md"), False, "glocal_ros")


def test_goals_stopped_at_b_run_in_process_only():
    with pytest.raises(ValueError, match="stop_at_threshold is in-process only"):
        run_transfer_graph(["default"], ["A0"], [0], TransferSettings(stop_at_threshold=True))

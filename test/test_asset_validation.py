"""`glocal-ros assets validate`: the letter against measured grasp success, the prior's score, steps to B."""

import json
import math
import subprocess
import sys

import pytest

from conftest import REPO
from glocal_app.benches.assets import letter_correlation, prior_scores, validation_report
from glocal_ros.objects import METADATA_FILE, record_lifting_poses
from glocal_ros.paths import objects_dir
from glocal_ros.tasks import ALL_TASKS

TRANSFER_REPORT = REPO / "bench" / "results" / "transfer-task-inputs.md"


def test_letter_correlation_is_spearman_over_the_letter_index() -> None:
    falling = {task: 1.0 - "ABCDEFG".index(task[0]) / 10 + int(task[1]) / 1000 for task in ALL_TASKS}
    rho, count = letter_correlation(falling)
    assert count == 49 and -1.0 <= rho < -0.95
    too_few, all_equal = letter_correlation({"A0": 1.0, "G0": 0.0}), letter_correlation({"A0": 5, "D0": 5, "G0": 5})
    assert math.isnan(too_few[0]) and too_few[1] == 2 and math.isnan(all_equal[0]) and all_equal[1] == 3


def test_the_report_has_a_correlation_per_measure_and_counts_never_as_slowest() -> None:
    measures = {"perturbed": {"A0": 0.9, "D0": 0.5, "G0": 0.1}, "steps_to_b": {"A0": 0.0, "D0": 500.0,
                                                                            "G0": math.inf},
                "scripted": {"A0": 1.0, "D0": 1.0, "G0": 1.0}}
    report = validation_report(measures, "glocal-ros assets validate", "preamble")
    assert "| perturbed grasp | 3 | -1.00 | easier |" in report and "| scripted grasp | 3 | - (all equal) |" in report
    assert "| steps to B | 3 | 1.00 | harder |" in report
    assert "| G0 | 10% | 100% | never |" in report and "A0 prior" not in report


def test_the_report_has_the_share_of_lifting_poses_by_row_median_and_flags_an_unlearnable_object() -> None:
    measures = {"lifting_poses": {"A0": 0.6, "A1": 0.2, "A2": 0.1, "D0": 0.4, "G0": 0.1},
                "best_pose": {"A0": 1.0, "A1": 0.9, "A2": 0.8, "D0": 0.9, "G0": 0.5}}
    report = validation_report(measures, "glocal-ros assets validate", "preamble")
    rho, _ = letter_correlation(measures["lifting_poses"])
    assert f"| lifting poses | 5 | {rho:.2f} | easier |" in report and "| best pose | 5 |" in report
    assert "| A | 20% | 90% |" in report, "the row's median share of poses (the mean of its best poses)"
    assert "**no**, 1 of 5 fail: G0 (50%)." in report
    assert "| G0 | 10% | 50% (fails) |" in report and "| A2 | 10% | 80% |" in report


def test_the_prior_is_scored_on_each_object_it_is_given() -> None:
    scores = prior_scores(objects_dir(), ["A0", "G6"], episodes=2, seed=0)
    assert set(scores) == {"A0", "G6"} and all(score in (0.0, 0.5, 1.0) for score in scores.values())


def run_validate(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "glocal_app.cli", "assets", "validate", *args],
                          capture_output=True, text=True, timeout=300, cwd=REPO)


def test_validate_writes_the_table_and_the_figure_from_a_transfer_report(tmp_path) -> None:
    report = tmp_path / "validate.md"
    result = run_validate("--episodes", "0", "--transfer", str(TRANSFER_REPORT), "--report", str(report))
    assert result.returncode == 0, result.stderr
    text = report.read_text()
    assert "| perturbed grasp | 49 |" in text and "| scripted grasp | 49 |" in text
    assert "| steps to B | 8 |" in text and "Command: `glocal-ros assets validate --episodes 0" in text
    assert report.with_suffix(".png").stat().st_size > 10_000


def test_validate_reports_the_lifting_poses_objects_json_holds(tmp_path) -> None:
    committed = json.loads((objects_dir() / METADATA_FILE).read_text())
    for metrics in committed["objects"].values():  # as before any object was measured
        metrics["lifting_pose_share"] = metrics["best_pose_success"] = None
    (tmp_path / METADATA_FILE).write_text(json.dumps(committed))
    record_lifting_poses(tmp_path, {"A0": (0.24, 1.0), "D3": (0.45, 1.0), "G0": (0.17, 0.7), "G6": (0.2, 1.0)},
                         {"seed": 0})
    report = tmp_path / "validate.md"
    result = run_validate("--episodes", "0", "--out", str(tmp_path), "--report", str(report))
    assert result.returncode == 0, result.stderr
    text = report.read_text()
    assert "| lifting poses | 4 |" in text and "| best pose | 4 |" in text and "| perturbed grasp | 49 |" in text
    g0 = next(line for line in text.splitlines() if line.startswith("| G0 |"))
    assert "fail: G0 (70%)." in text and g0.endswith("| 17% | 70% (fails) |")


def write_cost_map(work_dir, steps_to_b: dict) -> None:
    """A bench cost work directory as the bench writes it, of hand-made curves: task -> steps to B (None: not
    learned within a cap of 3,000), seed 0, keyed on the shipped prior and the committed objects."""
    from glocal_app.benches.cost import GoalLog, cost_settings, goal_record, run_key
    from glocal_ros.paths import object_fingerprint
    from glocal_app.benches.transfer import TransferGoal

    settings = cost_settings(step_budget=3_000)
    work_dir.mkdir()
    log = GoalLog(work_dir)
    for task, steps in steps_to_b.items():
        last = settings.step_budget if steps is None else steps
        curve = tuple((step, 80 if step == steps else 10) for step in range(0, last + 1, settings.eval_interval))
        goal = TransferGoal("default", task, 0, curve, 100, 75.0, 1.0)
        log.append(goal_record(goal, run_key(settings), object_fingerprint(task)))


def test_validate_takes_steps_to_b_from_a_cost_map(tmp_path) -> None:
    write_cost_map(tmp_path / "cost", {"A1": 0, "C2": 1_000, "E4": 2_000, "G5": None})
    report = tmp_path / "validate.md"
    result = run_validate("--episodes", "0", "--cost", str(tmp_path / "cost"), "--report", str(report))
    assert result.returncode == 0, result.stderr
    text = report.read_text()
    assert "| steps to B | 4 | 1.00 | harder |" in text, text
    assert "the cost map in" in text and "capped at 3000 steps" in text
    g5 = next(line for line in text.splitlines() if line.startswith("| G5 |"))
    assert "never" in g5, g5


def test_validate_refuses_an_empty_cost_map_and_two_sources_of_steps_to_b(tmp_path) -> None:
    (tmp_path / "empty").mkdir()
    result = run_validate("--episodes", "0", "--cost", str(tmp_path / "empty"), "--report",
                          str(tmp_path / "validate.md"))
    assert result.returncode == 1 and "holds no goal of bench cost" in result.stderr, result.stderr
    both = run_validate("--episodes", "0", "--cost", str(tmp_path / "empty"), "--transfer", str(TRANSFER_REPORT))
    assert both.returncode == 2 and "not allowed with argument" in both.stderr
    assert not (tmp_path / "validate.md").exists()


def test_validate_refuses_a_file_that_is_no_transfer_report(tmp_path) -> None:
    result = run_validate("--episodes", "0", "--transfer", str(REPO / "README.md"), "--report",
                          str(tmp_path / "validate.md"))
    assert result.returncode == 1 and "README.md" in result.stderr and "Traceback" not in result.stderr
    assert not (tmp_path / "validate.md").exists()


@pytest.mark.parametrize("args, message", [
    (["validate", "--episodes", "-3"], "--episodes: -3 is below 0"),
    (["check", "--perturbed-episodes", "0"], "--perturbed-episodes: 0 is below 1"),
    (["check", "--check-episodes", "0"], "--check-episodes must be at least 1"),
    (["generate", "--per-column", "6"], "--per-column: 6 is below 7"),
])
def test_asset_commands_refuse_counts_out_of_range_before_they_start(args, message) -> None:
    result = subprocess.run([sys.executable, "-m", "glocal_app.cli", "assets", *args], capture_output=True,
                            text=True, timeout=120, cwd=REPO)
    assert result.returncode == 2 and message in result.stderr and "Traceback" not in result.stderr

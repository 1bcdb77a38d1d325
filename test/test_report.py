"""``glocal-ros report``: synthetic runs recorded as real bags -> runs, statistics, figures, report.md.

The bags are written with the recorder's own BagWriter and the graph's
typestore, so the report reads exactly what a recorded run would contain.
"""

from __future__ import annotations

import shutil
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest

from conftest import REPO
from glocal_ros.analysis import figures
from glocal_ros.analysis.estimates import milestone_estimates
from glocal_ros.analysis.report import write_report
from glocal_ros.analysis.runs import (
    CurriculumSnapshot,
    RunData,
    group_by_strategy,
    learned_curve_band,
    milestone_table,
    read_run,
    read_runs,
    welch_p_value,
)
from glocal_ros.curriculum.codes import (
    STATUS_EVALUATING,
    STATUS_FINISHED,
    STATUS_STARTING,
    STATUS_TRAINING,
    STATUS_TRAINING_GLOBAL,
    STATUS_TRAINING_LOCAL,
)
from glocal_ros.recording import BagWriter, graph_typestore
from glocal_ros.tasks import ALL_TASKS

TS = graph_typestore()
STATE_TYPE = "glocal_interfaces/msg/CurriculumState"
EPISODE_TYPE = "glocal_interfaces/msg/EpisodeRecord"
INTERVAL = 1000
TOTAL_STEPS = 4500  # milestones at 1000..4000
T0_NS = 1_700_000_000 * 10**9
PNG_MAGIC = b"\x89PNG\r\n\x1a\n"


# --- building messages -----------------------------------------------------------------------

def header(stamp_ns: int):
    Time = TS.types["builtin_interfaces/msg/Time"]
    Header = TS.types["std_msgs/msg/Header"]
    return Header(stamp=Time(sec=stamp_ns // 10**9, nanosec=stamp_ns % 10**9), frame_id="")


def state_cdr(stamp_ns: int, *, strategy: str, seed: int, status: int, iteration: int, total_steps: int,
              tasks: list[str], learned: list[tuple[str, int]], global_task: str = "",
              local_tasks: tuple[str, ...] = (), milestones: bool = True) -> bytes:
    """A CurriculumState as the curriculum node publishes it, CDR-serialized."""
    State = TS.types[STATE_TYPE]
    Cluster = TS.types["glocal_interfaces/msg/TaskCluster"]
    learned_now = [(task, at) for task, at in learned if at <= total_steps]
    names = [task for task, _ in learned_now]
    reached = [k * INTERVAL for k in range(1, total_steps // INTERVAL + 1)] if milestones else []
    cluster = Cluster(tasks=[global_task, *local_tasks] if global_task else [],
                      scores=np.full(len(local_tasks) + bool(global_task), 50.0, dtype=np.float32), mean_score=50.0)
    msg = State(
        header=header(stamp_ns), run_id=f"{strategy}-seed{seed}", seed=seed, strategy=strategy, status=status,
        iteration=iteration, total_steps=total_steps, step_budget=TOTAL_STEPS,
        evaluation_episodes=total_steps // 10, silhouette=0.5,
        clusters=[cluster] if global_task else [], chosen_cluster=0, global_task=global_task,
        local_tasks=list(local_tasks), current_task=global_task, current_policy="prior",
        learned_tasks=names, learned_policies=[f"pi_{task}" for task in names],
        learned_at_steps=np.array([at for _, at in learned_now], dtype=np.uint64),
        remaining_tasks=[task for task in tasks if task not in names], milestone_interval=INTERVAL,
        milestone_steps=np.array(reached, dtype=np.uint64),
        milestone_learned=np.array([sum(at <= step for _, at in learned_now) for step in reached], dtype=np.uint32),
    )
    return TS.serialize_cdr(msg, STATE_TYPE)


def episode_cdr(stamp_ns: int, seq: int, phase: int, interrupted: bool) -> bytes:
    Episode = TS.types[EPISODE_TYPE]
    length, obs_dim, action_dim = 3, 4, 2
    msg = Episode(
        header=header(stamp_ns), seq=seq, task="A0", env_index=0, phase=phase, policy_name="prior",
        global_step=seq * 10, seed=-1, length=length, obs_dim=obs_dim, action_dim=action_dim,
        observations=np.zeros((length + 1) * obs_dim, np.float32), actions=np.zeros(length * action_dim, np.float32),
        rewards=-np.ones(length, np.float32), joint_names=["j1"], joint_positions=np.zeros(length + 1, np.float32),
        success=False, truncated=not interrupted, interrupted=interrupted,
    )
    return TS.serialize_cdr(msg, EPISODE_TYPE)


@dataclass
class SyntheticRun:
    """What a synthetic run was made of, to compare the report against."""

    strategy: str
    seed: int
    tasks: list[str]
    learned: list[tuple[str, int]]  # (task, total_steps when learned), in learning order
    iterations: list[tuple[str, tuple[str, ...], int]]  # (global, locals, start steps) of glocal-like runs
    episodes: tuple[int, int, int] = (3, 2, 1)  # train, eval, interrupted (of the train ones)

    def milestones(self) -> list[tuple[int, int]]:
        return [(k * INTERVAL, sum(at <= k * INTERVAL for _, at in self.learned))
                for k in range(1, TOTAL_STEPS // INTERVAL + 1)]

    def messages(self, milestones: bool) -> list[tuple[str, int, bytes]]:
        """(topic, stamp, cdr) in time order: the states of Algorithm 1 (or a baseline) and a few episodes."""
        base = dict(strategy=self.strategy, seed=self.seed, tasks=self.tasks, learned=self.learned,
                    milestones=milestones)
        states = [dict(status=STATUS_STARTING, iteration=0, total_steps=0)]
        if self.iterations:
            for m, (global_task, local_tasks, start) in enumerate(self.iterations, start=1):
                end = self.iterations[m][2] if m < len(self.iterations) else TOTAL_STEPS
                states += [
                    dict(status=STATUS_EVALUATING, iteration=m, total_steps=start),
                    dict(status=STATUS_TRAINING_GLOBAL, iteration=m, total_steps=start, global_task=global_task,
                         local_tasks=local_tasks),
                    dict(status=STATUS_TRAINING_LOCAL, iteration=m, total_steps=(start + end) // 2,
                         global_task=global_task, local_tasks=local_tasks),
                ]
        else:
            states += [dict(status=STATUS_TRAINING, iteration=0, total_steps=s) for s in range(0, TOTAL_STEPS, 1500)]
        states.append(dict(status=STATUS_FINISHED, iteration=len(self.iterations), total_steps=TOTAL_STEPS))
        out = [("/glocal/curriculum_state", T0_NS + i * 10**9, state_cdr(T0_NS + i * 10**9, **base, **s))
               for i, s in enumerate(states)]
        train, evals, interrupted = self.episodes
        for seq in range(train + evals):
            stamp = T0_NS + seq * 10**8 + 1
            out.append(("/glocal/episodes", stamp, episode_cdr(stamp, seq, int(seq >= train), seq < interrupted)))
        return sorted(out, key=lambda m: m[1])


def write_bag(path: Path, messages: list[tuple[str, int, bytes]]) -> None:
    writer = BagWriter(path, typestore=TS)
    for topic, stamp, data in messages:
        writer.write(topic, stamp, data)
    writer.close()


def write_run(run_dir: Path, run: SyntheticRun, milestones: bool = True, split_at: int | None = None) -> Path:
    """Record ``run`` into ``run_dir/bag``; with ``split_at``, resumed: the rest in ``bag.1``."""
    messages = run.messages(milestones)
    if split_at is None:
        write_bag(run_dir / "bag", messages)
    else:
        first, rest = messages[:split_at], messages[split_at:]
        # The resumed recorder gets the latched last state again (transient-local).
        latched = [m for m in first if m[0] == "/glocal/curriculum_state"][-1]
        write_bag(run_dir / "bag", first)
        write_bag(run_dir / "bag.1", [latched, *rest])
    return run_dir


A_TO_C = [t for t in ALL_TASKS if t[0] in "ABC"]


def glocal_run(seed: int) -> SyntheticRun:
    # B1 is tried in iteration 1, not learned, and learned in iteration 2.
    learned = [("A0", 0), ("A1", 600), ("A2", 900), ("B0", 1600), ("B1", 2100), ("C0", 2600 + 100 * seed)]
    if seed >= 1:
        learned.append(("C1", 3900))
    iterations = [("A1", ("A2", "B1"), 0), ("B0", ("B1", "C0", "C1"), 1500), ("C2", ("C1",), 3000)]
    return SyntheticRun("glocal", seed, list(ALL_TASKS), learned, iterations)


def random_run(seed: int) -> SyntheticRun:
    learned = [("A0", 0), ("A3", 1200 + 1000 * seed)] + ([("B2", 3500)] if seed == 1 else [])
    return SyntheticRun("random", seed, A_TO_C, learned, [])


@pytest.fixture(scope="module")
def recorded(tmp_path_factory) -> tuple[list[Path], dict[tuple[str, int], SyntheticRun], Path]:
    """2 strategies x 2 seeds, a glocal seed split over bag/ + bag.1/ (+ a broken bag.2/), a broken run."""
    root = tmp_path_factory.mktemp("runs")
    expected: dict[tuple[str, int], SyntheticRun] = {}
    run_dirs = []
    for seed in (0, 1):
        for run in (glocal_run(seed), random_run(seed)):
            # Random runs publish no milestones: the report derives them from learned_at_steps.
            run_dirs.append(write_run(root / f"{run.strategy}-{seed}", run, milestones=run.strategy == "glocal"))
            expected[(run.strategy, seed)] = run
    resumed = glocal_run(2)
    resumed_dir = write_run(root / "glocal-2", resumed, split_at=8)
    # A recorder killed during the second resume: its bag has no metadata.yaml.
    write_bag(resumed_dir / "bag.2", resumed.messages(True)[:2])
    (resumed_dir / "bag.2" / "metadata.yaml").unlink()
    run_dirs.append(resumed_dir)
    expected[("glocal", 2)] = resumed
    broken = root / "broken"
    write_bag(broken / "bag", glocal_run(9).messages(True))
    (broken / "bag" / "metadata.yaml").unlink()
    return run_dirs, expected, broken


def test_runs_are_read_with_strategy_seed_and_learned(recorded, capsys) -> None:
    run_dirs, expected, _ = recorded
    runs = read_runs(run_dirs)
    assert [(r.strategy, r.seed) for r in runs] == [("glocal", 0), ("glocal", 1), ("glocal", 2),
                                                    ("random", 0), ("random", 1)]
    for run in runs:
        synthetic = expected[(run.strategy, run.seed)]
        assert run.run_id == f"{run.strategy}-seed{run.seed}"
        assert run.learned_tasks == tuple(task for task, _ in synthetic.learned)
        assert run.tasks == tuple(synthetic.tasks)
        assert run.total_steps == TOTAL_STEPS and run.finished
        assert run.milestones() == synthetic.milestones()
        assert (run.episodes.train, run.episodes.eval, run.episodes.complete) == (3, 2, 4)
    assert "bag.2" in capsys.readouterr().err


def test_resumed_run_merges_bags_and_skips_the_broken_one(recorded, capsys) -> None:
    run_dirs, expected, broken = recorded
    run = read_run(run_dirs[-1])
    assert [b.name for b in run.bags_read] == ["bag", "bag.1"]
    assert [b.name for b, _ in run.bags_skipped] == ["bag.2"]
    assert "metadata.yaml" in run.bags_skipped[0][1]
    stamps = [s.order_key for s in run.states]
    assert stamps == sorted(stamps) and len(set(stamps)) == len(stamps)  # the latched re-send counted once
    assert run.final.status == STATUS_FINISHED and run.iterations == 3
    assert run.learned_tasks == tuple(task for task, _ in expected[("glocal", 2)].learned)
    assert read_run(broken) is None
    err = capsys.readouterr().err
    assert "warning: skipping bag" in err and str(broken / "bag") in err


def test_learned_curve_and_iteration_timeline(recorded) -> None:
    run_dirs, _, _ = recorded
    run = read_run(run_dirs[0])  # glocal seed 0
    steps, counts = run.learned_curve()
    assert steps.tolist() == [0, 0, 600, 900, 1600, 2100, 2600, TOTAL_STEPS]
    assert counts.tolist() == [1, 1, 2, 3, 4, 5, 6, 6]
    timeline = run.iteration_timeline()
    assert [(r.iteration, r.global_task, r.local_tasks, r.start_steps) for r in timeline] == [
        (1, "A1", ("A2", "B1"), 0), (2, "B0", ("B1", "C0", "C1"), 1500), (3, "C2", ("C1",), 3000)]
    # B1 failed in iteration 1 and was learned in iteration 2; C1 and C2 never were.
    assert [set(r.learned) for r in timeline] == [{"A1", "A2"}, {"B0", "B1", "C0"}, set()]


def test_milestone_statistics_and_welch_test(recorded) -> None:
    run_dirs, expected, _ = recorded
    groups = group_by_strategy(read_runs(run_dirs))
    table = milestone_table(groups)
    assert table.steps == [1000, 2000, 3000, 4000] and table.reference == "glocal"
    for strategy, seeds in (("glocal", (0, 1, 2)), ("random", (0, 1))):
        for i, step in enumerate(table.steps):
            assert table.values[strategy][step] == [expected[(strategy, s)].milestones()[i][1] for s in seeds]
    glocal_4m, random_4m = table.values["glocal"][4000], table.values["random"][4000]
    assert table.p_values["random"][4000] == pytest.approx(welch_p_value(glocal_4m, random_4m))
    from scipy.stats import ttest_ind

    assert table.p_values["random"][4000] == pytest.approx(ttest_ind(glocal_4m, random_4m, equal_var=False).pvalue)
    assert welch_p_value([1.0], [2.0, 3.0]) is None
    assert welch_p_value([5, 5], [5, 5]) is None  # undefined: both constant and equal
    steps, mean, _, low, high = learned_curve_band(groups["random"])
    assert mean[-1] == pytest.approx(2.5) and low[-1] == 2 and high[-1] == 3 and steps[-1] == TOTAL_STEPS
    single = milestone_table({"glocal": groups["glocal"]})
    assert single.reference is None and single.p_values == {}


def test_a_run_that_finished_early_keeps_its_count_in_the_mean_until_the_budget() -> None:
    def finished(seed: int, learned_at: list[int], total_steps: int, status: int = STATUS_FINISHED) -> RunData:
        tasks = [f"A{i}" for i in range(len(learned_at))]
        state = CurriculumSnapshot(
            stamp_ns=1, log_time_ns=1, run_id=f"glocal-seed{seed}", strategy="glocal", seed=seed, status=status,
            iteration=1, total_steps=total_steps, step_budget=TOTAL_STEPS, evaluation_episodes=0, num_clusters=0,
            chosen_cluster=0, global_task="", local_tasks=(), learned_tasks=tuple(tasks), learned_policies=(),
            learned_at_steps=tuple(learned_at), remaining_tasks=(), milestone_interval=INTERVAL, milestone_steps=(),
            milestone_learned=())
        return RunData(Path(f"glocal-{seed}"), [state])

    early = finished(0, [0, 1000], total_steps=1000)  # learned both by 1k steps, then finished
    late = finished(1, [0, 3000], total_steps=3000)
    assert early.learned_curve()[0].tolist()[-1] == TOTAL_STEPS
    steps, mean, _, low, high = learned_curve_band([early, late])
    at_2k = np.searchsorted(steps, 2000, side="right") - 1
    assert (mean[at_2k], low[at_2k], high[at_2k]) == (1.5, 1, 2)  # the early run still counts, with its 2
    stopped = finished(2, [0], total_steps=1000, status=STATUS_TRAINING)  # interrupted: not extended
    assert stopped.learned_curve()[0].tolist()[-1] == 1000


def test_learned_grid_greys_tasks_not_in_the_run(recorded) -> None:
    run_dirs, _, _ = recorded
    groups = group_by_strategy(read_runs(run_dirs))
    grid = figures.learned_fraction_grid(groups["random"])
    assert grid[0, 0] == 1.0 and grid[0, 3] == 1.0 and grid[1, 2] == 0.5 and grid[2, 6] == 0.0
    assert np.isnan(grid[3:]).all()  # D..G are not tasks of the random runs
    assert grid[3:].shape == (4, 7)


def test_report_writes_figures_and_tables(recorded, tmp_path) -> None:
    run_dirs, _, broken = recorded
    out = tmp_path / "report"
    report = write_report([*run_dirs, broken], out)
    assert report == out / "report.md"
    text = report.read_text()
    pngs = sorted(p.name for p in out.glob("*.png"))
    assert pngs == ["learned_grid.png", "learned_vs_steps.png", "milestones_iqm.png", "milestones_violin.png",
                    "timeline_glocal_seed0.png"]
    for png in out.glob("*.png"):
        assert png.stat().st_size > 1000 and png.read_bytes()[:8] == PNG_MAGIC
        assert f"]({png.name})" in text
    assert f"| {run_dirs[0]} | glocal | 0 | 4,500 / 4,500 | 6/49 | 3 | yes | 3/2 (4) | 1 |" in text
    assert f"| {run_dirs[1]} | random | 0 | 4,500 / 4,500 | 2/21 | 0 | yes | 3/2 (4) | 1 |" in text
    assert f"| {run_dirs[-1]} | glocal | 2 | 4,500 / 4,500 | 7/49 | 3 | yes | 3/2 (4) | 3 |" in text
    # Milestones: glocal 3 seeds; at 1M all have A0, A1, A2.
    assert "| glocal | 3.0 ± 0.0 (n=3) | 4.0 ± 0.0 (n=3) | 6.0 ± 0.0 (n=3) | 6.7 ± 0.6 (n=3) |" in text
    assert "| random | 1.0 ± 0.0 (n=2) | 1.5 ± 0.7 (n=2) | 2.0 ± 0.0 (n=2) | 2.5 ± 0.7 (n=2) |" in text
    groups = group_by_strategy(read_runs(run_dirs))
    p_4m = milestone_table(groups).p_values["random"][4000]
    assert f"{p_4m:.3f}" in text and "Welch's t-test, glocal vs each strategy" in text
    assert "| random | 0.00e+00* |" in text  # 1M: both groups constant, unequal: p = 0, significant
    # rliable's statistics: IQM [95% interval] and P(glocal > random); 3 seeds: the interval is the seeds' range.
    assert "| glocal | 3 | 3.0 [3.0, 3.0] | 4.0 [4.0, 4.0] | 6.0 [6.0, 6.0] | 6.7 [6.0, 7.0] |" in text
    assert "| random | 2 | 1.0 [1.0, 1.0] | 1.5 [1.0, 2.0] | 2.0 [2.0, 2.0] | 2.5 [2.0, 3.0] |" in text
    assert "| random | 1.00 [1.00, 1.00]* | 1.00 [1.00, 1.00]* | 1.00 [1.00, 1.00]* | 1.00 [1.00, 1.00]* |" in text
    assert "Few seeds: with 2 runs the IQM trims none" in text
    assert "bag.2`: **skipped**" in text and f"`{broken}`: **no run read**" in text
    assert "| 2 | 1,500 | B0 | B1, C0, C1 | B0, B1, C0 |" in text
    # Per strategy, beside the learned objects: mean training steps and evaluation episodes.
    assert "training steps (mean) | evaluation episodes (mean) |" in text
    final = text.split("## Learned objects at the end of each run", 1)[1].split("##", 1)[0]
    assert [line.endswith("| 4,500 | 450 |") for line in final.splitlines()
            if line.startswith(("| glocal | 3 |", "| random | 2 |"))] == [True, True]


def test_report_of_a_single_run_has_no_t_test(recorded, tmp_path) -> None:
    run_dirs, _, _ = recorded
    report = write_report([run_dirs[1]], tmp_path / "single", count_episodes=False)
    text = report.read_text()
    assert "No t-test" in text and "Welch's t-test, glocal" not in text
    assert "| random | 1 | 1.0 [1.0, 1.0] |" in text and "No probability of improvement" in text
    assert (tmp_path / "single" / "milestones_violin.png").stat().st_size > 1000
    assert (tmp_path / "single" / "milestones_iqm.png").read_bytes()[:8] == PNG_MAGIC  # the IQM panel alone
    assert figures.plot_milestone_estimates(milestone_estimates({}, "glocal"), tmp_path / "none.png") is None
    assert not list((tmp_path / "single").glob("timeline_*.png"))  # random has no iterations


def test_cli_report(recorded, tmp_path) -> None:
    run_dirs, _, broken = recorded
    out = tmp_path / "cli"
    result = subprocess.run([sys.executable, "-m", "glocal_app.cli", "report", *map(str, run_dirs), str(broken),
                             "--out", str(out)], cwd=REPO, capture_output=True, text=True, timeout=120)
    assert result.returncode == 0, result.stderr
    assert result.stdout.strip().endswith(str(out / "report.md"))
    assert "warning: skipping bag" in result.stderr
    assert (out / "report.md").is_file()
    # No readable run at all: an error message, not a traceback.
    result = subprocess.run([sys.executable, "-m", "glocal_app.cli", "report", str(broken), "--out", str(out)],
                            cwd=REPO, capture_output=True, text=True, timeout=120)
    assert result.returncode == 2 and "no readable run" in result.stderr and "Traceback" not in result.stderr


def test_default_out_is_first_run_dir(recorded, tmp_path) -> None:
    run_dirs, _, _ = recorded
    run_dir = shutil.copytree(run_dirs[0], tmp_path / "copy")
    from glocal_app.cli import main

    assert main(["report", str(run_dir), "--no-episodes"]) == 0
    assert (run_dir / "report" / "report.md").is_file()


def test_analysis_is_ros_free() -> None:
    code = "import sys, glocal_ros.analysis.report, glocal_ros.analysis.figures; assert 'rclpy' not in sys.modules"
    subprocess.run([sys.executable, "-c", code], check=True, cwd=REPO)
    # The CLI registers `report` at its start: scipy (a second to import) only once a statistic is due.
    code = "import sys, glocal_app.cli; glocal_app.cli.build_parser(); assert 'scipy.stats' not in sys.modules"
    subprocess.run([sys.executable, "-c", code], check=True, cwd=REPO)

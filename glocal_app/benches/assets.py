"""``glocal-ros assets validate``: does an object's letter say what the agent feels?

Spearman's rank correlation between the letter's index (A = 0 .. G = 6) and
each measure, over the objects that have it:

(a) perturbed-grasp success and (b) scripted-grasp success, as
    ``glocal-ros assets check`` stored them in ``objects.json``;
(a') the share of top-down poses that lift the object, and its best pose's
    success, as ``glocal-ros assets lifting-poses`` (or the asset pipeline)
    stored them (``sim_node.lifting_poses``); a best pose below 80% breaks
    the set's rule that every object stays learnable, and is flagged;
(c) the A0 prior's score, ``episodes`` deterministic episodes per object,
    measured here. The prior meets each object as a Train goal meets it (the
    learner's default fine-tuning): the one-hot bits it never trained on start
    as the mean of the trained one (``learner_node.fine_tuning``). Without
    that, its score on an object is mostly the effect of a random input
    weight, not of the object;
(d) median steps to B per task, the learning cost, of the goals of a
    ``glocal-ros bench cost`` work directory or of ``glocal-ros bench
    transfer`` reports (optional; a goal that never passed counts as slower
    than any).

The easy rows should be the easy objects: (a), (a'), (b) and (c) fall with
the letter (negative), (d) rises with it. Rows are summarised by the mean of
shares of episodes and by the median of the share of lifting poses and of
steps to B.
"""

from __future__ import annotations

import math
import statistics
from pathlib import Path
from typing import Mapping, Sequence

from glocal_ros.tasks import DIFFICULTY_LEVELS, COMPLEXITY_LEVELS, grid_coordinates, sorted_tasks
from learner_node.profiles import DEFAULT_PROFILE, learner_profile

#: (key, heading, what a higher value means) of each measure, in the report's order.
MEASURES = (
    ("perturbed", "perturbed grasp", "easier"),
    ("scripted", "scripted grasp", "easier"),
    ("lifting_poses", "lifting poses", "easier"),
    ("best_pose", "best pose", "easier"),
    ("prior", "A0 prior", "easier"),
    ("steps_to_b", "steps to B", "harder"),
)

#: Measures whose rows are summarised by their median (the others by their mean).
_ROW_MEDIANS = ("lifting_poses", "steps_to_b")


def prior_scores(objects_dir: Path, tasks: Sequence[str], episodes: int, seed: int = 0,
                 num_envs: int = 2, profile: str = DEFAULT_PROFILE,
                 prior_store: Path | None = None) -> dict[str, float]:
    """Share of ``episodes`` seeded deterministic episodes in which ``profile``'s prior lifts each object,
    scored as ``learner/evaluate`` scores it (a goal's check before its first step). The prior is the one of
    ``prior_store`` where it holds one (a set of another A0), else the profile's shipped one."""
    import tempfile

    from glocal_app.benches.transfer import prior_stores
    from learner_node.evaluation import evaluate
    from learner_node.policies import PolicyRegistry
    from learner_node.policy_store import PolicyStore
    from learner_node.training import Trainer
    from sim_node.batch import BatchedEnvs
    from sim_node.grasp_env import GraspEnv

    envs = BatchedEnvs(lambda i: GraspEnv(tasks[0], objects_dir=objects_dir), num_envs, tasks[0])
    try:
        with tempfile.TemporaryDirectory(prefix="glocal-validate-") as work:
            policies = PolicyRegistry(PolicyStore(Path(work) / "policies"), prior_stores(prior_store, profile))
            trainer = Trainer(envs, policies, Path(work) / "checkpoints", profile=learner_profile(profile))
            scores = evaluate(envs, trainer.evaluation_policy("prior", tasks), tasks, episodes,
                              policy_name="prior", seed=seed)
    finally:
        envs.close()
    return {score.task: score.successes / score.episodes for score in scores}


def steps_to_b(goals: Sequence) -> dict[str, float]:
    """Median steps to B of each task's ``TransferGoal``s; ``inf`` where most never passed."""
    from glocal_app.benches.transfer import median_steps_to_b

    return {task: median_steps_to_b([goal for goal in goals if goal.task == task])
            for task in {goal.task for goal in goals}}


def letter_correlation(values: Mapping[str, float]) -> tuple[float, int]:
    """Spearman's rho between the letter index and ``values``, and how many objects it covers; NaN for
    fewer than 3 objects or values all equal (no order to correlate)."""
    from scipy.stats import spearmanr

    tasks = sorted_tasks(values)
    if len(tasks) < 3 or len({values[task] for task in tasks}) == 1:
        return math.nan, len(tasks)
    rho = spearmanr([grid_coordinates(task)[0] for task in tasks], [values[task] for task in tasks])[0]
    return float(rho), len(tasks)


def validation_report(measures: Mapping[str, Mapping[str, float]], command: str, preamble: str = "") -> str:
    """The correlation table, the learnable check, the row summaries and the per-object table of ``measures``
    (key -> task -> value)."""
    lines = ["# assets validate: the letter against what the simulator and the learner measure", "",
             f"Command: `{command}`  ", preamble, "",
             "| measure | objects | Spearman (letter, measure) | a higher value means |",
             "| --- | ---: | ---: | --- |"]
    for key, heading, higher in MEASURES:
        if measures.get(key):
            rho, count = letter_correlation(measures[key])
            shown = "- (all equal)" if math.isnan(rho) else f"{rho:.2f}"
            lines.append(f"| {heading} | {count} | {shown} | {higher} |")
    if measures.get("best_pose"):
        lines += ["", _learnable_line(measures["best_pose"])]
    lines += ["", "Rows (shares of episodes: the mean of the row's tasks; lifting poses and steps to B: "
              "their median):", "",
              "| row | " + " | ".join(heading for key, heading, _ in MEASURES if measures.get(key)) + " |",
              "| --- |" + " ---: |" * sum(1 for key, *_ in MEASURES if measures.get(key))]
    for letter in DIFFICULTY_LEVELS:
        cells = []
        for key, _, _ in MEASURES:
            if not measures.get(key):
                continue
            row = [value for task, value in measures[key].items() if task[0] == letter]
            cells.append("-" if not row else _format(key, statistics.median(row) if key in _ROW_MEDIANS
                                                     else statistics.fmean(row)))
        lines.append(f"| {letter} | " + " | ".join(cells) + " |")
    keys = [key for key, *_ in MEASURES if measures.get(key)]
    lines += ["", "Per object:", "", "| task | " + " | ".join(h for k, h, _ in MEASURES if k in keys) + " |",
              "| --- |" + " ---: |" * len(keys)]
    for task in sorted_tasks(set().union(*(measures[key] for key in keys))):
        lines.append(f"| {task} | " + " | ".join(
            _object_cell(key, measures[key][task]) if task in measures[key] else "-" for key in keys) + " |")
    return "\n".join(lines) + "\n"


def _learnable_line(best_pose: Mapping[str, float]) -> str:
    """The objects whose best pose lifts them less often than the set's rule allows."""
    from glocal_ros.objects.pipeline import MIN_BEST_POSE_SUCCESS

    failing = [f"{task} ({best_pose[task]:.0%})" for task in sorted_tasks(best_pose)
               if best_pose[task] < MIN_BEST_POSE_SUCCESS]
    return (f"Every object learnable (its best scripted pose lifts it at least {MIN_BEST_POSE_SUCCESS:.0%} of "
            f"the time): " + (f"**no**, {len(failing)} of {len(best_pose)} fail: {', '.join(failing)}."
                               if failing else f"yes, all {len(best_pose)}."))


def _format(key: str, value: float) -> str:
    if key == "steps_to_b":
        return "never" if math.isinf(value) else f"{value:.0f}"
    return f"{value:.0%}"


def _object_cell(key: str, value: float) -> str:
    """``_format``, and a best pose below the set's minimum flagged."""
    from glocal_ros.objects.pipeline import MIN_BEST_POSE_SUCCESS

    return _format(key, value) + (" (fails)" if key == "best_pose" and value < MIN_BEST_POSE_SUCCESS else "")


def validation_figure(measures: Mapping[str, Mapping[str, float]], png: Path) -> Path:
    """The 7x7 grid coloured by each measure, one panel per measure (green: easy; shares from 0 to 1)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    keys = [(key, heading, higher) for key, heading, higher in MEASURES if measures.get(key)]
    figure, axes = plt.subplots(1, len(keys), figsize=(3.6 * len(keys), 3.6), squeeze=False)
    for axis, (key, heading, higher) in zip(axes[0], keys):
        grid = np.full((len(DIFFICULTY_LEVELS), len(COMPLEXITY_LEVELS)), np.nan)
        for task, value in measures[key].items():
            row, column = grid_coordinates(task)
            grid[row, column] = value
        finite = grid[np.isfinite(grid)]
        top = finite.max() if finite.size else 1.0
        shown = np.where(np.isinf(grid), top, grid)  # "never" coloured as the slowest
        # Shares on one scale, 0 to 1, so that panels compare; steps to B on their own.
        limits = dict(vmin=0.0, vmax=1.0) if key != "steps_to_b" else {}
        image = axis.imshow(shown, cmap="RdYlGn" if higher == "easier" else "RdYlGn_r", **limits)
        rho, _ = letter_correlation(measures[key])
        axis.set_title(f"{heading}\n" + ("all equal" if math.isnan(rho) else f"Spearman {rho:.2f}"), fontsize=10)
        axis.set_xticks(range(len(COMPLEXITY_LEVELS)), COMPLEXITY_LEVELS)
        axis.set_yticks(range(len(DIFFICULTY_LEVELS)), DIFFICULTY_LEVELS)
        axis.set_xlabel("complexity")
        figure.colorbar(image, ax=axis, fraction=0.046, pad=0.04)
    figure.tight_layout()
    png.parent.mkdir(parents=True, exist_ok=True)
    figure.savefig(png, dpi=110)
    plt.close(figure)
    return png

"""``glocal-ros bench scale RUN_DIR``: a scaling model fitted on a recorded run (``glocal_ros.analysis.scale``).

It times RUN_DIR's calls (a sequential run: its journal and bag), fits the per-call and per-unit seconds,
predicts the wall-clock of the same run with K pairs (GloCAL's parallel locals for K >= 2, the real
scheduler and strategy on a virtual clock), predicts the paper's grid on M machines, and, with
``--validate DIR...``, predicts each of those runs from its own settings, K and recorded answers with the
model of RUN_DIR and sets the prediction beside its measured wall-clock.

The paper's grid (``PAPER_GRID``), from the paper and this project's schedule, since the paper gives no
count of evaluations: 60 runs of 4M training steps (GloCAL, random, ALP-GMM-250, ALP-GMM-10 and the two
ablations, 10 seeds each), S-bar = 100, T = 50.
- GloCAL and its ablations: a check of the trained task every 10,000 steps (400 in 4M) and one before
  each goal, about 74 goals (49 tasks, half of them twice); an evaluation of the remaining tasks at
  each of 12 iterations (the paper's sample run), the remaining tasks falling evenly from 49 to 0.
- Baselines: the remaining tasks evaluated at step 0 and every 100,000 steps (41 evaluations), their
  number falling evenly from 49 to the 8 the paper leaves unlearned; goals of a chunk of episodes of up
  to 50 steps (``glocal_ros.curriculum.baselines``): random's 100 episodes, 800 goals; ALP-GMM's refit
  interval, 320 goals for ALP-GMM-250 and 8,000 for ALP-GMM-10.
One run per machine of this kind (2 cores: the sim and learner processes of one pair fill them; a second
pair would halve each one's speed), so M machines run M runs at a time.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Sequence

from glocal_app.processes import preset_parameters, recorded_run_settings
from glocal_ros.analysis.scale import (
    CallCost, CallModel, RecordedRun, fit_model, predicted_segments, read_recorded_run, schedule, simulate,
    time_calls, with_pairs,
)
from glocal_ros.curriculum.run import RunConfig
from glocal_ros.curriculum.strategies import ALP_GMM_FIT_RATES

DEFAULT_PAIRS = (1, 2, 4, 8)
DEFAULT_MACHINES = (1, 10, 40)
DEFAULT_REPORT = Path("bench/results/scale.md")
RUNS_PER_MACHINE = 1


@dataclass(frozen=True)
class PaperRun:
    """What one run of the paper's grid does, in the model's terms (assumptions: the module doc)."""

    strategy: str
    seeds: int
    training_steps: int
    train_calls: int
    evaluate_calls: int
    evaluation_episodes: int

    def seconds(self, model: CallModel) -> float:
        return (self.train_calls * model.train_call_s + self.evaluate_calls * model.evaluate_call_s
                + model.step_s * self.training_steps + model.eval_episode_s * self.evaluation_episodes)


def _glocal_like(strategy: str) -> PaperRun:
    goals, iterations = 74, 12
    checks = 4_000_000 // 10_000 + goals
    iteration_tasks = iterations * (49 + 0) / 2
    return PaperRun(strategy, 10, 4_000_000, goals, iterations, int(100 * (checks + iteration_tasks)))


def _baseline(strategy: str, episodes_per_goal: int) -> PaperRun:
    evaluations = 1 + 4_000_000 // 100_000
    return PaperRun(strategy, 10, 4_000_000, 4_000_000 // (episodes_per_goal * 50), evaluations,
                    int(100 * evaluations * (49 + 8) / 2))


PAPER_GRID = (_glocal_like("glocal"), _baseline("random", RunConfig.baseline_chunk_episodes),
              *(_baseline(name, rate) for name, rate in ALP_GMM_FIT_RATES.items()),
              _glocal_like("glocal_no_global"), _glocal_like("glocal_random_cluster"))


def max_episode_steps(run_dir: Path) -> int:
    """T of a run's curriculum (baselines size their goals with it): its preset's, from ``run.json``."""
    settings = recorded_run_settings(run_dir)
    if settings is None:
        raise ValueError(f"{run_dir}: no run.json, so no preset to read T from")
    return int(preset_parameters(str(settings["preset"]), "curriculum_node")["max_episode_steps"])


def check_scale(run_dir: Path, validate: Sequence[Path], pairs: Sequence[int], machines: Sequence[int]) -> None:
    """``ValueError`` for bad input, before anything is read at length."""
    for name, values in (("--pairs", pairs), ("--machines", machines)):
        if not values or min(values) < 1:
            raise ValueError(f"{name} must be whole numbers of at least 1, got {','.join(map(str, values))}")
    for path in (run_dir, *validate):
        read_recorded_run(path)


def _model_rows(model: CallModel) -> list[str]:
    return [f"| seconds per Train goal (start, policy load and store) | {model.train_call_s:.3f} |",
            f"| seconds per evaluate call (plus the clustering after it) | {model.evaluate_call_s:.3f} |",
            f"| seconds per policy copy | {model.copy_call_s:.3f} |",
            f"| seconds per training env step | {model.step_s * 1e3:.3f} ms ({_rate(model.step_s)}) |",
            f"| seconds per evaluation episode | {model.eval_episode_s:.3f} |"]


def _rate(step_s: float) -> str:
    return f"{1 / step_s:.0f} steps/s" if step_s > 0 else "-"


def scale_report(run_dir: Path, validate: Sequence[Path], pairs: Sequence[int], machines: Sequence[int],
                 command: str) -> str:
    run = read_recorded_run(run_dir)
    steps_t = max_episode_steps(run_dir)
    segments = time_calls(run, steps_t)
    model = fit_model(segments)
    predicted = predicted_segments(model, segments)
    errors = sorted(abs(p - s.seconds) / s.seconds for s, p in zip(segments, predicted) if s.seconds > 0)
    lines = ["# bench scale: the wall-clock of a run with K pairs and of the paper's grid", "",
             f"Command: `{command}`  ",
             f"Fitted on `{run_dir}` ({run.config.strategy}, seed {run.config.seed}, {len(run.config.tasks)} tasks, "
             f"budget {run.config.step_budget:,} steps, S-bar {run.config.eval_episodes}; {len(run.entries)} calls "
             f"in {len(segments)} segments; measured wall-clock {run.wall_seconds:.1f} s, first state to last; "
             f"launched as {recorded_run_settings(run_dir)}, e.g. by `glocal-ros experiment --strategies "
             f"{run.config.strategy} --seeds {run.config.seed} --preset PRESET [--budget STEPS] --out DIR`).", "",
             "## The model (non-negative least squares over the run's calls)", "", "| term | value |", "|---|---|",
             *_model_rows(model), "",
             f"Fit error on the run's own calls: median {100 * errors[len(errors) // 2]:.0f}%, worst "
             f"{100 * errors[-1]:.0f}% per segment; the sum {sum(predicted):.1f} s against {run.wall_seconds:.1f} s "
             f"measured ({100 * (sum(predicted) / run.wall_seconds - 1):+.1f}%).", "",
             "## The same run with K pairs (the real Run and strategy on a virtual clock)", "",
             "K = 1: the sequential strategy; K >= 2: GloCAL with parallel_locals. The double answers from the "
             "recorded run (the n-th goal on a task gets its n-th recorded goal on it; scores from the nearest "
             "recorded evaluation of the task).", "",
             "| K | predicted wall-clock | speed-up | learned | training steps | evaluation episodes |",
             "|---|---|---|---|---|---|"]
    base = None
    for k in pairs:
        prediction = simulate(with_pairs(run.config, k), run, model, k, steps_t)
        base = base or prediction.seconds
        lines.append(f"| {k} | {prediction.seconds:.1f} s | {base / prediction.seconds:.2f}x | {prediction.learned} "
                     f"| {prediction.total_steps:,} | {prediction.evaluation_episodes:,} |")
    lines += ["", "## Validation: measured runs predicted from their own settings, K and answers, with this model", "",
              "| run | K | measured | predicted | error |", "|---|---|---|---|---|"]
    for path in validate:
        other: RecordedRun = read_recorded_run(path)
        prediction = simulate(other.config, other, model, other.pairs, max_episode_steps(path))
        lines.append(f"| `{path}` | {other.pairs} | {other.wall_seconds:.1f} s | {prediction.seconds:.1f} s | "
                     f"{100 * (prediction.seconds / other.wall_seconds - 1):+.1f}% |")
    if not validate:
        lines.append("| (none: --validate RUN_DIR...) | | | | |")
    lines += ["", "## The paper's grid (60 runs of 4M steps), one run per 2-core machine", "",
              "Per run, from the model's per-step and per-episode seconds (assumptions: "
              "`glocal_app/benches/scale.py`):", "",
              "| strategy | runs | Train goals | evaluations | evaluation episodes | hours per run |",
              "|---|---|---|---|---|---|"]
    run_seconds = []
    for paper_run in PAPER_GRID:
        seconds = paper_run.seconds(model)
        run_seconds += [seconds] * paper_run.seeds
        lines.append(f"| {paper_run.strategy} | {paper_run.seeds} | {paper_run.train_calls} | "
                     f"{paper_run.evaluate_calls} | {paper_run.evaluation_episodes:,} | {seconds / 3600:.1f} |")
    lines += ["", "| machines | grid wall-clock | days |", "|---|---|---|"]
    for m in machines:
        seconds = schedule(run_seconds, m * RUNS_PER_MACHINE)
        lines.append(f"| {m} | {seconds / 3600:.1f} h | {seconds / 86400:.2f} |")
    return "\n".join(lines) + "\n"


__all__ = ["CallCost", "PAPER_GRID", "check_scale", "scale_report"]

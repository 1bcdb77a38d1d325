"""``glocal-ros adapt``: a novel object, fine-tuned from the best policy of a finished run, through the graph.

``adapt RUN_DIR --object MESH_OR_OBJECT_DIR --name NAME``:

1. Checks everything before any goal starts, leaving the run directory as it
   was when one fails: the run is finished (its curriculum state), holds a
   global policy (``glocal_ros.adaptation.run_candidates``), ``NAME`` names a
   novel object (not A0..G6 in any case) that this run has not adapted to, the
   budget and seed are ones the learner takes, and the object can be prepared
   (``glocal_ros.objects.pipeline.prepare_object``, done in a scratch directory
   first).
2. Moves the prepared object to ``RUN_DIR/adapt/NAME/objects`` (a set of
   one; the run's own set is not touched), and starts recorder, sim and learner
   as the run had them (its preset, learner profile and seed:
   ``RunOptions.parameters``), the sim on the novel object only, the learner on
   the run's policy store, the bag in ``RUN_DIR/adapt/NAME/bag``.
3. Scores and fine-tunes (``glocal_ros.adaptation.adapt``): every candidate
   through ``learner/evaluate`` on the run's S-bar seeded episodes, then one
   Train goal from the best until its score passes the run's B (checked every
   ``eval_interval`` steps of the run's preset) or ``--budget`` steps (default:
   the preset's per-task budget) are spent, into ``<run_id>.adapt-NAME``
   beside the run's policies.
4. Writes ``RUN_DIR/adapt/NAME/adapt.json`` (every candidate's score, the one
   chosen, steps to B) and prints it.

An adaptation stopped before step 4 (Ctrl-C) and given again: with the same
object (the prepared object's files equal, ``object_fingerprint``) it goes on
in its directory, a new bag beside the first, the learner resuming the Train
goal from its checkpoint or answering it from its finished marker; with another
object it starts again from step 2, the stopped goal's checkpoint removed, or
is refused when the stopped one had stored its policy (the store has no delete:
the message names the directory to remove). The graph is one pair, whatever the
run's ``--pairs``: one goal runs at a time.

The goal's episodes and evaluations are in the bag like any goal's; the
sim's episodes name the task ``NAME@PROXY`` (``glocal_ros.tasks``).
"""

from __future__ import annotations

import json
import shutil
import tempfile
import time
from dataclasses import replace
from pathlib import Path

from glocal_app.processes import (
    RUN_FILE,
    STATE_FILE,
    NodeProcess,
    RunOptions,
    isolated_environment,
    new_bag_path,
    preset_file,
    preset_parameters,
    recorded_run_settings,
)
from glocal_ros.adaptation import AdaptSettings, Adaptation, adapt, run_candidates
from glocal_ros.curriculum.run import RunConfig
from glocal_ros.files import atomic_write
from glocal_ros.tasks import check_novel_name, novel_task

ADAPT_DIR = "adapt"
RESULT_FILE = "adapt.json"
#: The graph's nodes, in start order (the recorder first, so that the bag holds every episode).
NODES = ("recorder_node", "sim_node", "learner_node")


def adapted_policy(run_id: str, name: str) -> str:
    return f"{run_id}.adapt-{name}"


def stored_tasks(policy_dir: Path) -> dict[str, str]:
    """Each stored policy's last task, read from its record (no model is loaded)."""
    from learner_node.policy_store import PolicyStore

    store = PolicyStore(policy_dir)
    return {name: store.record(name).task for name in store.names()}


def run_summary(run_dir: Path) -> tuple[RunOptions, dict]:
    """The options of the finished run in ``run_dir`` and what its ``RUN_FILE``, its curriculum's end state and its
    preset (``initial_policy``) say of it; ``ValueError`` when it holds no run or an unfinished one."""
    from glocal_app.launch import run_finished

    settings = recorded_run_settings(run_dir)
    if settings is None:
        raise ValueError(f"{run_dir}: no run ({RUN_FILE} missing): give the directory of a finished launch")
    if not run_finished(run_dir):
        raise ValueError(f"{run_dir}: the run is not finished; finish it first (the same launch resumes it)")
    options = RunOptions.from_settings(settings)
    state = json.loads((run_dir / STATE_FILE).read_text())
    return options, {**state, **settings, "initial_policy": str(_curriculum_parameters(options)["initial_policy"])}


def run_profile(options: RunOptions) -> str:
    """The learner profile the run trained under: its own option, else its preset's, else the default."""
    from learner_node.profiles import DEFAULT_PROFILE

    return options.learner_profile or str(preset_parameters(options.preset, "learner_node").get(
        "learner_profile", DEFAULT_PROFILE))


def _curriculum_parameters(options: RunOptions) -> dict:
    defaults = {name: getattr(RunConfig, name)
                for name in ("threshold", "eval_episodes", "task_step_budget", "eval_interval", "initial_policy")}
    return {**defaults, **preset_parameters(options.preset, "curriculum_node")}


def _adapt_settings(options: RunOptions, run: dict, budget: int | None, seed: int | None) -> AdaptSettings:
    """The run's B, S-bar and evaluation interval (its preset's), ``budget`` or the preset's per-task budget;
    ``ValueError`` for a budget the run's learner would refuse, or a seed out of range."""
    from learner_node.training import DEFAULT_MAX_STEP_BUDGET

    curriculum = _curriculum_parameters(options)
    most = int(preset_parameters(options.preset, "learner_node").get("max_step_budget", DEFAULT_MAX_STEP_BUDGET))
    if budget is not None and not 1 <= budget <= most:
        raise ValueError(f"--budget must be 1 to {most} (the run's learner's max_step_budget), got {budget}")
    return AdaptSettings(budget if budget is not None else int(curriculum["task_step_budget"]),
                         float(curriculum["threshold"]), int(curriculum["eval_episodes"]),
                         int(curriculum["eval_interval"]), int(run["seed"] if seed is None else seed))


def adapt_run(run_dir: Path, source: Path, name: str, budget: int | None = None, seed: int | None = None,
              startup_timeout: float = 120.0, learner_timeout: float = 3600.0) -> Adaptation:
    """Adapt run ``run_dir``'s policies to the object ``source`` as ``name`` (the module's steps 1-4)."""
    from glocal_ros.paths import object_fingerprint
    from glocal_ros.objects.pipeline import prepare_object
    from learner_node.training import CHECKPOINTS_DIR

    run_dir = Path(run_dir).resolve()
    check_novel_name(name)
    options, run = run_summary(run_dir)
    settings = _adapt_settings(options, run, budget, seed)
    stored = stored_tasks(run_dir / "policies")
    candidates = run_candidates(run["run_id"], run["strategy"], stored, run.get("current_policy", ""),
                                run["initial_policy"])
    output = adapted_policy(run["run_id"], name)
    work = run_dir / ADAPT_DIR / name
    if (work / RESULT_FILE).exists():
        raise ValueError(f"run {run['run_id']} has adapted to an object named {name!r} already ({work}): choose "
                         "another name")
    scratch = Path(tempfile.mkdtemp(prefix=f"glocal-adapt-{name}-"))
    try:
        prepare_object(Path(source), name, scratch / "objects", seed=settings.seed)
        same_object = (work / "objects" / name).is_dir() and (
            object_fingerprint(name, work / "objects") == object_fingerprint(name, scratch / "objects"))
        if output in stored and not same_object:
            raise ValueError(f"the policy {output} exists but not the adaptation that made it from this object "
                             f"({work / RESULT_FILE} missing): choose another name, or remove "
                             f"{run_dir / 'policies' / output} to adapt again")
        if same_object:
            # The learner resumes the goal from its checkpoint, or answers it from its finished marker.
            print(f"{work}: an adaptation of this object that did not finish; going on", flush=True)
        else:
            if work.exists():
                print(f"{work}: an adaptation of another object that did not finish; starting again", flush=True)
                shutil.rmtree(work)
            # A checkpoint of the same goal name on another object must not be resumed.
            shutil.rmtree(run_dir / "policies" / CHECKPOINTS_DIR / output, ignore_errors=True)
            work.parent.mkdir(parents=True, exist_ok=True)
            shutil.move(str(scratch), str(work))
    finally:
        shutil.rmtree(scratch, ignore_errors=True)
    return _adapt_through_graph(run_dir, work, options, run, candidates, output, settings, name,
                                startup_timeout, learner_timeout)


def _adapt_through_graph(run_dir: Path, work: Path, options: RunOptions, run: dict, candidates, output: str,
                         settings: AdaptSettings, name: str, startup_timeout: float,
                         learner_timeout: float) -> Adaptation:
    """Steps 2-4 on the prepared object: the graph of one pair (whatever the run had), ``RESULT_FILE`` written
    before the graph stops."""
    from curriculum_node.ros_learner import RosLearner
    from glocal_app.launch import stop_graph, wait_for_recorder
    from glocal_ros.domain import reserve_domain_id
    from node_common.runner import spinning_node

    domain_id, lock = reserve_domain_id()
    started: list[NodeProcess] = []
    try:
        logs = work / "logs"
        env = isolated_environment(domain_id, logs)
        plan = replace(options, pairs=1).parameters(run["strategy"], int(run["seed"]), run_dir, new_bag_path(work))
        plan["sim_node"].update(objects_dir=str(work / "objects"), initial_task=novel_task(name, candidates[0].proxy))
        plan["learner_node"].update(tensorboard_dir=str(work / "tensorboard"))
        for node in NODES:
            started.append(NodeProcess(node, logs, plan[node], preset_file(options.preset), env))
        with spinning_node("glocal_ros_adapt", domain_id, num_threads=4) as node:
            wait_for_recorder(node, started, startup_timeout, spun_elsewhere=True)
            learner = RosLearner(node, timeout_sec=learner_timeout)
            learner.wait_for_learner()
            started_at = time.monotonic()
            adaptation = adapt(learner, name, candidates, output, settings)
            print(f"adapted in {time.monotonic() - started_at:.0f} s", flush=True)
        text = (json.dumps(adaptation.to_dict(), indent=1) + "\n").encode()
        atomic_write(work / RESULT_FILE, lambda stream: stream.write(text))
        return adaptation
    finally:
        stop_graph(started)
        lock.close()


def describe(adaptation: Adaptation) -> str:
    """The adaptation as a user reads it: every candidate's score, the one chosen, steps to B."""
    settings = adaptation.settings
    lines = [f"{adaptation.object_name}: {len(adaptation.scores)} candidates on {settings.eval_episodes} "
             f"episodes (seed {settings.seed}), B = {settings.threshold:g}"]
    for candidate, score in adaptation.scores:
        mark = "*" if candidate == adaptation.chosen else " "
        lines.append(f" {mark} {candidate.policy} ({', '.join(candidate.roles)}; as {candidate.proxy}): "
                     f"{score:g}/{settings.eval_episodes}")
    outcome = (f"passed B after {adaptation.steps_to_b} steps" if adaptation.learned
               else f"did not pass B in {adaptation.steps_used} steps (last score {adaptation.final_score:g})")
    lines.append(f"fine-tuned {adaptation.chosen.policy} on {adaptation.task} into {adaptation.output_policy}: "
                 f"{outcome}")
    return "\n".join(lines)

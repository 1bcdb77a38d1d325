"""``glocal-ros bench learner``: SAC env steps/s with updates, in-process vs through sim_node.

For each learner profile and each N, the same Train goal (SAC from the profile's shipped A0
``prior`` on G3, an object the prior is still learning, so that episodes run to
their time limit as in a curriculum's goals rather than ending in a few steps;
one compute thread) runs on N envs three ways:

- in-process: the ``Trainer`` here on a ``BatchedEnvs`` here;
- through sim_node: the same ``Trainer`` here on a ``SimClient`` of a sim_node
  process (its node spun by an executor in a background thread), which is
  what learner_node does for a Train goal;
- learner_node: a real learner_node process, sent the goal on its Train
  action, timed by the stamps and step counts of its TrainingProgress
  messages (optional, ``learner_node=False`` leaves it out);
- in-process with curves (optional, ``curves=True``): the in-process goal
  with a ``tensorboard_dir``, so that every progress report is also written
  to its TensorBoard events and CSV (``learner_node.scalars``). The bench
  reports (and writes) at every vector step, learner_node about once a
  second: at R env steps/s the bench writes R / N times as often as a
  learner, so its ratio to in-process is a worst case for the learner's.

The sim_node runs with its defaults (``workers`` one per core, at most N;
viewer topics on) but for ``num_envs``, on a ROS domain of its own.

What is timed: the Trainer reports progress after every vector step
(``progress_interval_sec=0``); between two reports lie one batch of N env
steps and the gradient steps SAC_KWARGS asks for (``train_freq=1``;
``gradient_steps=-1``: N, one per env step). Through sim_node a step's
gradient steps run while the sim computes the next step
(``learner_node.updates``); in-process, physics and updates take turns in
one thread. The rate is env steps over the time from the first report at
or after ``warmup_steps(N)`` (updates start after ``batch_size`` steps of
the goal; a few dozen more let the first updates settle) to the last one. Loading the model, the update-free warm-up,
the final evaluation (1 episode) and storing the policy are not timed; no
checkpoint falls inside a measurement. learner_node reports progress about
once a second, so its timed span is the same up to a second less.

Beside them, the floor no goal can beat: the same N envs in this process
stepped with random actions and no learner (``bench sim``'s in-process
rate). Rounds alternate between the variants so that load on the shared
machine hits all alike; the table reports medians, the ratios to in-process
and the ratio of learner_node to the floor.
"""

from __future__ import annotations

import os
import shutil
import statistics
import sys
import tempfile
import threading
import time
from contextlib import ExitStack
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Callable, Sequence

import numpy as np

from glocal_app.benches.sim import steps_per_second
from glocal_app.processes import NodeProcess, isolated_environment, namespace_arguments
from glocal_ros.domain import reserve_domain_id
from glocal_ros.sim_contract import BatchStepper
from node_common.runner import spinning_node
from learner_node.policies import PolicyRegistry
from learner_node.policy_store import PolicyStore
from learner_node.profiles import DEFAULT_PROFILE, PROFILES, LearnerProfile
from learner_node.sac_settings import DEFAULT_NETWORK, NETWORKS, SAC_KWARGS, COMPUTE_THREADS
from glocal_ros.curriculum.learner import TrainGoal
from learner_node.training import Trainer

#: Env steps of a goal after the update-free warm-up before the clock starts.
SETTLE_STEPS = 64
#: Writes of a progress report timed alone for ``--curves``.
CURVES_WRITES = 2000
TASK = "G3"
INITIAL_POLICY = "prior"
BATCH_SIZE = NETWORKS[DEFAULT_NETWORK].batch_size  # the shipped prior's (train-prior's default network)


@dataclass(frozen=True)
class LearnerBenchRow:
    profile: str  # the learner profile of the goals (``learner_node.profiles``)
    num_envs: int
    in_process: float  # env steps/s with SAC updates, envs in this process
    through_ros: float  # env steps/s with SAC updates here, envs in sim_node
    learner_node: float | None  # env steps/s of a learner_node process's Train goal; None: not measured
    workers: int  # sim_node's worker processes
    rounds: tuple[tuple[float, ...], ...] = ()  # every measurement, per variant (``variant_names``)
    env_floor: float | None = None  # env steps/s of the envs alone in this process, random actions
    with_curves: float | None = None  # in-process with training curves written at every report; None: not measured
    curves_write: float | None = None  # seconds per write of a progress report's curves, measured alone

    @property
    def ratio(self) -> float:
        return self.through_ros / self.in_process

    @property
    def learner_node_ratio(self) -> float | None:
        return None if self.learner_node is None else self.learner_node / self.in_process

    @property
    def variant_names(self) -> tuple[str, ...]:
        """The variants of ``rounds``, in order."""
        return ("in-process", "via sim_node", "env floor", *(("learner_node",) if self.learner_node is not None else ()),
                *(("in-process with curves",) if self.with_curves is not None else ()))

    @property
    def curves_ratio(self) -> float | None:
        return None if self.with_curves is None else self.with_curves / self.in_process

    @property
    def seconds_per_curves_write(self) -> float | None:
        """What one write of the curves adds to a vector step (one write per step of N envs)."""
        if self.with_curves is None:
            return None
        return self.num_envs / self.with_curves - self.num_envs / self.in_process

    @property
    def floor_ratio(self) -> float | None:
        """The graph's rate (learner_node, else via sim_node) as a share of the envs' own."""
        graph = self.through_ros if self.learner_node is None else self.learner_node
        return None if self.env_floor is None else graph / self.env_floor


def warmup_steps(num_envs: int) -> int:
    """Goal steps before the clock starts: updates run from ``batch_size`` steps on."""
    return BATCH_SIZE + SETTLE_STEPS + num_envs


def train_steps_per_second(envs: BatchStepper, policies: PolicyRegistry, work_dir: Path, output_policy: str,
                           num_envs: int, steps: int, seed: int = 0,
                           profile: LearnerProfile = PROFILES[DEFAULT_PROFILE],
                           tensorboard_dir: Path | None = None) -> float:
    """Run one Train goal of ``warmup_steps + steps`` env steps; env steps/s over the timed part."""
    trainer = Trainer(envs, policies, work_dir / ".checkpoints", seed, checkpoint_interval=10**12,
                      progress_interval_sec=0.0, profile=profile, tensorboard_dir=tensorboard_dir)
    warmup = warmup_steps(num_envs)
    spec = TrainGoal(task=TASK, initial_policy=INITIAL_POLICY, output_policy=output_policy,
                     step_budget=warmup + steps, threshold=0.0, eval_episodes=1, eval_interval=0)
    marks: list[tuple[float, int]] = []
    trainer.train(spec, on_progress=lambda progress: marks.append((time.perf_counter(), progress.steps)))
    return timed_rate(marks, warmup)


def seconds_per_curves_write(folder: Path, writes: int = CURVES_WRITES) -> float:
    """Wall-clock seconds per ``GoalScalars.write`` of a progress report's scalars, ``writes`` in a row."""
    from learner_node.scalars import GoalScalars
    from learner_node.training import TrainProgress

    report = TrainProgress(1000, 2000, 40, 0.5, 15.0, 300.0, 12.5, -3.2, 0.4, 0.05).scalars()
    scalars = GoalScalars(folder)
    try:
        started = time.perf_counter()
        for step in range(writes):
            scalars.write(step, report)
        return (time.perf_counter() - started) / writes
    finally:
        scalars.close()


def timed_rate(marks: Sequence[tuple[float, int]], warmup: int) -> float:
    """Env steps/s between the first (time, goal steps) mark at or after ``warmup`` and the last."""
    timed = [(t, s) for t, s in marks if s >= warmup]
    if len(timed) < 2 or timed[-1][0] <= timed[0][0]:
        raise RuntimeError(f"too few progress reports after the warm-up ({len(marks)} in all): time more steps")
    (t0, s0), (t1, s1) = timed[0], timed[-1]
    return (s1 - s0) / (t1 - t0)


class LearnerNodeGoals:
    """Train goals sent to a learner_node process; timed by its TrainingProgress messages."""

    def __init__(self, node, namespace: str):
        from glocal_interfaces.action import Train
        from glocal_interfaces.msg import TrainingProgress

        from node_common import names, qos
        from node_common.action_client import ActionClient

        self._train_type = Train
        self.client = ActionClient(node, Train, f"{namespace}/{names.LEARNER_TRAIN}")
        self._progress: list[tuple[str, float, int]] = []  # (output policy, stamp, goal steps)
        node.create_subscription(TrainingProgress, f"{namespace}/{names.TRAINING_PROGRESS}", self._on_progress,
                                 qos.EVENTS)

    def _on_progress(self, message) -> None:
        stamp = message.header.stamp.sec + 1e-9 * message.header.stamp.nanosec
        self._progress.append((message.output_policy, stamp, message.goal_steps))

    def ready(self) -> bool:
        return self.client.server_is_ready()

    def steps_per_second(self, output_policy: str, num_envs: int, steps: int, timeout: float) -> float:
        from action_msgs.msg import GoalStatus

        warmup = warmup_steps(num_envs)
        goal = self._train_type.Goal(task=TASK, initial_policy=INITIAL_POLICY, output_policy=output_policy,
                                     step_budget=warmup + steps, eval_episodes=1, eval_interval=0)
        handle = _wait(self.client.send_goal_async(goal), 30, "the Train goal's acceptance")
        if not handle.accepted:
            raise RuntimeError("learner_node rejected the Train goal")
        result = _wait(handle.get_result_async(), timeout, "the Train result")
        if result.status != GoalStatus.STATUS_SUCCEEDED:
            raise RuntimeError(f"the Train goal ended with status {result.status}: {result.result.message}")
        time.sleep(0.2)  # the last progress message may trail the result
        return timed_rate([(t, s) for name, t, s in list(self._progress) if name == output_policy], warmup)


def _wait(future, timeout: float, what: str):
    done = threading.Event()
    future.add_done_callback(lambda _: done.set())
    if not done.wait(timeout):
        raise RuntimeError(f"no {what} within {timeout:.0f} s")
    return future.result()


def run_learner_bench(env_counts: Sequence[int], steps: int, rounds: int, learner_node: bool = True,
                      log: Callable[[str], None] = print, profiles: Sequence[str] = (DEFAULT_PROFILE,),
                      curves: bool = False) -> list[LearnerBenchRow]:
    from learner_node.sim_client import SimClient
    from sim_node.batch import BatchedEnvs
    from sim_node.grasp_env import GraspEnv

    domain_id, lock = reserve_domain_id()
    work = Path(tempfile.mkdtemp(prefix="glocal-bench-learner-"))
    logs = work / "logs"
    rng = np.random.default_rng(0)
    rows = []
    stack = ExitStack()
    try:
        node = stack.enter_context(spinning_node("bench_learner", domain_id))
        for profile, num_envs in ((profile, num_envs) for profile in profiles for num_envs in env_counts):
            learner_profile = PROFILES[profile]
            policies = PolicyRegistry(PolicyStore(work / "policies" / profile),
                                      [PolicyStore(learner_profile.shipped_priors())], seed=0)
            workers = min(num_envs, os.cpu_count() or 1)
            namespace = f"/bench_{profile}_{num_envs}"
            env = isolated_environment(domain_id, logs)
            processes = [NodeProcess("sim_node", logs, {"num_envs": num_envs, "initial_task": TASK}, env=env,
                                     extra_args=namespace_arguments(namespace))]
            client = SimClient(node, namespace=namespace)
            waits: list[tuple[str, Callable[[], bool]]] = [("sim_node's services", client.ready)]
            variants: list[tuple[str, Callable[[str], float]]] = []
            batch = BatchedEnvs(lambda i: GraspEnv(TASK), num_envs, TASK)
            variants.append(("in-process", lambda name: train_steps_per_second(
                batch, policies, work, name, num_envs, steps, profile=learner_profile)))
            variants.append(("through sim_node", lambda name: train_steps_per_second(
                client, policies, work, name, num_envs, steps, profile=learner_profile)))
            variants.append(("env floor", lambda name: steps_per_second(
                batch.step, num_envs, max(1, steps // num_envs), rng)))
            if learner_node:
                processes.append(NodeProcess(
                    "learner_node", logs, {"policy_dir": str(work / f"learner-{num_envs}"), "seed": 0,
                                           "checkpoint_interval": 10_000_000, "learner_profile": profile},
                    env=env, extra_args=namespace_arguments(namespace)))
                goals = LearnerNodeGoals(node, namespace)
                waits.append(("learner_node's Train action", goals.ready))
                variants.append(("learner_node", lambda name: goals.steps_per_second(
                    name, num_envs, steps, timeout=60 + 10 * (steps + warmup_steps(num_envs)))))
            if curves:
                variants.append(("in-process with curves", lambda name: train_steps_per_second(
                    batch, policies, work, name, num_envs, steps, profile=learner_profile,
                    tensorboard_dir=work / "tensorboard")))
            try:
                for what, ready in waits:
                    deadline = time.monotonic() + 120
                    while not ready():
                        if not all(p.running for p in processes) or time.monotonic() > deadline:
                            raise RuntimeError(f"no {what}: see the logs in {logs}")
                        time.sleep(0.1)
                runs: list[list[float]] = [[] for _ in variants]
                for round_index in range(rounds):
                    for run, (name, measure) in zip(runs, variants):
                        run.append(measure(f"bench-{name.replace(' ', '-')}-{num_envs}-{round_index}"))
                        log(f"{profile} N={num_envs} round {round_index + 1}/{rounds}: {name} {run[-1]:.1f} steps/s")
                medians = {name: statistics.median(run) for run, (name, _) in zip(runs, variants)}
                row = LearnerBenchRow(profile, num_envs, medians["in-process"], medians["through sim_node"],
                                      medians.get("learner_node"), workers, tuple(tuple(run) for run in runs),
                                      env_floor=medians["env floor"], with_curves=medians.get("in-process with curves"))
                log(f"{profile} N={num_envs}: in-process {row.in_process:.1f} steps/s, through sim_node ({workers} workers) "
                    f"{row.through_ros:.1f}, ratio {row.ratio:.2f}"
                    + (f"; learner_node {row.learner_node:.1f}, ratio {row.learner_node_ratio:.2f}"
                       if learner_node else "")
                    + f"; env floor {row.env_floor:.1f}, graph / floor {row.floor_ratio:.2f}"
                    + (f"; in-process with curves {row.with_curves:.1f}, ratio {row.curves_ratio:.2f}" if curves else ""))
                if curves:
                    row = replace(row, curves_write=statistics.median(
                        seconds_per_curves_write(work / "writes" / f"{profile}-{num_envs}-{index}") for index in range(3)))
                rows.append(row)
            finally:
                batch.close()
                for process in reversed(processes):
                    process.stop()
    finally:
        stack.close()
        lock.close()
        shutil.rmtree(work, ignore_errors=True)
    return rows


def learner_bench_report(rows: Sequence[LearnerBenchRow], command: str, steps: int, rounds: int) -> str:
    batch_size = BATCH_SIZE
    gradient_steps = SAC_KWARGS["gradient_steps"]
    gradient_steps = ("N gradient steps" if gradient_steps == -1 else
                      f"{gradient_steps} gradient step{'s' if gradient_steps != 1 else ''}")

    def maybe(value: float | None, digits: int) -> str:
        return "-" if value is None else f"{value:.{digits}f}"

    lines = [
        "# bench learner: SAC env steps/s with updates, in-process vs through sim_node",
        "",
        f"Command: `{command}`  ",
        f"{time.strftime('%Y-%m-%d %H:%M')}, Python {sys.version.split()[0]}, {os.cpu_count()} CPU cores. "
        f"Load average at the end {os.getloadavg()[0]:.1f} (the machine is shared). "
        f"One Train goal per measurement: SAC from the profile's `{INITIAL_POLICY}` on {TASK} (batch {batch_size}, "
        f"{gradient_steps} per batch of N env steps, {COMPUTE_THREADS} compute thread, SBX's networks and "
        f"updates in the learner's compiled loop, `learner_node/updates.py`); "
        f"{steps} env steps timed after {batch_size} + {SETTLE_STEPS} + N warm-up steps (updates start after "
        f"{batch_size}); model loading, the warm-up, the final evaluation and storing are not timed. "
        f"*in-process* and *via sim_node* run the Trainer in the bench process (envs in it, or a sim_node "
        f"process with its default workers over `sim/step`), timed at every step; *learner_node* sends the goal "
        f"to a learner_node process, timed by the stamps of its TrainingProgress (about 1 Hz). "
        f"*env floor*: the same envs in the bench process, random actions, no learner (`bench sim`'s "
        f"in-process rate): no goal can beat it. Median of {rounds} alternating rounds.",
        "",
        "| profile | N envs | in-process | via sim_node (workers) | learner_node | env floor "
        "| ratio sim_node / in-process | ratio learner_node / in-process | ratio graph / floor |",
        "| --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: |",
    ]
    lines += [f"| {r.profile} | {r.num_envs} | {r.in_process:.1f} | {r.through_ros:.1f} ({r.workers}) | {maybe(r.learner_node, 1)} "
              f"| {maybe(r.env_floor, 1)} | {r.ratio:.2f} | {maybe(r.learner_node_ratio, 2)} "
              f"| {maybe(r.floor_ratio, 2)} |" for r in rows]
    lines += ["", "Graph: learner_node, or via sim_node where learner_node was not measured."]
    curved = [r for r in rows if r.with_curves is not None]
    if curved:
        lines += ["", "Training curves (`--curves`): the in-process goal writing its TensorBoard events and CSV "
                  "(`learner_node.scalars`) at every progress report, here every vector step: a worst case for "
                  "learner_node, which writes about once a second. A write's cost, two ways: from the rates, "
                  "N / (with curves) - N / (in-process) seconds (medians; as noisy as the rates), and timed "
                  f"alone, {CURVES_WRITES} writes of a progress report in a row (median of 3). At one write a "
                  "second a write's cost in seconds is its share of the learner's time.", "",
                  "| profile | N envs | in-process | with curves | ratio with curves / in-process | "
                  "ratios in the same round | a write from the rates (ms) | a write alone (ms) | share at 1 Hz |",
                  "| --- | ---: | ---: | ---: | ---: | --- | ---: | ---: | ---: |"]
        lines += [f"| {r.profile} | {r.num_envs} | {r.in_process:.1f} | {r.with_curves:.1f} | {r.curves_ratio:.3f} | "
                  + ", ".join(f"{v / base:.3f}" for v, base in zip(r.rounds[-1], r.rounds[0]))
                  + f" | {1000 * r.seconds_per_curves_write:.2f} | {maybe(None if r.curves_write is None else 1000 * r.curves_write, 3)} "
                  f"| {maybe(None if r.curves_write is None else 100 * r.curves_write, 4)}% |"
                  for r in curved]
    lines += ["", "Every round, in order (env steps/s):", ""]
    for r in rows:
        names = r.variant_names
        runs = "; ".join(f"{name} " + ", ".join(f"{v:.1f}" for v in run) for name, run in zip(names, r.rounds))
        paired = [", ".join(f"{v / base:.2f}" for v, base in zip(run, r.rounds[0])) for run in r.rounds[1:]]
        lines.append(f"- {r.profile}, N={r.num_envs}: {runs} (ratios in the same round: "
                     + "; ".join(f"{name} {ratios}" for name, ratios in zip(names[1:], paired)) + ")")
    return "\n".join(lines) + "\n"

"""``glocal-ros bench sim``: env steps/s in-process vs through sim_node, side by side.

For each N, the same random actions drive N GraspEnvs in lockstep: as a
``BatchedEnvs`` in this process, and through two sim_node processes (their
``sim/step`` service, from a ``SimClient`` here), one stepping all envs in
its own process (``workers:=1``) and one with its default worker processes.
Rounds alternate between the three so that load on the shared machine hits
all alike; the table reports medians and the ratio of the default sim_node
to in-process.
"""

from __future__ import annotations

import os
import statistics
import sys
import tempfile
import time
from contextlib import ExitStack
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Sequence

import numpy as np

from glocal_app.processes import NodeProcess, isolated_environment, namespace_arguments
from glocal_ros.domain import reserve_domain_id
from node_common.runner import spinning_node
from sim_node.batch import BatchedEnvs
from sim_node.grasp_env import GraspEnv


@dataclass(frozen=True)
class SimBenchRow:
    num_envs: int
    in_process: float  # env steps/s
    ros_one_process: float  # env steps/s, sim_node with workers:=1
    through_ros: float  # env steps/s, sim_node with its default workers
    workers: int

    @property
    def ratio(self) -> float:
        return self.through_ros / self.in_process


def steps_per_second(step_batch: Callable[[np.ndarray], object], num_envs: int, batches: int,
                     rng: np.random.Generator) -> float:
    actions = rng.uniform(-1, 1, size=(batches, num_envs, 5)).astype(np.float32)
    start = time.perf_counter()
    for batch_actions in actions:
        step_batch(batch_actions)
    return num_envs * batches / (time.perf_counter() - start)


def run_sim_bench(env_counts: Sequence[int], batches: int, rounds: int, task: str = "A0",
                  log: Callable[[str], None] = print) -> list[SimBenchRow]:
    from learner_node.sim_client import SimClient

    domain_id, lock = reserve_domain_id()
    logs = Path(tempfile.mkdtemp(prefix="glocal-bench-"))
    rows = []
    stack = ExitStack()
    try:
        node = stack.enter_context(spinning_node("bench_sim", domain_id))
        for num_envs in env_counts:
            env = isolated_environment(domain_id, logs)
            workers = min(num_envs, os.cpu_count() or 1)
            sims = [NodeProcess("sim_node", logs, {"num_envs": num_envs, "initial_task": task, "viewer_rate_hz": 0.0,
                                                   "workers": count},
                                env=env, extra_args=namespace_arguments(f"/w{count}"))
                    for count in (1, workers)]
            clients = [SimClient(node, namespace=f"/w{count}") for count in (1, workers)]
            batch = BatchedEnvs(lambda i: GraspEnv(task), num_envs, task)
            try:
                for sim, client in zip(sims, clients):
                    deadline = time.monotonic() + 120
                    while not client.ready():
                        if not sim.running or time.monotonic() > deadline:
                            raise RuntimeError(f"sim_node did not start: see {sim.log_path}")
                        time.sleep(0.1)
                    client.reset()
                rng = np.random.default_rng(0)
                runs: list[list[float]] = [[], [], []]
                for _ in range(rounds):
                    for run, step in zip(runs, (batch.step, clients[0].step, clients[1].step)):
                        run.append(steps_per_second(step, num_envs, batches, rng))
                row = SimBenchRow(num_envs, *(statistics.median(run) for run in runs), workers)
                log(f"N={num_envs}: in-process {row.in_process:.0f} steps/s, sim_node (1 process) "
                    f"{row.ros_one_process:.0f}, sim_node ({workers} workers) {row.through_ros:.0f}, "
                    f"ratio {row.ratio:.2f}")
                rows.append(row)
            finally:
                batch.close()
                for sim in sims:
                    sim.stop()
    finally:
        stack.close()
        lock.close()
    return rows


def sim_bench_report(rows: Sequence[SimBenchRow], command: str, batches: int, rounds: int) -> str:
    lines = [
        "# bench sim: env steps/s, in-process vs through sim_node",
        "",
        f"Command: `{command}`  ",
        f"{time.strftime('%Y-%m-%d %H:%M')}, Python {sys.version.split()[0]}, {batches} lockstep batches of "
        f"random actions per measurement, median of {rounds} alternating rounds.",
        "",
        "| N envs | in-process | sim_node, 1 process | sim_node, default workers | ratio default / in-process |",
        "| ---: | ---: | ---: | ---: | ---: |",
    ]
    lines += [f"| {r.num_envs} | {r.in_process:.0f} | {r.ros_one_process:.0f} | {r.through_ros:.0f} ({r.workers}) "
              f"| {r.ratio:.2f} |" for r in rows]
    return "\n".join(lines) + "\n"

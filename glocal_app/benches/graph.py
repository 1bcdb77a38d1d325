"""``glocal-ros bench graph``: does any answer get lost between the nodes, idle and under load?

A sim_node (2 envs, T = 10) and a learner_node run as processes on a ROS
domain of their own; the bench process is their client, spun by a
MultiThreadedExecutor as the curriculum node is. Rows:

- ``Train goals``: short goals (2 env steps, 1 evaluation episode, each its
  own output policy) sent one after another through ``RosLearner``, exactly
  as the curriculum sends them;
- ``learner/evaluate``: one-episode evaluations of ``random``;
- ``sim/step``: random actions straight to the sim's batched step.

Services run sequentially and from 4 threads at once; goals only one after
another (the learner runs one at a time). An evaluation (an episode, about
0.17 s here) costs 20 sim steps and more, hence fewer of them by default. Every row runs without and with a
CPU burner per core beside it. A call is *lost* when it failed or did not
answer within ``CALL_TIMEOUT_SEC``; *recovered* counts what ``RosLearner``
had to do to get an answer (a goal sent again, a result asked for again).
Latency is per call (per goal: send to result), p50 and p99.
"""

from __future__ import annotations

import os
import subprocess
import sys
import tempfile
import threading
import time
from concurrent.futures import ThreadPoolExecutor
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Iterator, Sequence

import numpy as np

from glocal_app.processes import NodeProcess, isolated_environment
from glocal_ros.domain import reserve_domain_id
from glocal_ros.spaces import ACTION_DIM
from node_common.runner import spinning_node

CALL_TIMEOUT_SEC = 60.0
NUM_ENVS = 2
BURNER = "while True: pass"


@dataclass(frozen=True)
class GraphBenchRow:
    what: str
    threads: int
    burner: bool
    calls: int
    lost: int
    recovered: int
    p50_ms: float
    p99_ms: float
    wall_s: float


@contextmanager
def burners(on: bool) -> Iterator[None]:
    """One busy-looping process per core while inside, when ``on``."""
    processes = [subprocess.Popen([sys.executable, "-c", BURNER]) for _ in range(os.cpu_count() or 1)] if on else []
    try:
        yield
    finally:
        for process in processes:
            process.kill()
            process.wait()


def timed_calls(call: Callable[[int], None], count: int, threads: int) -> tuple[list[float], int]:
    """Latencies (s) of ``count`` calls of ``call(index)`` from ``threads`` threads, and how many failed."""
    latencies: list[float] = []
    lost = 0
    lock = threading.Lock()

    def one(index: int) -> None:
        nonlocal lost
        started = time.perf_counter()
        try:
            call(index)
        except Exception:  # noqa: BLE001 - counted: the bench reports losses, it does not stop on them
            with lock:
                lost += 1
            return
        with lock:
            latencies.append(time.perf_counter() - started)

    with ThreadPoolExecutor(threads) as pool:
        list(pool.map(one, range(count)))
    return latencies, lost


def run_graph_bench(goals: int, evaluations: int, steps: int,
                    log: Callable[[str], None] = print) -> list[GraphBenchRow]:
    from glocal_interfaces.srv import Evaluate, StepEnvs

    from curriculum_node.ros_learner import RosLearner
    from glocal_ros.curriculum.learner import TrainGoal
    from node_common import names
    from node_common.arrays import to_float32_field
    from node_common.calls import call_checked

    domain_id, lock = reserve_domain_id()
    work = Path(tempfile.mkdtemp(prefix="glocal-bench-graph-"))
    env = isolated_environment(domain_id, work / "logs")
    processes = [
        NodeProcess("sim_node", work / "logs", {"num_envs": NUM_ENVS, "max_steps": 10}, env=env),
        NodeProcess("learner_node", work / "logs", {"policy_dir": str(work / "policies"),
                                                    "checkpoint_interval": 10_000_000}, env=env),
    ]
    rows: list[GraphBenchRow] = []
    rng = np.random.default_rng(0)
    try:
        with spinning_node("bench_graph", domain_id, num_threads=4) as node:
            learner = RosLearner(node, timeout_sec=CALL_TIMEOUT_SEC)
            learner.wait_for_learner()
            evaluate = node.create_client(Evaluate, names.LEARNER_EVALUATE)
            step = node.create_client(StepEnvs, names.SIM_STEP)
            step.wait_for_service(CALL_TIMEOUT_SEC)
            actions = to_float32_field(rng.uniform(-1, 1, (NUM_ENVS, ACTION_DIM)).astype(np.float32))
            sent = iter(range(10**9))

            def train(index: int) -> None:
                learner.train(TrainGoal(task="A0", initial_policy="prior", output_policy=f"bench-{next(sent)}",
                                           step_budget=NUM_ENVS, threshold=0.0, eval_episodes=1,
                                           stop_when_learned=False))

            def evaluate_once(index: int) -> None:
                call_checked(evaluate, Evaluate.Request(policy="random", tasks=["A0"], episodes=1, seed=-1),
                             CALL_TIMEOUT_SEC)

            def step_once(index: int) -> None:
                call_checked(step, StepEnvs.Request(actions=actions), CALL_TIMEOUT_SEC)

            evaluate_once(0)  # an answered request: the learner's side of discovery is done too
            jobs = [("Train goals", train, goals, 1), ("learner/evaluate", evaluate_once, evaluations, 1),
                    ("learner/evaluate", evaluate_once, evaluations, 4), ("sim/step", step_once, steps, 1),
                    ("sim/step", step_once, steps, 4)]
            for burner in (False, True):
                with burners(burner):
                    for what, call, count, threads in jobs:
                        recovered_before = learner.goals_sent_again + learner.results_asked_again
                        started = time.monotonic()
                        latencies, lost = timed_calls(call, count, threads)
                        row = GraphBenchRow(
                            what, threads, burner, count, lost,
                            learner.goals_sent_again + learner.results_asked_again - recovered_before,
                            1e3 * _percentile(latencies, 50), 1e3 * _percentile(latencies, 99),
                            time.monotonic() - started)
                        rows.append(row)
                        log(f"{what}, {threads} thread(s), burner {'on' if burner else 'off'}: {row.calls} calls, "
                            f"{row.lost} lost, {row.recovered} recovered, p50 {row.p50_ms:.1f} ms, "
                            f"p99 {row.p99_ms:.1f} ms")
    finally:
        for process in reversed(processes):
            process.stop()
        lock.close()
    return rows


def _percentile(values: Sequence[float], q: float) -> float:
    return float(np.percentile(values, q)) if values else float("nan")


def graph_bench_report(rows: Sequence[GraphBenchRow], command: str) -> str:
    lines = [
        "# bench graph: lost answers between the nodes, idle and under load",
        "",
        f"Command: `{command}`  ",
        f"{time.strftime('%Y-%m-%d %H:%M')}, Python {sys.version.split()[0]}, {os.cpu_count()} CPU cores. "
        f"sim_node ({NUM_ENVS} envs, T = 10) and learner_node as processes; the client a MultiThreadedExecutor "
        f"node. Train goals go through the curriculum's `RosLearner` (2 env steps, 1 evaluation episode each); "
        f"*lost*: failed or unanswered within {CALL_TIMEOUT_SEC:.0f} s; *recovered*: goals `RosLearner` sent "
        f"again or results it asked for again. Burner: one `{BURNER}` process per core.",
        "",
        "| calls | threads | CPU burner | count | lost | recovered | p50 ms | p99 ms | wall s |",
        "| --- | ---: | --- | ---: | ---: | ---: | ---: | ---: | ---: |",
    ]
    lines += [f"| {r.what} | {r.threads} | {'on' if r.burner else 'off'} | {r.calls} | {r.lost} | {r.recovered} "
              f"| {r.p50_ms:.1f} | {r.p99_ms:.1f} | {r.wall_s:.0f} |" for r in rows]
    total = sum(r.lost for r in rows)
    lines += ["", f"Lost in all: {total} of {sum(r.calls for r in rows)}."]
    return "\n".join(lines) + "\n"

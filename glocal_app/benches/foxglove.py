"""``glocal-ros bench foxglove``: what an idle foxglove_bridge_node costs a training run.

The training throughput of the graph (env steps/s of a learner_node Train goal through sim_node, viewer
topics on, timed as ``bench learner`` times its learner_node column) with no bridge and with a bridge
serving on loopback that no client is connected to, side by side: the same sim_node and learner_node
processes, after one untimed warm-up goal (the learner's first goals run slower: JAX compiles), the
two variants alternating in ABBA order (without, with, with, without, ...) so that the load of the
shared machine, and its drift, hit both alike. The bridge is started before each of its
rounds (and is serving: its port accepts connections) and stopped after it, so that the rounds without
it really run without it.

The table reports the median of each variant, the ratio of the medians, each pair's ratio (a round
with the bridge over the round without it next to it), and each ABBA block's ratio (the geometric mean
of its two rounds with over its two without: a load that drifts linearly through the block cancels).
Target: with >= 0.95 x without. Beside it, a measure the machine's noise does not blur: the CPU time
the bridge process itself took during its rounds (``/proc``), as a share of one core.
"""

from __future__ import annotations

import os
import shutil
import socket
import statistics
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

from glocal_app.benches.learner import BATCH_SIZE, INITIAL_POLICY, SETTLE_STEPS, TASK, LearnerNodeGoals, warmup_steps
from glocal_app.processes import FOXGLOVE_HOST, FOXGLOVE_NODE, NodeProcess, isolated_environment, namespace_arguments
from glocal_ros.domain import reserve_domain_id
from node_common.runner import spinning_node

NAMESPACE = "/benchfox"
TARGET_RATIO = 0.95
VARIANTS = ("without bridge", "bridge idle")


@dataclass(frozen=True)
class FoxgloveBenchResult:
    num_envs: int
    steps: int
    rates: dict[str, list[float]]  # variant -> env steps/s of each of its rounds, in order
    pairs: list[float]  # with / without, per ABBA pair
    blocks: list[float]  # sqrt(with x with / (without x without)), per whole ABBA block of four rounds
    bridge_cpu: list[tuple[float, float]]  # per round with the bridge: (its CPU seconds, the round's wall seconds)

    @property
    def bridge_core_share(self) -> float:
        """The idle bridge's CPU time over its rounds' wall time: the share of one core it took."""
        return sum(cpu for cpu, _ in self.bridge_cpu) / sum(wall for _, wall in self.bridge_cpu)

    def median(self, variant: str) -> float:
        return statistics.median(self.rates[variant])

    @property
    def ratio(self) -> float:
        return self.median(VARIANTS[1]) / self.median(VARIANTS[0])


def _free_port() -> int:
    with socket.socket() as probe:
        probe.bind((FOXGLOVE_HOST, 0))
        return probe.getsockname()[1]


def _serving(port: int) -> bool:
    with socket.socket() as probe:
        return probe.connect_ex((FOXGLOVE_HOST, port)) == 0


def cpu_seconds(pid: int) -> float:
    """User + system CPU time of a process so far (Linux ``/proc``)."""
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")  # utime, stime: fields 14, 15


def _wait(ready: Callable[[], bool], processes: list[NodeProcess], what: str, timeout: float = 120.0) -> None:
    deadline = time.monotonic() + timeout
    while not ready():
        ended = [p for p in processes if not p.running]
        if ended or time.monotonic() > deadline:
            where = ended[0].log_path if ended else processes[-1].log_path
            raise RuntimeError(f"no {what}: see {where}")
        time.sleep(0.1)


def run_foxglove_bench(num_envs: int, steps: int, pairs: int, log: Callable[[str], None] = print,
                       ) -> FoxgloveBenchResult:
    domain_id, lock = reserve_domain_id()
    work = Path(tempfile.mkdtemp(prefix="glocal-bench-foxglove-"))
    logs = work / "logs"
    env = isolated_environment(domain_id, logs)
    namespace_args = namespace_arguments(NAMESPACE)
    rates: dict[str, list[float]] = {variant: [] for variant in VARIANTS}
    bridge_cpu: list[tuple[float, float]] = []
    processes: list[NodeProcess] = []
    try:
        with spinning_node("bench_foxglove", domain_id) as node:
            processes.append(NodeProcess("sim_node", logs, {"num_envs": num_envs, "initial_task": TASK}, env=env,
                                         extra_args=namespace_args))
            processes.append(NodeProcess("learner_node", logs, {"policy_dir": str(work / "policies"), "seed": 0,
                                                                "checkpoint_interval": 10_000_000},
                                         env=env, extra_args=namespace_args))
            goals = LearnerNodeGoals(node, NAMESPACE)
            _wait(goals.ready, processes, "learner_node's Train action")
            timeout = 60 + 10 * (steps + warmup_steps(num_envs))
            log(f"warm-up goal: {goals.steps_per_second('bench-foxglove-warmup', num_envs, steps, timeout):.1f} "
                f"env steps/s (not counted)")
            order = [VARIANTS[(index + 1) // 2 % 2] for index in range(2 * pairs)]  # A B B A A B ...
            for index, variant in enumerate(order):
                bridge = None
                if variant == VARIANTS[1]:
                    port = _free_port()
                    bridge = NodeProcess(FOXGLOVE_NODE, logs, {"port": port, "address": FOXGLOVE_HOST}, env=env,
                                         extra_args=namespace_args)
                    _wait(lambda: _serving(port), [*processes, bridge], "Foxglove server from the bridge")
                try:
                    started, cpu_before = time.monotonic(), bridge and cpu_seconds(bridge.process.pid)
                    rate = goals.steps_per_second(f"bench-foxglove-{index}", num_envs, steps, timeout)
                    if bridge is not None:
                        bridge_cpu.append((cpu_seconds(bridge.process.pid) - cpu_before, time.monotonic() - started))
                finally:
                    if bridge is not None:
                        code = bridge.stop()
                        if code not in (0, None):
                            raise RuntimeError(f"the bridge exited with {code}:\n{bridge.log()[-3000:]}")
                rates[variant].append(rate)
                log(f"round {index + 1}/{len(order)}: {variant} {rate:.1f} env steps/s")
    finally:
        for process in reversed(processes):
            process.stop()
        lock.close()
        shutil.rmtree(work, ignore_errors=True)
    # ABBA: rounds 2k and 2k+1 are one pair, one of each variant.
    measured = [rates[variant][order[:index + 1].count(variant) - 1] for index, variant in enumerate(order)]
    paired = [(measured[k] if order[k] == VARIANTS[1] else measured[k + 1]) /
              (measured[k] if order[k] == VARIANTS[0] else measured[k + 1]) for k in range(0, len(order), 2)]
    blocks = [(paired[k] * paired[k + 1]) ** 0.5 for k in range(0, len(paired) - 1, 2)]
    return FoxgloveBenchResult(num_envs, steps, rates, paired, blocks, bridge_cpu)


def foxglove_bench_report(result: FoxgloveBenchResult, command: str) -> str:
    met = "met" if result.ratio >= TARGET_RATIO else "missed"
    lines = [
        "# bench foxglove: training throughput with an idle Foxglove bridge",
        "",
        f"Command: `{command}`  ",
        f"{time.strftime('%Y-%m-%d %H:%M')}, Python {sys.version.split()[0]}, {os.cpu_count()} CPU cores. "
        f"Load average at the end {os.getloadavg()[0]:.1f} (the machine is shared). "
        f"One Train goal per round, sent to a learner_node process (SAC from `{INITIAL_POLICY}` on {TASK}, "
        f"N = {result.num_envs} envs in a sim_node process with its viewer topics on), timed by its "
        f"TrainingProgress stamps over {result.steps} env steps after {BATCH_SIZE} + {SETTLE_STEPS} + N warm-up "
        f"steps, after one untimed warm-up goal. *bridge idle*: foxglove_bridge_node serving on {FOXGLOVE_HOST} "
        f"(started before the round, "
        f"its port accepting), no client connected. The variants alternate ABBA on the same sim and learner "
        f"processes; the bridge is stopped between its rounds.",
        "",
        "| variant | median env steps/s | rounds (in order) |",
        "| --- | ---: | --- |",
    ]
    lines += [f"| {variant} | {result.median(variant):.1f} | "
              f"{', '.join(f'{rate:.1f}' for rate in result.rates[variant])} |" for variant in VARIANTS]
    lines += [
        "",
        f"Ratio of the medians, bridge idle / without: **{result.ratio:.3f}** (target >= {TARGET_RATIO}: {met}). "
        f"Per ABBA pair: {', '.join(f'{ratio:.3f}' for ratio in result.pairs)} "
        f"(median {statistics.median(result.pairs):.3f}). Per ABBA block (drift cancelled): "
        f"{', '.join(f'{ratio:.3f}' for ratio in result.blocks) or '- (fewer than 2 pairs)'}.",
        "",
        f"The idle bridge process itself took {sum(cpu for cpu, _ in result.bridge_cpu):.2f} CPU-s over "
        f"{sum(wall for _, wall in result.bridge_cpu):.0f} s of its rounds: "
        f"**{100 * result.bridge_core_share:.2f} % of one core** (of {os.cpu_count()}).",
    ]
    return "\n".join(lines) + "\n"

"""``glocal-ros bench backends``: SAC env steps/s of stable-baselines3 (torch) and SBX (JAX), side by side.

How the learner's backend (``learner_node.sac_settings``) was chosen: for
each N, a new SAC model of each library, with the project's settings
(``SAC_KWARGS`` and a ``Network``, the same seed), learns on N grasp envs
with physics in this process (SB3's own ``learn`` on a ``DummyVecEnv`` of
A0 envs; both libraries share SB3's loop, buffers and envs, and differ in
the networks and gradient steps). Both run on the learner's compute
threads (one). The rate is env steps over the time from the first step at
or after the warm-up (updates start after a batch; a few dozen more steps
let SBX compile its update) to the last. Rounds alternate between the
libraries so that load on the shared machine hits both alike.

This compares libraries, everything else equal; ``bench learner`` times
the learner's Train goal itself, through sim_node and learner_node.
"""

from __future__ import annotations

import os
import statistics
import sys
import time
from dataclasses import dataclass
from typing import Sequence

from glocal_app.benches.learner import SETTLE_STEPS, TASK, timed_rate
from learner_node.sac_settings import COMPUTE_THREADS, DEFAULT_NETWORK, SAC_KWARGS, network

#: The libraries compared: stable-baselines3's SAC on torch, and SBX's on JAX (the learner's).
BACKENDS = ("stable-baselines3", "sbx")


@dataclass(frozen=True)
class BackendsBenchRow:
    num_envs: int
    rounds: dict[str, tuple[float, ...]]  # backend -> env steps/s, one per round

    def median(self, backend: str) -> float:
        return statistics.median(self.rounds[backend])

    @property
    def ratio(self) -> float:
        """SBX over stable-baselines3, of the medians."""
        return self.median("sbx") / self.median("stable-baselines3")


def sac_class(backend: str):
    """The SAC class of ``backend``, in a process that computes as the learner's."""
    from learner_node.sac_settings import sac_algorithm

    sbx_sac = sac_algorithm()  # one compute thread for either library
    if backend == "sbx":
        return sbx_sac
    if backend == "stable-baselines3":
        from stable_baselines3 import SAC

        return SAC
    raise ValueError(f"unknown backend {backend!r}: choose from {', '.join(BACKENDS)}")


def learn_steps_per_second(backend: str, num_envs: int, steps: int, network_name: str, seed: int = 0) -> float:
    """A new model of ``backend`` learns ``warmup + steps`` env steps on N A0 envs; env steps/s of the timed part."""
    from stable_baselines3.common.callbacks import BaseCallback
    from stable_baselines3.common.vec_env import DummyVecEnv

    from sim_node.grasp_env import GraspEnv

    chosen = network(network_name)
    envs = DummyVecEnv([lambda: GraspEnv(TASK) for _ in range(num_envs)])
    marks: list[tuple[float, int]] = []

    class Clock(BaseCallback):
        def _on_step(self) -> bool:
            marks.append((time.perf_counter(), self.num_timesteps))
            return True

    try:
        model = sac_class(backend)("MlpPolicy", envs, seed=seed, device="cpu",
                                   **dict(chosen.sac_kwargs(), learning_starts=chosen.batch_size))
        warmup = chosen.batch_size + SETTLE_STEPS + num_envs
        model.learn(warmup + steps, callback=Clock())
    finally:
        envs.close()
    return timed_rate(marks, warmup)


def run_backends_bench(env_counts: Sequence[int], steps: int, rounds: int,
                       network_name: str = DEFAULT_NETWORK) -> list[BackendsBenchRow]:
    rows = []
    for num_envs in env_counts:
        measured: dict[str, list[float]] = {backend: [] for backend in BACKENDS}
        for _ in range(rounds):
            for backend in BACKENDS:
                measured[backend].append(learn_steps_per_second(backend, num_envs, steps, network_name))
        rows.append(BackendsBenchRow(num_envs, {backend: tuple(rates) for backend, rates in measured.items()}))
    return rows


def backends_bench_report(rows: Sequence[BackendsBenchRow], command: str, steps: int, rounds: int,
                          network_name: str = DEFAULT_NETWORK) -> str:
    chosen = network(network_name)
    lines = [
        "# bench backends: SAC env steps/s, stable-baselines3 (torch) vs SBX (JAX)",
        "",
        f"Command: `{command}`  ",
        f"{time.strftime('%Y-%m-%d %H:%M')}, Python {sys.version.split()[0]}, {os.cpu_count()} CPU cores. "
        f"Load average at the end {os.getloadavg()[0]:.1f} (the machine is shared). "
        f"A new SAC model per measurement, network {network_name} ({list(chosen.hidden)}, batch "
        f"{chosen.batch_size}), gamma {SAC_KWARGS['gamma']}, one gradient step per env step, "
        f"{COMPUTE_THREADS} compute thread, learning on N {TASK} grasp envs in this process (SB3's `learn`, "
        f"physics included); {steps} env steps timed after {chosen.batch_size} + {SETTLE_STEPS} + N warm-up "
        f"steps. Median of {rounds} alternating rounds.",
        "",
        "| N envs | stable-baselines3 (torch) | SBX (JAX) | ratio SBX / stable-baselines3 |",
        "| ---: | ---: | ---: | ---: |",
    ]
    lines += [f"| {row.num_envs} | {row.median('stable-baselines3'):.1f} | {row.median('sbx'):.1f} "
              f"| {row.ratio:.2f} |" for row in rows]
    lines += ["", "Every round, in order (env steps/s):", ""]
    for row in rows:
        paired = ", ".join(f"{sbx / torch:.2f}"
                           for torch, sbx in zip(row.rounds["stable-baselines3"], row.rounds["sbx"]))
        lines.append(f"- N={row.num_envs}: " + "; ".join(
            f"{backend} " + ", ".join(f"{rate:.1f}" for rate in row.rounds[backend]) for backend in BACKENDS)
            + f" (ratios in the same round: {paired})")
    return "\n".join(lines) + "\n"

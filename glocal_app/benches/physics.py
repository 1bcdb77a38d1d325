"""``glocal-ros bench physics``: where one control step of the env floor goes, profiled.

The env floor (``bench sim``'s in-process rate, ``bench learner``'s ``env
floor``) is ``GraspEnv.step``: an arm command (one damped least-squares IK
step and motor targets), ``SUBSTEPS`` PyBullet steps of the Panda, the table
and the object, and an observation; an episode's end adds a reset, whose
object settles for a number of physics steps. For each task, one env in this
process takes uniform random actions and resets when an episode ends:

- **the profile**: cProfile over ``steps`` control steps, its time split by
  the project's functions (cProfile does not see pybullet's C functions
  behind ``functools.partial``, so each one's time is its Python caller's):
  physics in steps, the arm command, the observation, the rest of a step,
  settling in resets, the rest of a reset. cProfile's own cost lands on the
  Python parts, so the shares are an upper bound for them and the rates come
  from the runs below, which it does not time;
- **one physics step**, in µs: in the profiled steps (the arm moving, the
  fingers opening, closing and touching); ``stepSimulation`` alone with the
  object at rest on the table and the robot holding its home pose; and with
  the object removed (the Panda's dynamics, its motors and the finger gear);
- **what is free and what is not**, env steps/s in alternating rounds (medians):
  the env as it is (``sim_node.physics_client.PhysicsClient``); pybullet_utils'
  ``BulletClient``, which binds the client id at every call (the same
  simulation to the bit); and the solver at fewer iterations than its 50,
  which changes the simulation and so every measured grasp outcome and
  policy: reported, not taken.
"""

from __future__ import annotations

import cProfile
import os
import pstats
import statistics
import sys
import time
from dataclasses import dataclass
from typing import Callable, Sequence

import numpy as np

#: The solver iteration counts the bench tries beside the sim's own (PyBullet's default, 50).
SOLVER_ITERATIONS = (50, 30, 20, 10)
SIM_SOLVER_ITERATIONS = 50
#: (row label, the function's file suffix, its name, the caller's file suffix and name or None: from any caller)
_PARTS = (
    ("physics in steps", "grasp_world.py", "step", ("grasp_env.py", "step")),
    ("arm command (IK, motor targets)", "panda_robot.py", "command", None),
    ("observation (state, contacts)", "grasp_env.py", "_observe", ("grasp_env.py", "step")),
    ("settling in resets", "grasp_world.py", "step", ("grasp_world.py", "reset")),
)


@dataclass(frozen=True)
class PhysicsProfile:
    task: str
    steps: int
    parts: dict[str, float]  # row label -> seconds per control step, in the profile
    substep_us: dict[str, float]  # state -> µs per physics step
    rates: dict[str, float]  # variant -> median env steps/s, not profiled


def _cumulative(stats: dict, file: str, name: str, caller: tuple[str, str] | None) -> float:
    for (path, _, function), (_, _, _, cumulative, callers) in stats.items():
        if path.endswith(file) and function == name:
            if caller is None:
                return cumulative
            return sum(entry[3] for (caller_path, _, caller_name), entry in callers.items()
                       if caller_path.endswith(caller[0]) and caller_name == caller[1])
    return 0.0


def _run(env, steps: int, rng: np.random.Generator) -> None:
    for action in rng.uniform(-1.0, 1.0, size=(steps, 5)).astype(np.float32):
        _, _, terminated, truncated, _ = env.step(action)
        if terminated or truncated:
            env.reset()


def _profile(env, steps: int) -> dict[str, float]:
    profiler = cProfile.Profile()
    profiler.enable()
    _run(env, steps, np.random.default_rng(1))
    profiler.disable()
    stats = pstats.Stats(profiler).stats
    parts = {label: _cumulative(stats, file, name, caller) / steps for label, file, name, caller in _PARTS}
    step_total = _cumulative(stats, "grasp_env.py", "step", None) / steps
    reset_total = _cumulative(stats, "grasp_env.py", "reset", None) / steps
    parts["rest of a step (clips, TCP pose)"] = step_total - sum(parts[label] for label, *_ in _PARTS[:3])
    parts["rest of a reset (state restore)"] = reset_total - parts["settling in resets"]
    return parts


def _substep_us(client, repeats: int = 2000) -> float:
    start = time.perf_counter()
    for _ in range(repeats):
        client.stepSimulation()
    return (time.perf_counter() - start) / repeats * 1e6


def _rate(env, steps: int) -> float:
    rng = np.random.default_rng(2)
    start = time.perf_counter()
    _run(env, steps, rng)
    return steps / (time.perf_counter() - start)


def run_physics_bench(tasks: Sequence[str], steps: int, rounds: int,
                      log: Callable[[str], None] = print) -> list[PhysicsProfile]:
    import sim_node.grasp_env as grasp_env
    from glocal_ros.spaces import SUBSTEPS
    from pybullet_utils.bullet_client import BulletClient

    results = []
    for task in tasks:
        env = grasp_env.GraspEnv(task)
        original = grasp_env.PhysicsClient
        grasp_env.PhysicsClient = BulletClient
        try:
            bound_per_call = grasp_env.GraspEnv(task)
        finally:
            grasp_env.PhysicsClient = original
        try:
            for each in (env, bound_per_call):
                each.reset(seed=0)
                _run(each, 50, np.random.default_rng(0))  # warm
            parts = _profile(env, steps)
            env.reset(seed=0)
            client = env.world.client
            substeps = {"in the profiled steps": parts["physics in steps"] / SUBSTEPS * 1e6,
                        "robot at home, object at rest": _substep_us(client)}
            variants: dict[str, list[float]] = {}
            for _ in range(rounds):
                variants.setdefault("as it is", []).append(_rate(env, steps))
                variants.setdefault("BulletClient (bound at every call)", []).append(_rate(bound_per_call, steps))
                for iterations in SOLVER_ITERATIONS[1:]:
                    client.setPhysicsEngineParameter(numSolverIterations=iterations)
                    variants.setdefault(f"{iterations} solver iterations", []).append(_rate(env, steps))
                client.setPhysicsEngineParameter(numSolverIterations=SIM_SOLVER_ITERATIONS)
            env.reset(seed=0)
            client.removeBody(env.world.object.body)
            substeps["robot at home, no object"] = _substep_us(client)
            rates = {name: statistics.median(values) for name, values in variants.items()}
            results.append(PhysicsProfile(task, steps, parts, substeps, rates))
            log(f"{task}: {1e3 * sum(parts.values()):.2f} ms per control step profiled, "
                + ", ".join(f"{name} {rate:.0f}" for name, rate in rates.items()) + " env steps/s")
        finally:
            env.close()
            bound_per_call.close()
    return results


def physics_bench_report(results: Sequence[PhysicsProfile], command: str, rounds: int) -> str:
    from glocal_ros.spaces import SUBSTEPS

    tasks = [r.task for r in results]
    lines = [
        "# bench physics: where one control step of the env floor goes",
        "",
        f"Command: `{command}`  ",
        f"{time.strftime('%Y-%m-%d %H:%M')}, Python {sys.version.split()[0]}, {os.cpu_count()} CPU cores, load "
        f"average at the end {os.getloadavg()[0]:.1f} (the machine is shared). One GraspEnv in one process per "
        f"task, uniform random actions, a reset at each episode's end; a control step is {SUBSTEPS} physics "
        f"steps. The profile: cProfile over {results[0].steps if results else 0} control steps, each part's "
        "time per control step (cProfile's own cost lands on the Python parts: their shares are upper "
        f"bounds). The rates: not profiled, medians of {rounds} alternating rounds.",
        "",
        "## The profile (ms per control step, and share)",
        "",
        "| part | " + " | ".join(tasks) + " |",
        "| --- | " + " | ".join("---:" for _ in tasks) + " |",
    ]
    for label in results[0].parts if results else ():
        cells = [f"{1e3 * r.parts[label]:.3f} ({r.parts[label] / sum(r.parts.values()):.0%})" for r in results]
        lines.append(f"| {label} | " + " | ".join(cells) + " |")
    lines.append("| all | " + " | ".join(f"{1e3 * sum(r.parts.values()):.3f}" for r in results) + " |")
    lines += ["", "## One physics step (µs)", "",
              "| state | " + " | ".join(tasks) + " |", "| --- | " + " | ".join("---:" for _ in tasks) + " |"]
    for state in results[0].substep_us if results else ():
        lines.append(f"| {state} | " + " | ".join(f"{r.substep_us[state]:.1f}" for r in results) + " |")
    lines += ["", "## Env steps/s, side by side", "",
              "| variant | " + " | ".join(tasks) + " | ratio to as it is (median over tasks) | changes the simulation |",
              "| --- | " + " | ".join("---:" for _ in tasks) + " | ---: | --- |"]
    for variant in results[0].rates if results else ():
        ratio = statistics.median(r.rates[variant] / r.rates["as it is"] for r in results)
        changes = "yes: not taken" if "solver" in variant else "no"
        lines.append(f"| {variant} | " + " | ".join(f"{r.rates[variant]:.0f}" for r in results)
                     + f" | {ratio:.2f} | {changes} |")
    return "\n".join(lines) + "\n"

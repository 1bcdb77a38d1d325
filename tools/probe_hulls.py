"""Probe: do finer collision hulls make the committed objects harder to grasp, and what do they cost?

Rebuilds every committed object's collision hulls with a finer V-HACD
(``--resolution``, ``--concavity``, ``--depth``, ``--max-hulls``; the
voxel resolution is what raises the hull count) into a copy of the objects directory (same
URDFs, visual meshes and mass properties), then grasps both sets with the
same seeded perturbed grasps (``sim_node.scripted_grasp.perturbed_success_rate``)
and prints, per set, the Spearman correlation of the letter with the
success rate, the row means, and the env steps per second of those
contact-rich episodes, measured in alternating order.

    .venv/bin/python tools/probe_hulls.py --episodes 40 --rounds 1 --out build/hulls-fine
"""

from __future__ import annotations

import argparse
import shutil
import sys
import time
from pathlib import Path

import numpy as np


def finer_hulls(objects: Path, out: Path, vhacd) -> dict[str, int]:
    """A copy of ``objects`` whose collision hulls are rebuilt from each object's solid; hull counts."""
    from glocal_ros.objects import GeneratorConfig, ObjectSetMetadata
    from glocal_ros.objects.physics import convex_decomposition
    from glocal_ros.objects.pipeline import _candidate_rngs, _measure, candidate_mesh

    metadata = ObjectSetMetadata.load(objects)
    config = GeneratorConfig()
    shutil.copytree(objects, out, dirs_exist_ok=True)
    counts = {}
    for task, obj in metadata.objects.items():
        _, mesh = candidate_mesh(obj.seed, obj.candidate_index, config)
        solid = _measure(mesh, _candidate_rngs(obj.seed, obj.candidate_index)[1], config).solid
        counts[task], _ = convex_decomposition(solid, out / task / "collision.obj", vhacd)
        print(f"{task}: {obj.hull_count} -> {counts[task]} hulls", flush=True)
    return counts


def grasp(objects: Path, tasks: list[str], episodes: int) -> tuple[dict[str, float], float]:
    """Perturbed-grasp success per task (``assets check``'s seeds) and env steps/s over all episodes."""
    from sim_node.grasp_env import GraspEnv
    from sim_node.scripted_grasp import perturbed_success_rate

    env = GraspEnv(tasks[0], objects_dir=objects)
    steps, started = 0, time.perf_counter()
    original_step = env.step

    def counted_step(action):
        nonlocal steps
        steps += 1
        return original_step(action)

    env.step = counted_step
    try:
        rates = {task: perturbed_success_rate(env, task, episodes, seed=offset)
                 for offset, task in enumerate(tasks)}
    finally:
        env.close()
    return rates, steps / (time.perf_counter() - started)


def summary(name: str, rates: dict[str, float], speed: float) -> str:
    from scipy.stats import spearmanr

    rho = spearmanr(["ABCDEFG".index(task[0]) for task in rates], list(rates.values()))[0]
    rows = " ".join(f"{letter} {np.mean([r for t, r in rates.items() if t[0] == letter]):.0%}"
                    for letter in "ABCDEFG")
    return f"{name}: Spearman {rho:.2f}; rows {rows}; {speed:.0f} env steps/s"


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--max-hulls", type=int, default=64)
    parser.add_argument("--depth", type=int, default=8)
    parser.add_argument("--concavity", type=float, default=0.0001, help="V-HACD's; the generator's is 0.0025")
    parser.add_argument("--resolution", type=int, default=1_000_000, help="V-HACD's voxels; the generator's is 200k")
    parser.add_argument("--episodes", type=int, default=40)
    parser.add_argument("--rounds", type=int, default=2, help="alternating speed rounds (success from the first)")
    parser.add_argument("--out", type=Path, default=Path("build/hulls"))
    args = parser.parse_args()

    from glocal_ros.objects.physics import VhacdConfig
    from glocal_ros.paths import objects_dir
    from glocal_ros.tasks import ALL_TASKS

    committed = objects_dir()
    vhacd = VhacdConfig(resolution=args.resolution, depth=args.depth, concavity=args.concavity,
                        max_hulls=args.max_hulls)
    counts = finer_hulls(committed, args.out, vhacd)
    print(f"hulls: mean {np.mean(list(counts.values())):.1f}, max {max(counts.values())}")
    tasks = list(ALL_TASKS)
    results: dict[str, list] = {"committed": [], "finer": []}
    for _ in range(args.rounds):
        for name, objects in (("committed", committed), ("finer", args.out)):
            results[name].append(grasp(objects, tasks, args.episodes))
    for name, runs in results.items():
        print(summary(name, runs[0][0], float(np.median([speed for _, speed in runs]))))
    return 0


if __name__ == "__main__":
    sys.exit(main())

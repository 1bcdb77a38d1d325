"""Probe: do physically hard shapes cost the learner real effort, where the generated blobs do not?

Copies the committed object set and replaces row G by seven hand-made primitives of the kinds issue 31
names as hard for a top-down parallel gripper (friction 0.5 and density 600 kg/m^3, as the generated
objects; V-HACD is not needed: each part is convex):

G0  flat box 7 x 10 x 2.4 cm (the environment notes' probe: a box policy grasped it 3 times in 30)
G1  flat plate 7 x 12 x 1.2 cm: gripped only across its 7 cm, fingertips at the table
G2  cone, radius 3.5 cm, 6 cm tall: faces 30 degrees from vertical, outside the friction cone at mu 0.5
G3  wedge 7 cm wide, 6 deep, 4 high: faces 41 degrees from vertical, a ridge on top
G4  cylinder of radius 1.2 cm, 14 cm tall, standing: it topples when touched
G5  sphere of radius 3.6 cm: it rolls
G6  hammer: a 2 cm handle, 11 cm long, and a 9 cm head; the only gripper-width feature is away
    from the centre of mass

``--measure`` then prints, per replaced object, what the asset commands measure (scripted grasp
success over 20 episodes, perturbed over 40, the share of lifting poses and the best pose's success)
and the shipped prior's score before a goal's first step (20 episodes, as ``learner/evaluate``
scores it). ``glocal-ros bench cost --objects-dir OUT`` maps what learning them costs
(``bench/results/cost-hard-primitives.md``). Not project code: the object set stays generated;
this measures whether its shape space should widen.

    python tools/probe_hard_primitives.py /tmp/hard-objects --measure
"""

from __future__ import annotations

import argparse
import shutil
from pathlib import Path

import numpy as np
import trimesh

from glocal_ros.objects.physics import FrictionConfig, MassConfig, mass_properties, write_urdf
from glocal_ros.paths import objects_dir


def _box(size: tuple[float, float, float], centre: tuple[float, float, float] = (0.0, 0.0, 0.0)) -> trimesh.Trimesh:
    box = trimesh.creation.box(size)
    box.apply_translation(centre)
    return box


def _wedge(width: float, depth: float, height: float) -> trimesh.Trimesh:
    """A triangular prism: its ridge along y, ``height`` above the middle of its base."""
    half_w, half_d = width / 2, depth / 2
    corners = [(-half_w, -half_d, 0), (half_w, -half_d, 0), (0, -half_d, height),
               (-half_w, half_d, 0), (half_w, half_d, 0), (0, half_d, height)]
    return trimesh.convex.convex_hull(np.array(corners))


#: task: (what it is, its convex parts)
SHAPES: dict[str, tuple[str, list[trimesh.Trimesh]]] = {
    "G0": ("flat box 7 x 10 x 2.4 cm", [_box((0.07, 0.10, 0.024))]),
    "G1": ("flat plate 7 x 12 x 1.2 cm", [_box((0.07, 0.12, 0.012))]),
    "G2": ("cone r 3.5 cm, 6 cm tall", [trimesh.creation.cone(radius=0.035, height=0.06, sections=32)]),
    "G3": ("wedge 7 x 6 x 4 cm", [_wedge(0.07, 0.06, 0.04)]),
    "G4": ("cylinder r 1.2 cm, 14 cm tall", [trimesh.creation.cylinder(radius=0.012, height=0.14)]),
    "G5": ("sphere r 3.6 cm", [trimesh.creation.icosphere(subdivisions=3, radius=0.036)]),
    "G6": ("hammer: 2 cm handle, 9 cm head", [_box((0.02, 0.11, 0.025), (0.0, 0.055, 0.0125)),
                                              _box((0.09, 0.035, 0.035), (0.0, -0.0175, 0.0175))]),
}


def write_parts(path: Path, parts: list[trimesh.Trimesh]) -> None:
    """An OBJ with one object per convex part: PyBullet makes a compound of their hulls, as of V-HACD's output."""
    lines, offset = [], 0
    for index, part in enumerate(parts):
        lines.append(f"o part{index}")
        lines += [f"v {x:.6f} {y:.6f} {z:.6f}" for x, y, z in part.vertices]
        lines += [f"f {a + 1 + offset} {b + 1 + offset} {c + 1 + offset}" for a, b, c in part.faces]
        offset += len(part.vertices)
    path.write_text("\n".join(lines) + "\n")


def measure(out: Path, seed: int = 0) -> None:
    """The asset commands' grasp measures and the prior's step-0 score of the replaced objects, as a table."""
    import tempfile

    from learner_node.evaluation import evaluate
    from learner_node.policies import PolicyRegistry
    from learner_node.policy_store import PolicyStore
    from learner_node.profiles import DEFAULT_PROFILE, PROFILES
    from learner_node.training import Trainer
    from sim_node.batch import BatchedEnvs
    from sim_node.grasp_env import GraspEnv
    from sim_node.lifting_poses import lifting_pose_trial
    from sim_node.scripted_grasp import perturbed_success_rate, scripted_success_rate

    tasks = list(SHAPES)
    env = GraspEnv(tasks[0], objects_dir=out)
    grasps = {task: (scripted_success_rate(env, task, 20, seed), perturbed_success_rate(env, task, 40, seed))
              for task in tasks}
    env.close()
    lifting = {task: lifting_pose_trial(out, task, seed) for task in tasks}
    profile = PROFILES[DEFAULT_PROFILE]
    work = Path(tempfile.mkdtemp(prefix="probe-hard-"))
    envs = BatchedEnvs(lambda i: GraspEnv(tasks[0], objects_dir=out), 2, tasks[0])
    try:
        trainer = Trainer(envs, PolicyRegistry(PolicyStore(work / "store"), [PolicyStore(profile.shipped_priors())]),
                          work / "checkpoints", profile=profile)
        prior = {score.task: score.successes
                 for score in evaluate(envs, trainer.evaluation_policy("prior", tasks), tasks, 20, seed=seed + 1)}
    finally:
        envs.close()
    print("| object | shape | scripted | perturbed | lifting poses | best pose | prior, step 0 |")
    print("| --- | --- | ---: | ---: | ---: | ---: | ---: |")
    for task, (what, _) in SHAPES.items():
        (scripted, perturbed), (share, best) = grasps[task], lifting[task]
        print(f"| {task} | {what} | {scripted:.0%} | {perturbed:.0%} | {share:.0%} | {best:.0%} | {prior[task]} / 20 |")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("out", type=Path, help="the object set to write (replaced if it exists)")
    parser.add_argument("--measure", action="store_true", help="then measure the replaced objects")
    args = parser.parse_args()
    out = args.out
    if out.exists():
        shutil.rmtree(out)
    shutil.copytree(objects_dir(), out)
    for task, (what, parts) in SHAPES.items():
        whole = trimesh.util.concatenate(parts)
        centre = whole.center_mass  # the link frame is the centre of mass (write_urdf)
        for part in [whole, *parts]:
            part.apply_translation(-centre)
        folder = out / task
        shutil.rmtree(folder)
        folder.mkdir()
        props = mass_properties(whole, MassConfig())
        whole.export(folder / "visual.obj")
        write_parts(folder / "collision.obj", parts)
        write_urdf(folder / "model.urdf", task, props, FrictionConfig())
        print(f"{task}: {what}, {props.mass * 1000:.0f} g, extents {np.round(whole.extents * 100, 1)} cm")
    if args.measure:
        measure(out)


if __name__ == "__main__":
    main()

"""The scripted grasp controller against real PyBullet, on small primitive objects."""

from __future__ import annotations

from pathlib import Path

import gymnasium as gym
import pytest

from sim_node.grasp_env import GraspEnv
from sim_node.scripted_grasp import Phase, ScriptedGraspPolicy, scripted_success_rate

BOX_TASK, CYLINDER_TASK = "A0", "B3"


def write_object(objects_dir: Path, task: str, geometry: str, inertia: tuple[float, float, float]) -> None:
    ixx, iyy, izz = inertia
    (objects_dir / task).mkdir(parents=True, exist_ok=True)
    (objects_dir / task / "model.urdf").write_text(
        f"""<?xml version="1.0"?>
<robot name="{task}">
  <link name="base">
    <contact><lateral_friction value="1.0"/></contact>
    <inertial>
      <mass value="0.1"/>
      <inertia ixx="{ixx}" ixy="0" ixz="0" iyy="{iyy}" iyz="0" izz="{izz}"/>
    </inertial>
    <visual><geometry>{geometry}</geometry></visual>
    <collision><geometry>{geometry}</geometry></collision>
  </link>
</robot>
"""
    )


@pytest.fixture(scope="module")
def env(tmp_path_factory: pytest.TempPathFactory):
    """One env holding the probe's 4 x 6 x 5 cm box (A0) and a 2.8 cm-radius cylinder (B3)."""
    objects_dir = tmp_path_factory.mktemp("objects")
    x, y, z = 0.04, 0.06, 0.05
    box_inertia = (0.1 * (y * y + z * z) / 12, 0.1 * (x * x + z * z) / 12, 0.1 * (x * x + y * y) / 12)
    write_object(objects_dir, BOX_TASK, f'<box size="{x} {y} {z}"/>', box_inertia)
    r, h = 0.028, 0.06
    side = 0.1 * (3 * r * r + h * h) / 12
    cylinder = f'<cylinder radius="{r}" length="{h}"/>'
    write_object(objects_dir, CYLINDER_TASK, cylinder, (side, side, 0.1 * r * r / 2))
    grasp_env = GraspEnv(objects_dir=objects_dir)
    yield grasp_env
    grasp_env.close()


@pytest.mark.parametrize("task", [BOX_TASK, CYLINDER_TASK])
def test_scripted_policy_lifts_the_object(env: GraspEnv, task: str) -> None:
    assert scripted_success_rate(env, task, episodes=10, seed=0) >= 0.8


def test_successful_episode_terminates_with_is_success(env: GraspEnv) -> None:
    wrapped = gym.wrappers.RecordEpisodeStatistics(env)
    policy = ScriptedGraspPolicy()
    wrapped.reset(seed=3, options={"task": BOX_TASK})
    flags = []
    while not flags or not (flags[-1][0] or flags[-1][1]):
        _, reward, terminated, truncated, info = wrapped.step(policy.act(wrapped))
        assert reward == -1.0
        flags.append((terminated, truncated, info["is_success"]))
    assert flags[-1] == (True, False, True)
    assert not any(success for _, _, success in flags[:-1])
    assert env.grasp_state().object_lift > env.config.success_height
    assert env.grasp_state().left_contact and env.grasp_state().right_contact
    assert len(flags) < env.config.max_steps


def test_policy_starts_over_in_each_episode(env: GraspEnv) -> None:
    policy = ScriptedGraspPolicy()
    env.reset(seed=0, options={"task": BOX_TASK})
    while True:
        _, _, terminated, truncated, _ = env.step(policy.act(env))
        if terminated or truncated:
            break
    assert policy.phase is Phase.LIFT
    env.reset()
    action = policy.act(env)
    assert policy.phase is Phase.APPROACH
    assert action[0] == -1.0 and env.action_space.contains(action)


def test_success_rate_needs_episodes(env: GraspEnv) -> None:
    with pytest.raises(ValueError, match="episodes"):
        scripted_success_rate(env, BOX_TASK, episodes=0)

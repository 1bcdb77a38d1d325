"""GraspEnv against real PyBullet, with small primitive objects written per test session."""

from __future__ import annotations

import math
import re
import warnings
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

from glocal_ros.tasks import NUM_TASKS, UnknownTaskError, task_index
from primitive_objects import BOX_TASK, CYLINDER_TASK, write_object, write_test_objects
from sim_node.grasp_env import (
    OBS_FINGER_CONTACTS,
    OBS_GRIPPER_OPENING,
    OBS_GRIPPER_POSITION,
    OBS_GRIPPER_YAW,
    OBS_OBJECT_LIFT,
    OBS_OBJECT_RELATIVE_POSITION,
    OBS_OBJECT_RELATIVE_YAW,
    OBS_TASK,
    GraspEnv,
    GraspEnvConfig,
    GraspState,
)
from sim_node.panda_robot import JOINT_NAMES, yaw_of
from sim_node.scripted_grasp import GraspError, ScriptedGraspPolicy



@pytest.fixture(scope="module")
def objects_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return write_test_objects(tmp_path_factory.mktemp("objects"))


@pytest.fixture
def make_env(objects_dir: Path):
    envs: list[GraspEnv] = []

    def make(**kwargs) -> GraspEnv:
        env = GraspEnv(objects_dir=objects_dir, **kwargs)
        envs.append(env)
        return env

    yield make
    for env in envs:
        env.close()


def rollout(env: GraspEnv, seed: int, actions: np.ndarray, task: str = BOX_TASK) -> tuple[np.ndarray, list]:
    """Observations and (reward, terminated, truncated, is_success) of one seeded episode."""
    observations = [env.reset(seed=seed, options={"task": task})[0]]
    outcomes = []
    for action in actions:
        observation, reward, terminated, truncated, info = env.step(action)
        observations.append(observation)
        outcomes.append((reward, terminated, truncated, info["is_success"]))
        if terminated or truncated:
            break
    return np.array(observations), outcomes


def contact_rich_actions() -> np.ndarray:
    """Random moves, then a descent onto the object, a close and a lift."""
    actions = np.random.default_rng(5).uniform(-1.0, 1.0, size=(50, 5))
    actions[10:20, 4] = -1.0
    actions[20:30, 0] = 1.0
    actions[30:, 4] = 1.0
    return actions


def test_env_checker_passes(make_env) -> None:
    # The checker's one expected warning: without a registered spec it cannot
    # re-make the env in the other render modes (one of them opens a GUI).
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        check_env(make_env(render_mode="rgb_array"))
    messages = [str(warning.message) for warning in caught]
    assert all("not having a spec" in message for message in messages), messages


def test_observations_stay_in_the_declared_space(make_env) -> None:
    env = make_env()
    env.action_space.seed(0)
    observation, _ = env.reset(seed=0)
    for _ in range(60):
        assert observation.shape == (63,) and observation.dtype == np.float32
        assert env.observation_space.contains(observation)
        observation, *_ = env.step(env.action_space.sample())


def test_first_observation_describes_the_home_pose(make_env) -> None:
    env = make_env()
    observation, info = env.reset(seed=1)
    assert info == {"is_success": False, "task": BOX_TASK}
    np.testing.assert_allclose(observation[OBS_GRIPPER_POSITION], (0.0, 0.0, 0.15), atol=0.005)
    assert observation[OBS_GRIPPER_OPENING] == pytest.approx(0.08, abs=1e-3)
    assert observation[OBS_OBJECT_LIFT] == pytest.approx(0.0, abs=1e-6)
    assert observation[OBS_FINGER_CONTACTS].tolist() == [0.0, 0.0]
    position, _ = env.object_pose()
    tcp = observation[OBS_GRIPPER_POSITION] + (0.5, 0.0, 0.0)
    np.testing.assert_allclose(observation[OBS_OBJECT_RELATIVE_POSITION], position - tcp, atol=1e-6)
    assert position[2] == pytest.approx(0.025, abs=0.002)


def test_the_object_yaw_shows_a_half_turn(make_env) -> None:
    """The box is not round: turned by half a turn it is another grasp problem, and the policy sees it."""
    env = make_env()
    turns = []
    for seed in range(6):
        observation, _ = env.reset(seed=seed)
        gripper_yaw = math.atan2(*observation[OBS_GRIPPER_YAW])
        relative_yaw = yaw_of(tuple(env.object_pose()[1])) - gripper_yaw
        np.testing.assert_allclose(observation[OBS_OBJECT_RELATIVE_YAW],
                                   (math.sin(relative_yaw), math.cos(relative_yaw)), atol=1e-5)
        turns.append(math.atan2(*observation[OBS_OBJECT_RELATIVE_YAW]))
    # Random yaws over six resets: the feature reaches both halves of the turn.
    assert max(turns) - min(turns) > math.pi


def test_one_hot_follows_the_task(make_env) -> None:
    env = make_env()
    observation, _ = env.reset(seed=0)
    assert observation[OBS_TASK].sum() == 1.0 and observation[task_index(BOX_TASK)] == 1.0
    observation, _ = env.reset(options={"task": CYLINDER_TASK})
    assert env.task == CYLINDER_TASK
    assert observation[OBS_TASK].sum() == 1.0 and observation[task_index(CYLINDER_TASK)] == 1.0
    assert len(observation[OBS_TASK]) == NUM_TASKS


def test_a_novel_object_loads_from_its_name_and_shows_its_proxys_bit(make_env, objects_dir: Path) -> None:
    write_object(objects_dir, "crate", '<box size="0.04 0.05 0.06"/>', (5e-5, 4.3e-5, 3.4e-5))
    env = make_env(task="crate@C4")
    under_c4, info = env.reset(seed=3)
    assert info["task"] == "crate@C4" and env.world.object.urdf == objects_dir / "crate" / "model.urdf"
    assert under_c4[OBS_TASK].sum() == 1.0 and under_c4[task_index("C4")] == 1.0
    under_a0, _ = env.reset(seed=3, options={"task": "crate@A0"})
    assert under_a0[task_index("A0")] == 1.0
    np.testing.assert_array_equal(under_a0[OBS_TASK.stop:], under_c4[OBS_TASK.stop:])  # only the bit differs


def test_task_switch_persists_over_later_resets(make_env) -> None:
    env = make_env()
    env.reset(seed=0, options={"task": CYLINDER_TASK})
    _, info = env.reset()
    assert env.task == info["task"] == CYLINDER_TASK
    _, info = env.reset(options={"task": BOX_TASK})
    assert env.task == info["task"] == BOX_TASK


def test_reward_is_minus_one_until_truncation_at_max_steps(make_env) -> None:
    env = make_env(config=GraspEnvConfig(max_steps=7))
    env.reset(seed=0)
    away_and_up = np.array((-1.0, 0.5, 1.0, 1.0, 1.0), dtype=np.float32)
    for step in range(1, 8):
        _, reward, terminated, truncated, info = env.step(away_and_up)
        assert reward == -1.0 and not terminated and info["is_success"] is False
        assert truncated == (step == 7)
        assert env.grasp_state().step == step


def test_seeded_episodes_repeat_exactly_whatever_came_before(make_env) -> None:
    actions = contact_rich_actions()
    fresh = make_env()
    expected_obs, expected_outcomes = rollout(fresh, 7, actions)

    used = make_env()
    rollout(used, 1, actions)
    rollout(used, 2, np.random.default_rng(3).uniform(-1.0, 1.0, size=(50, 5)), task=CYLINDER_TASK)
    obs, outcomes = rollout(used, 7, actions)

    np.testing.assert_array_equal(obs, expected_obs)
    assert outcomes == expected_outcomes


def test_the_env_client_binds_each_function_once_and_simulates_as_bullet_client_does(make_env, monkeypatch):
    import sim_node.grasp_env as grasp_env
    from pybullet_utils.bullet_client import BulletClient

    env = make_env()
    expected_obs, expected_outcomes = rollout(env, 7, contact_rich_actions())
    assert "stepSimulation" in vars(env.world.client)  # bound once, found on the instance from then on
    monkeypatch.setattr(grasp_env, "PhysicsClient", BulletClient)
    obs, outcomes = rollout(make_env(), 7, contact_rich_actions())
    np.testing.assert_array_equal(obs, expected_obs)
    assert outcomes == expected_outcomes


def test_seeds_vary_the_spawn_pose(make_env) -> None:
    env = make_env()
    positions, yaws = [], []
    for seed in range(5):
        env.reset(seed=seed)
        position, orientation = env.object_pose()
        positions.append(position[:2])
        yaws.append(2 * math.atan2(orientation[2], orientation[3]))
    assert np.ptp(np.array(positions), axis=0).min() > 0.01
    assert np.ptp(yaws) > 0.5
    assert np.all(np.abs(np.array(positions) - (0.5, 0.0)) <= 0.05 + 1e-3)


def test_unknown_task_raises(make_env) -> None:
    with pytest.raises(UnknownTaskError):
        make_env(task="Z9")
    env = make_env()
    env.reset(seed=0)
    with pytest.raises(UnknownTaskError):
        env.reset(options={"task": "H0"})


def test_missing_urdf_names_the_path(make_env, objects_dir: Path) -> None:
    missing = re.escape(str(objects_dir / "C4" / "model.urdf"))
    with pytest.raises(FileNotFoundError, match=missing):
        make_env(task="C4")
    env = make_env()
    with pytest.raises(FileNotFoundError, match=missing):
        env.reset(options={"task": "C4"})
    env.reset(seed=0)
    assert env.task == BOX_TASK


def test_unknown_reset_option_raises(make_env) -> None:
    with pytest.raises(ValueError, match="colour"):
        make_env().reset(options={"colour": "red"})


def test_out_of_range_actions_are_clipped(make_env) -> None:
    env = make_env()
    action = np.array((0.3, 0.7, -0.4, 0.9, -0.6), dtype=np.float32)
    scaled = action / np.abs(action).min() * 10.0
    env.reset(seed=4)
    clipped_obs, *_ = env.step(np.clip(scaled, -1.0, 1.0))
    env.reset(seed=4)
    scaled_obs, *_ = env.step(scaled)
    env.reset(seed=4)
    infinite_obs, *_ = env.step(np.sign(scaled) * np.inf)
    np.testing.assert_array_equal(scaled_obs, clipped_obs)
    np.testing.assert_array_equal(infinite_obs, clipped_obs)


def test_malformed_actions_raise(make_env) -> None:
    env = make_env()
    with pytest.raises(RuntimeError, match="reset"):
        env.step(np.zeros(5))
    env.reset(seed=0)
    with pytest.raises(ValueError, match="NaN"):
        env.step(np.array((0.0, np.nan, 0.0, 0.0, 0.0)))
    with pytest.raises(ValueError, match="shape"):
        env.step(np.zeros(4))


def test_workspace_keeps_the_gripper_above_the_table(make_env) -> None:
    config = GraspEnvConfig(max_steps=30)
    env = make_env(config=config)
    observation, _ = env.reset(seed=0)
    for _ in range(10):
        observation, *_ = env.step(np.array((-1.0, 0.0, 1.0, 1.0, 0.0)))
    for _ in range(10):
        observation, *_ = env.step(np.array((-1.0, 0.0, 1.0, 1.0, -1.0)))
    x, y, z = observation[OBS_GRIPPER_POSITION]
    assert x == pytest.approx(config.workspace_half_width, abs=0.005)
    assert y == pytest.approx(config.workspace_half_width, abs=0.005)
    assert z == pytest.approx(config.min_tcp_height, abs=0.003)


def test_mesh_object_with_off_diagonal_inertia_spawns_link_upright(tmp_path: Path) -> None:
    # PyBullet turns such a body's frame to the inertia's principal axes; the
    # env must still place, observe and report the URDF link frame.
    corners = [(x, y, z) for x in (-0.02, 0.02) for y in (-0.03, 0.03) for z in (-0.025, 0.025)]
    faces = ((1, 2, 4, 3), (5, 7, 8, 6), (1, 5, 6, 2), (3, 4, 8, 7), (1, 3, 7, 5), (2, 6, 8, 4))
    (tmp_path / "A0").mkdir()
    (tmp_path / "A0" / "hull.obj").write_text(
        "".join(f"v {x} {y} {z}\n" for x, y, z in corners)
        + "".join(f"f {a} {b} {c} {d}\n" for a, b, c, d in faces)
    )
    write_object(tmp_path, "A0", '<mesh filename="hull.obj" scale="1 1 1"/>', (3e-5, 2e-5, 2.5e-5))
    urdf = tmp_path / "A0" / "model.urdf"
    urdf.write_text(urdf.read_text().replace('ixz="0"', 'ixz="8e-6"'))

    env = GraspEnv(objects_dir=tmp_path)
    try:
        assert env.world.object.inertial_frame[1] != (0.0, 0.0, 0.0, 1.0)
        for seed in range(3):
            env.reset(seed=seed)
            position, orientation = env.object_pose()
            roll, pitch, _ = env.world.client.getEulerFromQuaternion(orientation)
            assert abs(roll) < 0.01 and abs(pitch) < 0.01
            assert position[2] == pytest.approx(0.025, abs=0.002)
            points = env.world.object_points()
            assert points[:, 2].min() == pytest.approx(0.0, abs=0.002)
            assert points[:, 2].max() == pytest.approx(0.05, abs=0.002)
    finally:
        env.close()


def test_state_accessors_for_the_sim_node(make_env) -> None:
    env = make_env()
    observation, _ = env.reset(seed=0)
    unwrapped = gym.wrappers.RecordEpisodeStatistics(env).unwrapped
    assert unwrapped.joint_names == [f"panda_joint{i}" for i in range(1, 8)] + [
        "panda_finger_joint1",
        "panda_finger_joint2",
    ]
    positions = unwrapped.joint_positions()
    assert positions.shape == (9,)
    np.testing.assert_allclose(positions[7:], (0.04, 0.04), atol=1e-3)

    state = unwrapped.grasp_state()
    assert state == GraspState(False, False, state.gripper_opening, state.object_lift, 0)
    assert state.gripper_opening == pytest.approx(observation[OBS_GRIPPER_OPENING], abs=1e-6)

    position, orientation = unwrapped.object_pose()
    assert position.shape == (3,) and orientation.shape == (4,)
    assert np.linalg.norm(orientation) == pytest.approx(1.0)
    env.step(np.zeros(5))
    assert unwrapped.grasp_state().step == 1


def test_rgb_render_and_double_close(make_env) -> None:
    env = make_env(render_mode="rgb_array")
    env.reset(seed=0)
    frame = env.render()
    assert frame.shape == (240, 320, 3) and frame.dtype == np.uint8 and frame.std() > 0
    env.close()
    env.close()


def test_config_is_validated() -> None:
    with pytest.raises(ValueError, match="max_steps"):
        GraspEnvConfig(max_steps=0)
    with pytest.raises(ValueError, match="min_tcp_height"):
        GraspEnvConfig(min_tcp_height=0.4)
    with pytest.raises(ValueError, match="settle"):
        GraspEnvConfig(settle_substeps=500)



def test_the_fingers_move_as_one_as_the_urdf_says(make_env) -> None:
    """A scripted grasp 2 cm off the box's middle across the hand: one finger meets the box first,
    and the coupling (the URDF's mimic) keeps the other at the same travel; uncoupled, the two
    stood 4 mm apart here (3 cm on a generated object)."""
    env = make_env()
    policy = ScriptedGraspPolicy(error=GraspError(across=0.02), retry=False)
    env.reset(seed=1, options={"task": BOX_TASK})
    finger1, finger2 = JOINT_NAMES.index("panda_finger_joint1"), JOINT_NAMES.index("panda_finger_joint2")
    apart, closed = [], False
    while True:
        _, _, terminated, truncated, _ = env.step(policy.act(env))
        positions = env.world.robot.joint_positions()
        apart.append(abs(positions[finger1] - positions[finger2]))
        closed |= env.grasp_state().gripper_opening < 0.07
        if terminated or truncated:
            break
    assert closed, "the scripted grasp never closed the gripper"
    assert max(apart) < 0.002, max(apart)

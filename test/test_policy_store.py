"""The policy store: named SAC policies on disk, written atomically, loaded as data."""

import json
import re
import subprocess
import sys

import numpy as np
import pytest

from conftest import store_pickled_policy
from learner_node.policy_store import PolicyRecord, PolicyStore, UnknownPolicyError
from learner_node.sac_settings import DEFAULT_NETWORK, network
from sim_node.grasp_env import GraspEnv


@pytest.fixture(scope="module")
def model():
    env = GraspEnv("A0")
    yield network(DEFAULT_NETWORK).new_model(env, 0, buffer_size=100)
    env.close()


def test_save_list_load_update(tmp_path, model):
    store = PolicyStore(tmp_path)
    assert store.names() == []
    store.save(model, PolicyRecord(name="G1", task="B2", parent="prior", steps_trained=123))
    assert store.names() == ["G1"] and "G1" in store
    record = store.record("G1")
    assert (record.task, record.parent, record.steps_trained, record.last_score) == ("B2", "prior", 123, -1.0)
    observation = np.zeros((2, 63), dtype=np.float32)
    np.testing.assert_allclose(store.load("G1").predict(observation, deterministic=True)[0],
                               model.predict(observation, deterministic=True)[0], atol=1e-6)
    assert store.update("G1", last_score=80.0, last_score_task="B2").last_score == 80.0


def test_a_model_of_another_library_is_refused_on_save_naming_it_and_nothing_is_written(tmp_path, model):
    from stable_baselines3 import SAC

    store = PolicyStore(tmp_path)
    with pytest.raises(ValueError, match="only SBX's SAC.*not stable_baselines3.sac.sac.SAC"):
        store.save(SAC("MlpPolicy", model.get_env(), seed=0, device="cpu", buffer_size=100),
                   PolicyRecord(name="torch_made"))
    assert store.names() == [] and list((tmp_path / "torch_made").iterdir()) == []


def test_a_policy_of_the_pickled_format_before_is_listed_never_loaded_or_copied(tmp_path, model):
    """A stable-baselines3 zip (what the store wrote before) is refused naming the file and the command that
    converts it; the refusal reads none of it."""
    store_pickled_policy(tmp_path / "store", "old", model)
    store = PolicyStore(tmp_path / "store")
    assert store.names() == ["old"] and store.record("old").model_file == "model-1.zip"
    zip_file = tmp_path / "store" / "old" / "model-1.zip"
    message = (f"{re.escape(str(zip_file))}: policy 'old' is a stable-baselines3 zip.*glocal-ros policy import "
               f"{re.escape(str(zip_file))} --trust")
    for action in (lambda: store.load("old"), lambda: PolicyStore(tmp_path / "copy").add_copy(store, "old", "new"),
                   lambda: store.keep_experience("old", _experience(2))):
        with pytest.raises(ValueError, match=message):
            action()
    assert not (tmp_path / "copy" / "new").exists() and store.record("old").experience_file == ""


def test_overwrite_keeps_one_complete_model(tmp_path, model):
    store = PolicyStore(tmp_path)
    store.save(model, PolicyRecord(name="L1"))
    store.save(model, PolicyRecord(name="L1", steps_trained=5))
    files = sorted(p.name for p in (tmp_path / "L1").iterdir())
    assert files == ["model-2.npz", "policy.json"]
    assert store.record("L1").steps_trained == 5


def test_unknown_and_invalid_names(tmp_path):
    store = PolicyStore(tmp_path)
    with pytest.raises(UnknownPolicyError, match="unknown policy 'nope'"):
        store.record("nope")
    for bad in ("../escape", "", "a/b", ".hidden"):
        with pytest.raises(ValueError, match="invalid policy name"):
            store.record(bad)


@pytest.mark.parametrize("model_file", ["../other/model-1.npz", "/etc/passwd", "model-1.npz/..", "evil.pkl",
                                        "../other/model-1.zip"])
def test_a_model_file_outside_the_store_naming_is_refused(tmp_path, model, model_file):
    """policy.json is data anyone may edit: the model it names must be the store's own."""
    store = PolicyStore(tmp_path)
    store.save(model, PolicyRecord(name="G1"))
    metadata = tmp_path / "G1" / "policy.json"
    metadata.write_text(metadata.read_text().replace('"model-1.npz"', json.dumps(model_file)))
    with pytest.raises(ValueError, match="is not a model file of this store"):
        store.load("G1")


def test_a_kill_during_save_never_corrupts_the_store(tmp_path, model):
    store = PolicyStore(tmp_path)
    store.save(model, PolicyRecord(name="P", steps_trained=1))
    # A process killed mid-save (SIGKILL right after it started writing the new model).
    script = (
        "import os, signal, sys\n"
        "from learner_node import policy_store\n"
        "from learner_node.policy_store import PolicyStore, PolicyRecord\n"
        "store = PolicyStore(sys.argv[1])\n"
        "def dying(model, stream):\n"
        "    stream.write(b'partial')\n"
        "    os.kill(os.getpid(), signal.SIGKILL)\n"
        "policy_store.write_model = dying\n"
        "store.save(object(), PolicyRecord(name='P', steps_trained=2))\n"
    )
    result = subprocess.run([sys.executable, "-c", script, str(tmp_path)], capture_output=True)
    assert result.returncode == -9
    assert store.record("P").steps_trained == 1
    store.load("P")  # still the complete first model


# Saves a policy in a process whose files may not grow past 200 kB, as a full disk stops them.
_SAVE_WITHOUT_ROOM = """
import resource, sys
from pathlib import Path
from glocal_ros.files import atomic_write
resource.setrlimit(resource.RLIMIT_FSIZE, (200_000, 200_000))
try:
    atomic_write(Path(sys.argv[1]), lambda stream: stream.write(bytes(1_000_000)))
except OSError as error:
    print(error)
"""


def test_a_write_that_fails_for_room_names_the_file_and_leaves_nothing(tmp_path):
    import subprocess
    import sys

    target = tmp_path / "L1" / "model-2.npz"
    target.parent.mkdir()
    result = subprocess.run([sys.executable, "-c", _SAVE_WITHOUT_ROOM, str(target)], capture_output=True, text=True,
                            timeout=120, check=True)
    assert f"cannot write {target}: File too large" in result.stdout, result.stdout + result.stderr
    assert list(target.parent.iterdir()) == []  # no temporary file left


def _experience(transitions: int, start: float = 0.0) -> dict:
    """Transitions numbered by their observation's first entry, oldest first."""
    observations = np.zeros((transitions, 63), dtype=np.float32)
    observations[:, 0] = start + np.arange(transitions)
    return {"observations": observations, "next_observations": observations + 1,
            "actions": np.zeros((transitions, 5), dtype=np.float32),
            "rewards": -np.ones(transitions, dtype=np.float32), "dones": np.zeros(transitions, dtype=np.float32),
            "timeouts": np.zeros(transitions, dtype=np.float32)}


def test_experience_is_kept_with_its_model_copied_with_it_and_dropped_by_a_save_without_it(tmp_path, model):
    store = PolicyStore(tmp_path / "a")
    store.save(model, PolicyRecord(name="P"), _experience(7))
    assert sorted(p.name for p in (tmp_path / "a" / "P").iterdir()) == ["experience-1.npz", "model-1.npz",
                                                                        "policy.json"]
    np.testing.assert_array_equal(store.experience("P")["observations"][:, 0], np.arange(7))

    copy = PolicyStore(tmp_path / "b")
    copy.add_copy(store, "P", "Q")
    np.testing.assert_array_equal(copy.experience("Q")["next_observations"][:, 0], np.arange(7) + 1)

    model_bytes = (tmp_path / "a" / "P" / "model-1.npz").read_bytes()
    store.keep_experience("P", _experience(3, start=100))
    assert (tmp_path / "a" / "P" / store.record("P").model_file).read_bytes() == model_bytes
    np.testing.assert_array_equal(store.experience("P")["observations"][:, 0], [100, 101, 102])

    store.save(model, PolicyRecord(name="P"))
    assert store.experience("P") is None
    assert sorted(p.name for p in (tmp_path / "a" / "P").iterdir()) == ["model-3.npz", "policy.json"]


@pytest.mark.parametrize("experience_file", ["../other/experience-1.npz", "/etc/passwd", "evil.pkl"])
def test_an_experience_file_outside_the_store_naming_is_refused(tmp_path, model, experience_file):
    store = PolicyStore(tmp_path)
    store.save(model, PolicyRecord(name="G1"), _experience(2))
    metadata = tmp_path / "G1" / "policy.json"
    metadata.write_text(metadata.read_text().replace('"experience-1.npz"', json.dumps(experience_file)))
    with pytest.raises(ValueError, match="is not an experience file of this store"):
        store.experience("G1")


def test_recent_experience_folds_the_env_axis_and_a_goals_ring_takes_it_row_by_row(model, tmp_path):
    """A buffer of 2 envs that wrapped gives its newest transitions, oldest first; a goal's ring takes them
    all, one row each, keeps its newest ``capacity`` as it goes round, and saves and loads them."""
    from stable_baselines3.common.buffers import ReplayBuffer

    from learner_node.replay_buffer import recent_experience
    from learner_node.updates import TransitionRing

    spaces = (model.observation_space, model.action_space)
    two = ReplayBuffer(8, *spaces, device="cpu", n_envs=2)  # SB3: 8 transitions, 4 rows of 2
    for row in range(6):  # rows 0..5 into 4 slots: rows 2..5 stay
        obs = np.zeros((2, 63), dtype=np.float32)
        obs[:, 0] = [2 * row, 2 * row + 1]
        two.add(obs, obs + 1, np.zeros((2, 5), dtype=np.float32), -np.ones(2), np.zeros(2), [{}, {}])
    recent = recent_experience(two, 5)
    np.testing.assert_array_equal(recent["observations"][:, 0], [7, 8, 9, 10, 11])
    assert len(recent_experience(two, 100)["observations"]) == 8

    ring = TransitionRing(4, 63, 5)
    assert ring.add(recent) == 4  # the newest 4 of 5
    assert (ring.size, ring.pos, ring.full) == (4, 0, True)
    np.testing.assert_array_equal(ring.recent(3)["observations"][:, 0], [9, 10, 11])
    assert ring.add({name: values[:1] for name, values in recent.items()}) == 1  # 7 replaces the oldest, 8
    np.testing.assert_array_equal(ring.recent(4)["observations"][:, 0], [9, 10, 11, 7])
    np.testing.assert_array_equal(ring.recent(4)["next_observations"][:, 0], [10, 11, 12, 8])
    with (tmp_path / "ring.npz").open("wb") as stream:
        ring.save(stream)
    again = TransitionRing(4, 63, 5)
    assert again.load(tmp_path / "ring.npz")
    for name, values in ring.recent(4).items():
        np.testing.assert_array_equal(again.recent(4)[name], values, err_msg=name)
    assert not TransitionRing(5, 63, 5).load(tmp_path / "ring.npz"), "a ring of another capacity starts empty"
    with pytest.raises(ValueError, match="do not fit"):
        ring.add({**recent, "observations": np.zeros((5, 10), dtype=np.float32)})

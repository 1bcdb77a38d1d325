"""The policy store: named SB3 policies on disk, written atomically."""

import json
import subprocess
import sys

import numpy as np
import pytest
from stable_baselines3 import SAC

from learner_node.policy_store import PolicyRecord, PolicyStore, UnknownPolicyError
from learner_node.sac_settings import SAC_KWARGS
from sim_node.grasp_env import GraspEnv


@pytest.fixture(scope="module")
def model():
    env = GraspEnv("A0")
    yield SAC("MlpPolicy", env, seed=0, device="cpu", **{**SAC_KWARGS, "buffer_size": 100})
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


def test_overwrite_keeps_one_complete_model(tmp_path, model):
    store = PolicyStore(tmp_path)
    store.save(model, PolicyRecord(name="L1"))
    store.save(model, PolicyRecord(name="L1", steps_trained=5))
    files = sorted(p.name for p in (tmp_path / "L1").iterdir())
    assert files == ["model-2.zip", "policy.json"]
    assert store.record("L1").steps_trained == 5


def test_unknown_and_invalid_names(tmp_path):
    store = PolicyStore(tmp_path)
    with pytest.raises(UnknownPolicyError, match="unknown policy 'nope'"):
        store.record("nope")
    for bad in ("../escape", "", "a/b", ".hidden"):
        with pytest.raises(ValueError, match="invalid policy name"):
            store.record(bad)


@pytest.mark.parametrize("model_file", ["../other/model-1.zip", "/etc/passwd", "model-1.zip/..", "evil.pkl"])
def test_a_model_file_outside_the_store_naming_is_refused(tmp_path, model, model_file):
    """policy.json is data anyone may edit; the model it names is unpickled: it must be the store's own."""
    store = PolicyStore(tmp_path)
    store.save(model, PolicyRecord(name="G1"))
    metadata = tmp_path / "G1" / "policy.json"
    metadata.write_text(metadata.read_text().replace('"model-1.zip"', json.dumps(model_file)))
    with pytest.raises(ValueError, match="is not a model file of this store"):
        store.load("G1")


def test_a_kill_during_save_never_corrupts_the_store(tmp_path, model):
    store = PolicyStore(tmp_path)
    store.save(model, PolicyRecord(name="P", steps_trained=1))
    # A process killed mid-save (SIGKILL right after it started writing the new model).
    script = (
        "import os, signal, sys\n"
        "from stable_baselines3 import SAC\n"
        "from learner_node.policy_store import PolicyStore, PolicyRecord\n"
        "store = PolicyStore(sys.argv[1])\n"
        "class Dying:\n"
        "    def save(self, stream):\n"
        "        stream.write(b'partial')\n"
        "        os.kill(os.getpid(), signal.SIGKILL)\n"
        "store.save(Dying(), PolicyRecord(name='P', steps_trained=2))\n"
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

    target = tmp_path / "L1" / "model-2.zip"
    target.parent.mkdir()
    result = subprocess.run([sys.executable, "-c", _SAVE_WITHOUT_ROOM, str(target)], capture_output=True, text=True,
                            timeout=120, check=True)
    assert f"cannot write {target}: File too large" in result.stdout, result.stdout + result.stderr
    assert list(target.parent.iterdir()) == []  # no temporary file left

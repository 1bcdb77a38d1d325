"""Nothing a store holds is unpickled: a pickle whose loading would create a marker file, planted in every file a
policy store, a goal's checkpoint and the prior's work directory hold, runs nothing, and reading the file refuses
it with a ``ValueError`` that names it.

Each file gets every way a pickle can sit in it: the whole file; for an ``.npz``, an object array (the only way a
``.npy`` holds a pickle) beside its arrays, and a member that is a raw pickle. A payload counts as run when its
marker exists after the read; the test checks first that the payload does run when unpickled.
"""

from __future__ import annotations

import base64
import io
import json
import pickle
import re
import shutil
import zipfile
from pathlib import Path
from typing import Callable

import numpy as np
import pytest

from conftest import store_pickled_policy
from glocal_ros.paths import assets_dir
from learner_node.model_files import load_model, load_pickled_model
from learner_node.policies import PolicyRegistry
from learner_node.policy_store import PolicyStore
from learner_node.prior import PriorConfig, train_prior
from glocal_ros.curriculum.learner import TrainGoal
from learner_node.training import CHECKPOINT_FILE, FINISHED_FILE, Trainer
from sim_node.batch import BatchedEnvs
from sim_node.grasp_env import GraspEnv, GraspEnvConfig
from sim_node.scripted_grasp import ScriptedGraspPolicy

SHORT = GraspEnvConfig(max_steps=10)


class Payload:
    """Unpickled, it creates ``marker`` (``open(marker, "w")``): proof that a load ran the file's code."""

    def __init__(self, marker: Path):
        self.marker = marker

    def __reduce__(self):
        return open, (str(self.marker), "w")


class Plants:
    """Plants payloads into files, each with a marker of its own, and counts them."""

    def __init__(self, folder: Path):
        self.folder = folder
        self.markers: list[Path] = []

    def payload(self) -> bytes:
        self.markers.append(self.folder / f"marker-{len(self.markers)}")
        return pickle.dumps(Payload(self.markers[-1]))

    def ways(self, path: Path) -> list[tuple[str, bytes]]:
        """(how, the file's new content) for every way a pickle can sit in ``path``."""
        ways = [("the whole file", self.payload())]
        if path.suffix == ".npz":
            with np.load(path, allow_pickle=False) as archive:
                arrays = {name: archive[name] for name in archive.files}
            ways.append(("an object array", _npz(arrays, planted=np.array([_Marked(self)], dtype=object))))
            raw = io.BytesIO()
            with zipfile.ZipFile(raw, "w") as archive, zipfile.ZipFile(path) as original:
                for member in original.namelist():
                    archive.writestr(member, original.read(member))
                archive.writestr("planted.npy", self.payload())
            ways.append(("a raw pickle member", raw.getvalue()))
        return ways

    def check(self, path: Path, read: Callable[[], object]) -> list[str]:
        """Plant each way in ``path``, ``read()``; the failures (a payload that ran, no refusal naming ``path``)."""
        original, failures = path.read_bytes(), []
        for how, content in self.ways(path):
            earlier = {marker for marker in self.markers if marker.exists()}
            path.write_bytes(content)
            try:
                read()
                failures.append(f"{path.name} ({how}): read without an error")
            except ValueError as error:
                if str(path) not in str(error):
                    failures.append(f"{path.name} ({how}): the error does not name the file: {error}")
            finally:
                path.write_bytes(original)
            ran = [marker.name for marker in self.markers if marker.exists() and marker not in earlier]
            if ran:
                failures.append(f"{path.name} ({how}): the payload ran ({ran})")
        return failures


class _Marked:
    """A payload made at pickling time, so that each object array gets a marker of its own."""

    def __init__(self, plants: Plants):
        self.plants = plants

    def __reduce__(self):
        self.plants.markers.append(self.plants.folder / f"marker-{len(self.plants.markers)}")
        return open, (str(self.plants.markers[-1]), "w")


def _npz(arrays: dict[str, np.ndarray], **more) -> bytes:
    stream = io.BytesIO()
    np.savez(stream, **arrays, **more)
    return stream.getvalue()


def test_the_payload_runs_when_unpickled(tmp_path):
    plants = Plants(tmp_path)
    pickle.loads(plants.payload())
    assert plants.markers[0].exists()


@pytest.fixture(scope="module")
def goal(tmp_path_factory):
    """A goal stopped after 18 steps (its checkpoint), and the same goal finished (its policy in the store and its
    outcome kept): every file a learner's store holds, as the learner writes them."""
    work = tmp_path_factory.mktemp("goal")
    envs = BatchedEnvs(lambda i: GraspEnv("A0", config=SHORT), 2, "A0")
    policies = PolicyRegistry(PolicyStore(work / "store"), [PolicyStore(assets_dir() / "priors")])
    spec = TrainGoal("A0", "prior", "out", step_budget=40, eval_episodes=1)
    vector_steps = iter(range(1_000))
    trainer = Trainer(envs, policies, work / "checkpoints")
    stopped = trainer.train(spec, should_stop=lambda: "stopped" if next(vector_steps) >= 8 else "")
    assert not stopped.completed
    shutil.copytree(work / "checkpoints" / "out", work / "stopped")
    yield work, envs, policies, spec
    envs.close()


def test_no_file_of_a_goals_checkpoint_runs_a_planted_pickle(goal, tmp_path):
    work, envs, policies, spec = goal
    folder = work / "checkpoints" / "out"
    saved = json.loads((folder / CHECKPOINT_FILE).read_text())
    assert (saved["model"], saved["buffer"]) == ("model-1.npz", "buffer-1.npz")

    def resume():
        Trainer(envs, policies, work / "checkpoints").train(spec)

    plants, failures = Plants(tmp_path), []
    for name in (CHECKPOINT_FILE, saved["model"], saved["buffer"]):
        failures += plants.check(folder / name, resume)
    assert not failures and len(plants.markers) == 7, failures


def test_no_file_of_a_stored_policy_or_a_finished_goal_runs_a_planted_pickle(goal, tmp_path):
    work, envs, policies, spec = goal
    shutil.rmtree(work / "checkpoints" / "out")
    shutil.copytree(work / "stopped", work / "checkpoints" / "out")
    outcome = Trainer(envs, policies, work / "checkpoints").train(spec)
    assert outcome.completed and "resumed from a checkpoint at step 18" in outcome.message
    store = policies.store
    record = store.record("out")
    assert (record.model_file, record.experience_file) == ("model-1.npz", "experience-1.npz")

    def finished_again():
        Trainer(envs, policies, work / "checkpoints").train(spec)

    plants, failures = Plants(tmp_path), []
    folder = store.root / "out"
    failures += plants.check(folder / "policy.json", lambda: store.record("out"))
    failures += plants.check(folder / record.model_file, lambda: store.load("out"))
    failures += plants.check(folder / record.experience_file, lambda: store.experience("out"))
    failures += plants.check(work / "checkpoints" / "out" / FINISHED_FILE, finished_again)
    assert not failures and len(plants.markers) == 8, failures
    assert "finished before" in Trainer(envs, policies, work / "checkpoints").train(spec).message


def test_no_file_of_the_priors_work_directory_runs_a_planted_pickle(tmp_path):
    work = tmp_path / "prior"
    config = PriorConfig(demo_episodes=1, max_steps=40, checkpoint_every=40, min_steps=40)

    def resume():
        train_prior(lambda: GraspEnv("A0", config=SHORT), ScriptedGraspPolicy().act, work, config)

    resume()
    plants, failures = Plants(tmp_path), []
    for name in ("checkpoint.npz", "replay_buffer.npz"):
        failures += plants.check(work / name, resume)
    assert not failures and len(plants.markers) == 6, failures


def test_a_zip_of_the_format_before_is_refused_unread_and_would_have_run_its_payload(tmp_path):
    """A policy the store wrote before (stable-baselines3's zip) with a payload in its pickled data: the store
    refuses it, as the model loader does, without running it; the trusted import (SB3's load) would run it."""
    from learner_node.sac_settings import DEFAULT_NETWORK, network

    env = GraspEnv("A0", config=SHORT)
    try:
        model = network(DEFAULT_NETWORK).new_model(env, 0, buffer_size=100)
    finally:
        env.close()
    zip_file = store_pickled_policy(tmp_path / "store", "old", model)
    marker = tmp_path / "marker"
    with zipfile.ZipFile(zip_file) as archive:
        members = {name: archive.read(name) for name in archive.namelist()}
    data = json.loads(members["data"])
    data["target_entropy"][":serialized:"] = base64.b64encode(pickle.dumps(Payload(marker))).decode()
    members["data"] = json.dumps(data).encode()
    with zipfile.ZipFile(zip_file, "w") as archive:
        for name, content in members.items():
            archive.writestr(name, content)

    for read in (lambda: PolicyStore(tmp_path / "store").load("old"), lambda: load_model(zip_file)):
        with pytest.raises(ValueError, match=f"^{re.escape(str(zip_file))}: .*stable-baselines3 zip"):
            read()
        assert not marker.exists()
    try:
        load_pickled_model(zip_file)
    except Exception:
        pass  # what the payload left in place of the entropy target breaks the model; the payload ran before
    assert marker.exists(), "the planted payload is live: SB3's load runs it"

"""Stored models are data (``learner_node.model_files``): arrays and JSON, rebuilt as SB3's load rebuilt the pickled
zip, refused whole and by the file's name when anything does not fit; the shipped priors, converted from their zips
(kept as test data in test/data/pickled-priors), act and train exactly as the zips did."""

import json
import re
import zipfile
from pathlib import Path

import jax
import numpy as np
import pytest

from conftest import REPO
from learner_node.evaluation import evaluate
from learner_node.model_files import ATTRIBUTES, load_model, load_pickled_model, read_model_file, write_model
from learner_node.policy_store import PolicyRecord, PolicyStore
from learner_node.profiles import PROFILES
from learner_node.sac_settings import DEFAULT_NETWORK, entropy_learning_rate, network, seed_keys
from sim_node.batch import BatchedEnvs
from sim_node.grasp_env import GraspEnv

PICKLED_PRIORS = REPO / "test" / "data" / "pickled-priors"


@pytest.fixture(scope="module")
def env():
    env = GraspEnv("A0")
    yield env
    env.close()


@pytest.fixture(scope="module")
def model(env):
    return network(DEFAULT_NETWORK).new_model(env, 0, buffer_size=100)


def _leaves(model) -> dict[str, object]:
    trees = {"actor": model.policy.actor_state, "critics": model.policy.qf_state, "entropy": model.ent_coef_state,
             "policy key": model.policy.key, "noise key": model.policy.noise_key}
    return {f"{name}{jax.tree_util.keystr(path)}": leaf for name, tree in trees.items()
            for path, leaf in jax.tree_util.tree_flatten_with_path(tree)[0]}


def assert_same_model(expected, actual, keys: bool = True) -> None:
    """Every leaf of the two models' states of one type, dtype, weak type and value; every stored setting equal;
    (``keys``) the gradient steps' key and the action space's generator in one state."""
    expected_leaves, actual_leaves = _leaves(expected), _leaves(actual)
    assert expected_leaves.keys() == actual_leaves.keys()
    for name, leaf in expected_leaves.items():
        other = actual_leaves[name]
        assert (type(leaf), getattr(leaf, "dtype", None), getattr(leaf, "weak_type", None)) == \
            (type(other), getattr(other, "dtype", None), getattr(other, "weak_type", None)), name
        np.testing.assert_array_equal(np.asarray(leaf), np.asarray(other), err_msg=name)
    for name in (*ATTRIBUTES, "train_freq", "observation_space", "action_space"):
        value, other = getattr(expected, name), getattr(actual, name)
        # SBX makes "auto" numpy's float32, and its load (and this one) a float
        assert value == other and (type(value) is type(other) or name == "target_entropy"), name
    assert expected.lr_schedule(1) == actual.lr_schedule(1)
    assert entropy_learning_rate(expected) == entropy_learning_rate(actual)
    for network_name in ("actor", "qf"):
        assert repr(getattr(expected.policy, network_name)) == repr(getattr(actual.policy, network_name))
    if keys:
        np.testing.assert_array_equal(expected.key, actual.key)
        assert expected.action_space.np_random.bit_generator.state == actual.action_space.np_random.bit_generator.state


def _write(model, path: Path) -> Path:
    with path.open("wb") as stream:
        write_model(model, stream)
    return path


def test_a_model_that_trained_comes_back_as_it_was(tmp_path, env):
    """Adam's counts and moments, weakly typed steps, the learning rate SBX set, the entropy coefficient and the
    policy's keys: all of them, and the settings a goal changed (a learning rate: the entropy coefficient's Adam
    keeps the one it was made with)."""
    model = network(DEFAULT_NETWORK).new_model(env, 3, buffer_size=200, learning_starts=20)
    model.learn(40)
    model.learning_rate = 1e-4
    model._setup_lr_schedule()
    loaded = load_model(_write(model, tmp_path / "model.npz"), env=env)
    assert_same_model(model, loaded, keys=False)
    assert loaded.policy.actor_state.step.weak_type and int(loaded.policy.actor_state.step) == model._n_updates
    assert np.float32(entropy_learning_rate(loaded)) == np.float32(3e-4) and loaded.learning_rate == 1e-4
    observations = np.random.default_rng(0).uniform(-1, 1, (5, 63)).astype(np.float32)
    np.testing.assert_array_equal(model.predict(observations, deterministic=True)[0],
                                  loaded.predict(observations, deterministic=True)[0])


@pytest.mark.parametrize("profile", ["glocal_ros", "paper"])
def test_the_shipped_prior_acts_exactly_as_the_zip_it_was_converted_from(profile):
    """The converted prior against its zip (loaded the trusted way): the same arrays and settings, its record's
    metadata kept, and on the same seeded episodes the same actions, step by step, and the same score."""
    profile = PROFILES[profile]
    old_record = json.loads((PICKLED_PRIORS / profile.prior_store / "prior" / "policy.json").read_text())
    zipped = load_pickled_model(PICKLED_PRIORS / profile.prior_store / "prior" / old_record["model_file"])
    store = PolicyStore(profile.shipped_priors())
    converted = store.load("prior")
    assert_same_model(zipped, converted)
    record = store.record("prior").__dict__
    for name in ("model_file", "experience_file", "updated"):
        assert record.pop(name) != old_record.pop(name)
    assert record == old_record

    envs = BatchedEnvs(lambda i: GraspEnv("A0"), 2, "A0")
    runs = []
    try:
        for model in (zipped, converted):
            actions = []

            def act(observations, model=model, actions=actions):
                actions.append(model.predict(observations, deterministic=True)[0])
                return actions[-1]

            (score,) = evaluate(envs, act, ["A0"], 4, seed=7)
            runs.append((score, np.concatenate(actions)))
    finally:
        envs.close()
    (zip_score, zip_actions), (score, actions) = runs
    assert score == zip_score and len(actions) >= 4 * 5
    np.testing.assert_array_equal(actions, zip_actions)


def test_the_shipped_prior_trains_on_exactly_as_the_zip_it_was_converted_from(env):
    """A goal continues a stored policy: the converted prior and its zip, loaded on the same env, seeded alike,
    end 40 steps of SAC (gradient steps from the first: the prior's learning_starts is 0) with equal states."""
    old_record = json.loads((PICKLED_PRIORS / "priors" / "prior" / "policy.json").read_text())
    models = [load_pickled_model(PICKLED_PRIORS / "priors" / "prior" / old_record["model_file"], env=env),
              PolicyStore(PROFILES["glocal_ros"].shipped_priors()).load("prior", env=env)]
    for model in models:
        model.set_random_seed(5)
        seed_keys(model, 5)
        model.learn(40, reset_num_timesteps=False)
    zipped, converted = models
    assert converted._n_updates == zipped._n_updates > old_record["steps_trained"] - 1
    assert_same_model(zipped, converted)


# ------------------------------------------------------------------------------------------ refusals

def _rewrite(source: Path, target: Path, edit) -> Path:
    """``target``: the model file ``source`` with ``edit(arrays, metadata)`` applied."""
    arrays, metadata = read_model_file(source)
    edit(arrays, metadata)
    with target.open("wb") as stream:
        np.savez(stream, metadata=np.array(json.dumps(metadata)), **arrays)
    return target


def _bigger_network(arrays, metadata):
    metadata["attributes"]["policy_kwargs"]["net_arch"] = [256, 256]


def _set(**attributes):
    return lambda arrays, metadata: metadata["attributes"].update(attributes)


@pytest.mark.parametrize("edit, message", [
    (lambda arrays, metadata: arrays.pop("actor_state/params/params/Dense_1/kernel"),
     "array 'actor_state/params/params/Dense_1/kernel' is missing"),
    (lambda arrays, metadata: arrays.update(extra=np.zeros(3)), "does not have: ['extra']"),
    (lambda arrays, metadata: arrays.update({"qf_state/target_params/params/VmapContinuousCritic_0/Dense_0/bias":
                                             np.zeros((2, 65), np.float32)}),
     "is (2, 65) float32, and the network the metadata describes has (2, 64) float32"),
    (lambda arrays, metadata: arrays.update({"policy/key": np.zeros(2, np.int64)}), "'policy/key' is (2,) int64"),
    (_bigger_network, "Dense_0/bias' is (64,) float32, and the network the metadata describes has (256,) float32"),
    (lambda arrays, metadata: arrays.update({"action_space/low": np.zeros(4, np.float32)}),
     "'action_space/low' is (4,) float32"),
    (_set(gamma="0.95"), "attribute gamma is '0.95' (str), not float, int"),
    (_set(surprise=1), "unknown ['surprise']"),
    (_set(policy_kwargs={"net_arch": [64, 64], "activation_fn": "os.system"}), "policy_kwargs ['activation_fn']"),
    (lambda arrays, metadata: metadata.update(version=2), "not a model file of format"),
    (lambda arrays, metadata: metadata.pop("train_freq"), "the metadata lacks 'train_freq'"),
    (lambda arrays, metadata: metadata.update(weak_typed=["nothing"]), "weak_typed is not a list of the file's"),
])
def test_arrays_or_metadata_that_do_not_fit_are_refused_naming_the_file(tmp_path, model, edit, message):
    path = _rewrite(_write(model, tmp_path / "model.npz"), tmp_path / "edited.npz", edit)
    with pytest.raises(ValueError, match=f"^{re.escape(str(path))}: .*{re.escape(message)}"):
        load_model(path)


def test_a_truncated_file_or_another_kind_of_file_is_refused_naming_it(tmp_path, model):
    whole = _write(model, tmp_path / "model.npz").read_bytes()
    for name, content in {"truncated.npz": whole[: len(whole) // 2], "empty.npz": b"", "text.npz": b"{}"}.items():
        (tmp_path / name).write_bytes(content)
    with (tmp_path / "array.npz").open("wb") as stream:
        np.save(stream, np.zeros(3))
    with zipfile.ZipFile(tmp_path / "member.npz", "w") as archive:
        archive.writestr("weights.npy", b"not an array")
    np.savez(tmp_path / "bare.npz", weights=np.zeros(3))
    for name, message in {"truncated.npz": "", "empty.npz": "", "text.npz": "", "array.npz": "not an .npz",
                          "member.npz": "member 'weights' is not an array", "bare.npz": "no metadata"}.items():
        with pytest.raises(ValueError, match=f"^{re.escape(str(tmp_path / name))}: .*{message}"):
            load_model(tmp_path / name)


def test_an_env_of_other_spaces_is_refused_naming_the_file(tmp_path, model):
    import gymnasium as gym

    class Wider(gym.Wrapper):
        observation_space = gym.spaces.Box(-2.0, 2.0, (63,), np.float32)

    path = _write(model, tmp_path / "model.npz")
    wider = Wider(GraspEnv("A0"))
    try:
        with pytest.raises(ValueError, match=f"^{re.escape(str(path))}: Observation spaces do not match"):
            load_model(path, env=wider)
    finally:
        wider.close()


def test_a_model_whose_settings_are_code_is_not_stored_and_nothing_is_written(tmp_path, env):
    import flax.linen as nn

    model = network(DEFAULT_NETWORK).new_model(env, 0, buffer_size=100, policy_kwargs={"net_arch": [8],
                                                                                       "activation_fn": nn.tanh})
    store = PolicyStore(tmp_path)
    with pytest.raises(ValueError, match=r"policy_kwargs \['activation_fn'\] are not stored as data"):
        store.save(model, PolicyRecord(name="tanh"))
    assert list((tmp_path / "tanh").iterdir()) == []

"""SAC models as data: arrays and JSON metadata in one ``.npz``, loaded without unpickling or running code.

A model file (a stored policy's ``model-<N>.npz``, a goal's checkpoint, the
prior's work checkpoint) is a numpy ``.npz`` archive of plain arrays:

- ``metadata``: a 0-d string array holding JSON: the format's name and
  version, the algorithm (SBX's SAC with its ``MlpPolicy``, nothing else is
  written or read), the SB3 attributes that decide how the model acts and
  trains (hyperparameters, network, counters: ``ATTRIBUTES``), ``train_freq``,
  the spaces' shapes and dtypes, the entropy coefficient's learning rate, and
  which leaves were Python scalars or weakly typed JAX arrays;
- one array per leaf of the model's JAX state, named by its path:
  ``actor_state/...``, ``qf_state/...``, ``ent_coef_state/...`` (flax train
  states: step, parameters, target parameters, Adam's moments and counts),
  ``policy/key`` and ``policy/noise_key`` (the policy's sampling keys);
- ``observation_space/low``, ``/high`` and ``action_space/low``, ``/high``.

Why one ``.npz``: one file is one atomic write (``glocal_ros.files.atomic_write``),
so a store's protocol (model file, then ``policy.json``) stays as it was and
the metadata can never describe other arrays than its own; ``np.load`` with
``allow_pickle=False`` reads numeric and string arrays and refuses object
arrays, which are the only way a ``.npy`` holds a pickle. JSON rather than
msgpack: the metadata is small, and a person can read it with ``unzip -p``.

Loading (``load_model``) rebuilds the model as SB3's ``load`` does, with no
code from the file: a SAC of the learner's backend is made from the
metadata (``_init_setup_model=False``, the attributes set, ``_setup_model``),
which builds networks and optimisers of the recorded settings; every leaf of
that fresh model's states names an array the file must hold with the same
shape and dtype, and the file must hold no other. Any difference (a truncated
file, a missing or extra array, a shape of another network, an unknown
attribute) is a ``ValueError`` that names the file, and nothing is loaded.

What is not stored, and why a loaded model still acts and trains as one
loaded from SB3's zip did (``test/test_model_files.py`` compares the two):
- the gradient steps' JAX key (``model.key``): SBX's load seeds it from the
  model's seed (``set_random_seed`` in ``_setup_model``), and so does this
  load; a goal's checkpoint keeps the key in its random state. (A model
  without a seed, which this project never makes, gets another random key.);
- the networks and optimisers themselves (code): rebuilt from the settings.
  SBX makes the entropy coefficient's Adam with the model's learning rate
  when it builds it, and keeps that rate when a goal changes the model's
  (``FineTuning.learning_rate``); the rate is stored
  (``sac_settings.entropy_learning_rate``);
- ``_last_obs`` and ``_last_episode_starts``: SB3's load given an env
  discards them (``force_reset``), and acting without an env never reads
  them;
- the episode statistics (``ep_info_buffer``, ``ep_success_buffer``,
  ``start_time``): SB3 logs them, nothing here reads them;
- the replay buffer: a goal's checkpoint and the prior's keep it beside the
  model (``learner_node.replay_buffer``), as with SB3.
Building the networks takes an example observation and action: they come
from stand-in spaces that give zeros, so loading draws from no random
generator, as SB3's load drew none; the key and the action space are seeded
again with the model's seed after the networks are built, so they are in the
state SB3's load leaves them in.

``load_pickled_model`` reads SB3's zip, the format before this one. It
unpickles, so it runs whatever code the file holds: it is only for ``glocal-ros
policy import --trust``, which converts such a file once.

ROS-free; SBX (and JAX) are imported on first use.
"""

from __future__ import annotations

import json
import zipfile
from pathlib import Path
from typing import Any, BinaryIO

import numpy as np

from glocal_ros.files import read_npz
from learner_node.sac_settings import entropy_learning_rate, sac_algorithm, share_compiled_code

FORMAT = "glocal_ros SAC model"
FORMAT_VERSION = 1
METADATA = "metadata"
#: The only model SBX's SAC this format holds: the policy of ``SAC("MlpPolicy", ...)``.
POLICY = "MlpPolicy"
#: The train states and keys stored as arrays: (owner, attribute) -> the prefix of their arrays' names.
_STATES = {("policy", "actor_state"): "actor_state", ("policy", "qf_state"): "qf_state",
           ("model", "ent_coef_state"): "ent_coef_state", ("policy", "key"): "policy/key",
           ("policy", "noise_key"): "policy/noise_key"}
_SPACES = ("observation_space", "action_space")

_NONE = type(None)
#: SB3's saved attributes that are data, with the JSON types each may have; SB3's load sets them before
#: ``_setup_model``, as this one does.
ATTRIBUTES: dict[str, tuple[type, ...]] = {
    "verbose": (int,), "policy_kwargs": (dict,), "num_timesteps": (int,), "_total_timesteps": (int,),
    "_num_timesteps_at_start": (int,), "seed": (int, _NONE), "learning_rate": (float, int),
    "tensorboard_log": (str, _NONE), "_episode_num": (int,), "use_sde": (bool,), "sde_sample_freq": (int,),
    "_current_progress_remaining": (float, int), "_stats_window_size": (int,), "_n_updates": (int,),
    "n_envs": (int,), "buffer_size": (int,), "batch_size": (int,), "learning_starts": (int,),
    "tau": (float, int), "gamma": (float, int), "gradient_steps": (int,), "optimize_memory_usage": (bool,),
    "replay_buffer_kwargs": (dict,), "n_steps": (int,), "use_sde_at_warmup": (bool,),
    "initial_qf_learning_rate": (float, int, _NONE), "param_resets": (list, _NONE), "reset_idx": (int,),
    "policy_delay": (int,), "ent_coef_init": (str, float, int), "target_entropy": (str, float, int),
}
#: The keyword arguments of SBX's ``SACPolicy`` that are data; others (activation functions, optimiser
#: and network classes) are code, and a model made with them is not stored.
POLICY_KWARGS = ("net_arch", "use_sde", "n_critics", "dropout_rate", "layer_norm", "log_std_init")

Arrays = dict[str, np.ndarray]


# ---------------------------------------------------------------------------------------------- writing

def write_model(model, stream: BinaryIO) -> None:
    """Write ``model`` (SBX's SAC) to ``stream`` as a model file; ``ValueError`` naming what is not storable."""
    arrays, metadata = model_arrays(model)
    text = json.dumps(metadata, allow_nan=False, sort_keys=True)
    np.savez_compressed(stream, **{METADATA: np.array(text)}, **arrays)


def model_arrays(model) -> tuple[Arrays, dict[str, Any]]:
    """The arrays and the metadata of a model file of ``model``."""
    from sbx import SAC
    from sbx.sac.policies import SACPolicy
    from stable_baselines3.common.buffers import ReplayBuffer

    if type(model) is not SAC or type(model.policy) is not SACPolicy:
        raise ValueError(f"only SBX's SAC with its MlpPolicy is stored as data, not {_class_name(model)} "
                         f"with {_class_name(getattr(model, 'policy', None))}")
    if model.action_noise is not None:
        raise ValueError("a model with action noise is not stored: its noise is code")
    if model.replay_buffer_class not in (None, ReplayBuffer):
        raise ValueError(f"a model with replay buffer {model.replay_buffer_class} is not stored: only SB3's "
                         "ReplayBuffer")
    attributes = {name: getattr(model, name) for name in ATTRIBUTES}
    # SBX turns "auto" into numpy's float32, and its load into a float: the value either way.
    if not isinstance(attributes["target_entropy"], str):
        attributes["target_entropy"] = float(attributes["target_entropy"])
    _check_attributes(attributes, "the model")
    arrays: Arrays = {}
    python_scalars, weak_typed = [], []
    for prefix, tree in _state_trees(model).items():
        for name, leaf in _leaves(prefix, tree):
            if name in arrays:  # a key with a "/" in it would make two paths one name
                raise ValueError(f"two leaves of the model's state are both named {name!r}")
            array, python_scalar, weak = _as_array(leaf)
            arrays[name] = array
            if python_scalar:
                python_scalars.append(name)
            if weak:
                weak_typed.append(name)
    spaces = {}
    for space_name in _SPACES:
        space = getattr(model, space_name)
        spaces[space_name] = _space_metadata(space, space_name)
        arrays[f"{space_name}/low"], arrays[f"{space_name}/high"] = np.asarray(space.low), np.asarray(space.high)
    frequency, unit = model.train_freq
    metadata = {"format": FORMAT, "version": FORMAT_VERSION, "algorithm": "sbx.SAC", "policy": POLICY,
                "attributes": attributes, "train_freq": [int(frequency), unit.value], "spaces": spaces,
                "entropy_learning_rate": entropy_learning_rate(model),
                "python_scalars": python_scalars, "weak_typed": weak_typed}
    return arrays, metadata


def _check_attributes(attributes: dict[str, Any], where: str) -> None:
    """``ValueError`` unless ``attributes`` are exactly ``ATTRIBUTES``, each of its types, JSON as it is."""
    if set(attributes) != set(ATTRIBUTES):
        missing, extra = sorted(set(ATTRIBUTES) - set(attributes)), sorted(set(attributes) - set(ATTRIBUTES))
        raise ValueError(f"{where}: attributes missing {missing}, unknown {extra}")
    for name, value in attributes.items():
        if type(value) not in ATTRIBUTES[name]:
            allowed = ", ".join(kind.__name__ for kind in ATTRIBUTES[name])
            raise ValueError(f"{where}: attribute {name} is {value!r} ({type(value).__name__}), not {allowed}")
    unknown = sorted(set(attributes["policy_kwargs"]) - set(POLICY_KWARGS))
    if unknown:
        raise ValueError(f"{where}: policy_kwargs {unknown} are not stored as data (only {', '.join(POLICY_KWARGS)})")
    for name, value in attributes.items():
        try:
            same = json.loads(json.dumps(value, allow_nan=False)) == value
        except (TypeError, ValueError):
            same = False
        if not same:
            raise ValueError(f"{where}: attribute {name} = {value!r} is not plain JSON data")


def _state_trees(model) -> dict[str, Any]:
    """The model's JAX state, by the prefix of its arrays' names."""
    owners = {"policy": model.policy, "model": model}
    return {prefix: getattr(owners[owner], attribute) for (owner, attribute), prefix in _STATES.items()}


def _leaves(prefix: str, tree) -> list[tuple[str, Any]]:
    """``tree``'s leaves, each named by ``prefix`` and its path (``actor_state/params/params/Dense_0/kernel``)."""
    import jax

    return [("/".join([prefix, *(_key_name(key) for key in path)]), leaf)
            for path, leaf in jax.tree_util.tree_flatten_with_path(tree)[0]]


def _key_name(key) -> str:
    for attribute in ("name", "key", "idx"):  # GetAttrKey, DictKey / FlattenedIndexKey, SequenceKey
        if hasattr(key, attribute):
            return str(getattr(key, attribute))
    raise ValueError(f"a JAX tree path of unknown kind: {key!r}")


def _as_array(leaf) -> tuple[np.ndarray, bool, bool]:
    """(the array a leaf is stored as, whether it is a Python scalar, whether it is a weakly typed 0-d array).

    A Python scalar is stored as JAX would make it (an int is int32); a weak type is kept only for 0-d arrays,
    the only weak leaves SBX's states have (steps, the learning rate SBX sets, the entropy coefficient).
    """
    import jax.numpy as jnp

    python_scalar = isinstance(leaf, (bool, int, float))
    array = np.asarray(jnp.asarray(leaf))
    weak = not python_scalar and array.ndim == 0 and bool(getattr(leaf, "weak_type", False))
    return array, python_scalar, weak


def _space_metadata(space, name: str) -> dict[str, Any]:
    from gymnasium import spaces

    if type(space) is not spaces.Box:
        raise ValueError(f"only Box spaces are stored, and the {name} is {space}")
    return {"shape": list(space.shape), "dtype": np.dtype(space.dtype).name}


def _class_name(value) -> str:
    kind = type(value)
    return f"{kind.__module__}.{kind.__qualname__}"


# ---------------------------------------------------------------------------------------------- reading

def load_model(path, env=None):
    """The SAC model in the model file at ``path``, on ``env`` (None: for acting only), as the learner computes
    (``sac_settings.sac_algorithm``, ``share_compiled_code``). ``ValueError`` naming ``path`` when it is not a
    whole model file of this format, or when ``env``'s spaces differ from the model's."""
    path = Path(path)
    arrays, metadata = read_model_file(path)
    try:
        model = _rebuilt(arrays, metadata, env)
        _set_states(model, arrays, metadata)
    except KeyError as error:
        raise ValueError(f"{path}: the metadata lacks {error}") from error
    except (ValueError, TypeError, AssertionError, OverflowError) as error:  # SB3's and SBX's own checks too
        raise ValueError(f"{path}: {error}") from error
    share_compiled_code(model)
    return model


def read_model_file(path: Path) -> tuple[Arrays, dict[str, Any]]:
    """The arrays and the metadata of the model file at ``path``, read without unpickling anything."""
    try:  # SB3's zip is a zip too: say what it is, without reading its pickles
        with zipfile.ZipFile(path) as archive:
            members = archive.namelist()
    except (OSError, zipfile.BadZipFile):
        members = []  # read_npz says what is wrong
    if "data" in members and f"{METADATA}.npy" not in members:
        raise ValueError(f"{path}: {_pickled_zip_message(path)}")
    arrays = read_npz(path)
    if METADATA not in arrays:
        raise ValueError(f"{path}: no metadata: not a model file of this learner")
    text = arrays.pop(METADATA)
    if text.ndim != 0 or text.dtype.kind != "U":
        raise ValueError(f"{path}: metadata is not a string")
    try:
        metadata = json.loads(str(text[()]))
    except ValueError as error:
        raise ValueError(f"{path}: metadata is not JSON ({error})") from error
    if not isinstance(metadata, dict) or (metadata.get("format"), metadata.get("version")) != (FORMAT, FORMAT_VERSION):
        raise ValueError(f"{path}: not a model file of format {FORMAT!r} version {FORMAT_VERSION}")
    return arrays, metadata


def _pickled_zip_message(path: Path) -> str:
    return (f"a stable-baselines3 zip, whose loading unpickles and runs the code it holds: this learner loads only "
            f"its own model files (arrays and JSON). If you trust it, convert a policy with `glocal-ros policy "
            f"import {path} --trust`; for a goal's checkpoint, delete its folder to train the goal again")


def _rebuilt(arrays: Arrays, metadata: dict[str, Any], env):
    """A model of the metadata's settings, its networks and optimisers new: SB3's ``load`` without the pickles.
    Takes the spaces' arrays out of ``arrays``."""
    import jax
    import optax
    from stable_baselines3.common.utils import check_for_correct_spaces

    if (metadata.get("algorithm"), metadata.get("policy")) != ("sbx.SAC", POLICY):
        raise ValueError(f"a model of {metadata.get('algorithm')!r} with {metadata.get('policy')!r}; this learner "
                         f"runs SBX's SAC with {POLICY!r}")
    attributes = dict(metadata["attributes"])
    _check_attributes(attributes, "metadata")
    for name in _SPACES:
        attributes[name] = _space(metadata["spaces"][name], arrays, name)
    SAC = sac_algorithm()
    if env is not None:
        env = SAC._wrap_env(env, attributes["verbose"])
        check_for_correct_spaces(env, attributes["observation_space"], attributes["action_space"])
        attributes["n_envs"] = env.num_envs
    model = SAC(POLICY, env, device="cpu", _init_setup_model=False)
    frequency, unit = metadata["train_freq"]
    # Building the networks takes an example observation and action for their shapes, which SB3's load (the
    # networks unpickled) never drew: stand-ins give zeros, so no random generator moves.
    model.__dict__.update(attributes, train_freq=(frequency, unit),
                          **{name: _stand_in(attributes[name]) for name in _SPACES})
    model._setup_model()
    for owner in (model, model.policy, model.replay_buffer):
        for name in _SPACES:
            setattr(owner, name, attributes[name])
    rate = metadata["entropy_learning_rate"]
    if type(rate) is not float:
        raise ValueError(f"entropy_learning_rate {rate!r} is not a number")
    model.ent_coef_state = model.ent_coef_state.replace(tx=optax.adam(learning_rate=rate))
    if model.seed is not None:
        # As SB3's load leaves them (``set_random_seed`` in ``_setup_model``, which found the unpickled networks
        # there): here building the networks split the key after, and the stand-in action space was seeded.
        model.key = jax.random.PRNGKey(model.seed)
        model.action_space.seed(model.seed)
    return model


def _stand_in(space):
    """A Box of ``space``'s bounds whose samples are zeros, drawn from no generator."""
    from gymnasium import spaces

    class Zeros(spaces.Box):
        def sample(self, *args, **kwargs) -> np.ndarray:
            return np.zeros(self.shape, self.dtype)

    return Zeros(low=space.low, high=space.high, shape=space.shape, dtype=space.dtype)


def _space(described: dict[str, Any], arrays: Arrays, name: str):
    from gymnasium import spaces

    shape, dtype = tuple(described["shape"]), np.dtype(described["dtype"])
    bounds = [arrays.pop(f"{name}/{bound}", None) for bound in ("low", "high")]
    for bound, values in zip(("low", "high"), bounds):
        if values is None or values.shape != shape or values.dtype != dtype:
            found = "missing" if values is None else f"{values.shape} {values.dtype}"
            raise ValueError(f"array '{name}/{bound}' is {found}, the {name} is {shape} {dtype}")
    return spaces.Box(low=bounds[0], high=bounds[1], shape=shape, dtype=dtype)


def _set_states(model, arrays: Arrays, metadata: dict[str, Any]) -> None:
    """Give the rebuilt ``model`` the file's states: every leaf of the fresh states from the array of its name."""
    import jax
    import jax.numpy as jnp

    python_scalars, weak_typed = (_names(metadata, key, arrays) for key in ("python_scalars", "weak_typed"))
    if python_scalars & weak_typed:
        raise ValueError(f"arrays {sorted(python_scalars & weak_typed)} are listed as Python scalars and as weakly "
                         "typed")
    remaining = dict(arrays)
    owners = {"policy": model.policy, "model": model}
    for (owner, attribute), prefix in _STATES.items():
        fresh = getattr(owners[owner], attribute)
        leaves = []
        for name, leaf in _leaves(prefix, fresh):
            if name not in remaining:
                raise ValueError(f"array {name!r} is missing (the network the metadata describes has it)")
            array, expected = remaining.pop(name), np.asarray(jnp.asarray(leaf))
            if (array.shape, array.dtype) != (expected.shape, expected.dtype):
                raise ValueError(f"array {name!r} is {array.shape} {array.dtype}, and the network the metadata "
                                 f"describes has {expected.shape} {expected.dtype}")
            if name in python_scalars:
                leaves.append(array.item())
            elif name in weak_typed:
                leaves.append(_weakly_typed(name, array))
            else:
                leaves.append(jnp.asarray(array))
        setattr(owners[owner], attribute, jax.tree_util.tree_unflatten(jax.tree_util.tree_structure(fresh), leaves))
    if remaining:
        raise ValueError(f"arrays the network the metadata describes does not have: {sorted(remaining)}")


def _names(metadata: dict[str, Any], key: str, arrays: Arrays) -> set[str]:
    """The metadata's list ``key`` of array names; ``ValueError`` unless each is an array of the file."""
    names = metadata[key]
    if not isinstance(names, list) or not all(isinstance(name, str) and name in arrays for name in names):
        raise ValueError(f"{key} is not a list of the file's arrays")
    return set(names)


def _weakly_typed(name: str, array: np.ndarray):
    """A weakly typed 0-d JAX array of ``array``'s value: JAX makes one of a Python scalar."""
    import jax.numpy as jnp

    if array.ndim != 0:
        raise ValueError(f"array {name!r} is listed as weakly typed and is not 0-d")
    weak = jnp.asarray(array.item())
    if weak.dtype != array.dtype:
        raise ValueError(f"array {name!r} is listed as weakly typed and is {array.dtype}, not {weak.dtype}")
    return weak


# -------------------------------------------------------------------------------- the format before this

def saved_policy_module(path) -> str:
    """The module of the policy class an SB3-layout model zip names (``sbx.sac.policies`` for SBX's SAC).

    Reads the zip's JSON only: nothing is unpickled.
    """
    try:
        with zipfile.ZipFile(path) as archive:
            return json.loads(archive.read("data"))["policy_class"]["__module__"]
    except (OSError, KeyError, TypeError, ValueError, zipfile.BadZipFile) as error:
        raise ValueError(f"{path} is not a saved SAC model: {error}") from error


def load_pickled_model(path, env=None):
    """The SAC model in SB3's zip at ``path``: UNPICKLES, so it runs any code the file holds. Only for a file the
    user trusts (``glocal-ros policy import --trust``). ``ValueError`` naming the library that made it when that
    is not the learner's backend."""
    made_by = saved_policy_module(path)
    if not made_by.startswith("sbx."):
        raise ValueError(f"{path} holds a SAC model of {made_by.split('.')[0]!r} ({made_by}); this learner "
                         "runs SBX (sbx-rl): train the policy again with it (a prior: glocal-ros train-prior)")
    model = sac_algorithm().load(path, device="cpu", env=env)
    share_compiled_code(model)
    return model

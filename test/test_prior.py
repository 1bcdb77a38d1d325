"""`learner_node.prior`: the A0 prior trains with the network it is given and resumes only the same network."""

import pytest

from learner_node.prior import PriorConfig, train_prior
from learner_node.sac_settings import NETWORKS
from sim_node.grasp_env import GraspEnv
from sim_node.scripted_grasp import ScriptedGraspPolicy

TINY = dict(demo_episodes=1, max_steps=80, checkpoint_every=40, min_steps=80)


def test_a_prior_has_the_chosen_network_and_resumes_from_its_checkpoint(tmp_path):
    """Real SAC, a few dozen steps: the SB2-sized network and batch, then a resume that adds the steps left."""
    small = NETWORKS["64x64"]
    model = train_prior(lambda: GraspEnv("A0"), ScriptedGraspPolicy().act, tmp_path,
                        PriorConfig(**TINY, network="64x64"))
    assert model.policy_kwargs["net_arch"] == list(small.hidden) and model.batch_size == small.batch_size
    hidden = model.policy.actor_state.params["params"]
    assert [hidden[layer]["kernel"].shape[1] for layer in ("Dense_0", "Dense_1")] == [64, 64]
    assert model.num_timesteps == 80
    assert sorted(path.name for path in tmp_path.iterdir()) == ["checkpoint.npz", "replay_buffer.npz"]

    longer = dict(TINY, max_steps=120, min_steps=120)
    resumed = train_prior(lambda: GraspEnv("A0"), ScriptedGraspPolicy().act, tmp_path,
                          PriorConfig(**longer, network="64x64"))
    assert resumed.num_timesteps == 120 and resumed.batch_size == small.batch_size

    with pytest.raises(ValueError, match="another network"):
        train_prior(lambda: GraspEnv("A0"), ScriptedGraspPolicy().act, tmp_path,
                    PriorConfig(**longer, network="256x256"))


def test_an_unknown_network_is_refused_with_the_choices():
    with pytest.raises(ValueError, match="64x64"):
        PriorConfig(network="32x32")


def test_collected_experience_is_a_function_of_its_seed():
    """The shipped prior sampling its policy on A0: the same seed gives the same transitions, another seed others."""
    import numpy as np

    from glocal_ros.paths import assets_dir
    from learner_node.policy_store import PolicyStore
    from learner_node.prior import collect_experience

    model = PolicyStore(assets_dir() / "priors").load("prior")
    env = GraspEnv("A0")
    try:
        first, again, other = (collect_experience(model, env, 60, seed) for seed in (1, 1, 2))
    finally:
        env.close()
    assert len(first["observations"]) == 60
    for name in first:
        np.testing.assert_array_equal(first[name], again[name])
    assert not np.array_equal(first["actions"], other["actions"])

"""``learner_node.instruments`` on the shipped prior: what each instrument reads when the policy is its parent,
when it has moved, and before a goal has probe states."""

from __future__ import annotations

import math

import jax
import numpy as np
import pytest

from glocal_ros.paths import assets_dir
from learner_node.instruments import PROBE_STATES, GoalInstruments, Instruments, evenly_spread
from learner_node.model_files import load_model
from learner_node.policy_store import PolicyStore
from learner_node.updates import TransitionRing


@pytest.fixture(scope="module")
def prior():
    store = PolicyStore(assets_dir() / "priors")
    return store, store.experience("prior")


def fresh_model(store):
    return load_model(str(store.model_path("prior")))


def test_the_parent_itself_reads_no_distance_and_its_own_value(prior):
    store, experience = prior
    model = fresh_model(store)
    instruments = GoalInstruments(model, experience)
    assert instruments.probes.shape == (PROBE_STATES, experience["observations"].shape[1])
    measured = instruments.measure(model, TransitionRing.for_model(model))
    assert measured.action_distance == pytest.approx(0.0, abs=1e-6)
    assert measured.q_parent_action == pytest.approx(measured.q_current_action)
    assert all(math.isfinite(value) for value in measured.scalars().values())
    assert instruments.measure(model, TransitionRing.for_model(model)) == measured, "the same policy, the same read"


def test_a_moved_actor_reads_a_distance_and_other_values(prior):
    store, experience = prior
    parent, moved = fresh_model(store), fresh_model(store)
    actor = moved.policy.actor_state
    moved.policy.actor_state = actor.replace(params=jax.tree_util.tree_map(lambda w: w * 1.5, actor.params))
    measured = GoalInstruments(parent, experience).measure(moved, TransitionRing.for_model(moved))
    assert measured.action_distance > 0.01
    assert measured.q_current_action != pytest.approx(measured.q_parent_action)
    unmoved = GoalInstruments(parent, experience).measure(parent, TransitionRing.for_model(parent))
    assert measured.q_parent_action == pytest.approx(unmoved.q_parent_action), "the critics did not move"


def test_without_parent_experience_the_goal_takes_its_own_first_transitions(prior):
    store, experience = prior
    model = fresh_model(store)
    instruments = GoalInstruments(model, None)
    ring = TransitionRing.for_model(model)
    ring.add({name: values[:PROBE_STATES - 1] for name, values in experience.items()})
    assert instruments.measure(model, ring) == Instruments(), "NaN until the goal holds enough transitions"
    ring.add({name: values[PROBE_STATES - 1:PROBE_STATES + 9] for name, values in experience.items()})
    assert math.isfinite(instruments.measure(model, ring).action_distance)
    np.testing.assert_array_equal(instruments.probes, evenly_spread(experience["observations"][:PROBE_STATES + 9]))


def test_probes_spread_evenly_over_the_rows():
    rows = np.arange(1000, dtype=np.float32).reshape(-1, 1)
    spread = evenly_spread(rows, 5)
    assert spread[:, 0].tolist() == [0, 250, 500, 749, 999]
    assert len(evenly_spread(rows[:3], 5)) == 3

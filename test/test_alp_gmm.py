import collections

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from glocal_ros.curriculum.alp_gmm import AlpGmmSampler
from glocal_ros.tasks import ALL_TASKS, UnknownTaskError


def run(sampler: AlpGmmSampler, episodes: int, episode_return) -> list[str]:
    """Train ``episodes`` episodes on sampled tasks; ``episode_return(i, task)`` is the outcome."""
    sampled = []
    for i in range(episodes):
        task = sampler.sample()
        sampled.append(task)
        sampler.update(task, episode_return(i, task))
    return sampled


def row_a_improves(episodes: int):
    """Row A gets better over the run, every other task stays at one return: ALP only in row A."""
    return lambda i, task: -50.0 + 50.0 * i / episodes if task[0] == "A" else -40.0


def test_same_seed_and_updates_give_same_samples():
    def trace(seed):
        sampler = AlpGmmSampler(ALL_TASKS, fit_rate=10, seed=seed, k_max=4)
        return run(sampler, 60, lambda i, task: -50.0 + (i * 7 + ord(task[0])) % 50)

    assert trace(3) == trace(3)
    assert trace(3) != trace(4)


def test_samples_before_first_fit_are_uniform():
    sampler = AlpGmmSampler(ALL_TASKS, fit_rate=10**6, seed=0)
    counts = collections.Counter(sampler.sample() for _ in range(100 * len(ALL_TASKS)))
    assert set(counts) == set(ALL_TASKS)
    assert all(50 <= n <= 150 for n in counts.values())  # expected 100, sd ~10


def test_sampling_concentrates_where_returns_improve():
    sampler = AlpGmmSampler(ALL_TASKS, fit_rate=25, seed=0, history_size=100, k_max=5)
    sampled = run(sampler, 300, row_a_improves(300))
    late = sampled[150:]
    share_a = sum(task[0] == "A" for task in late) / len(late)
    assert share_a > 0.4  # uniform would give 1/7; seeds 0..7 give 0.53..0.89


def test_random_fraction_one_stays_uniform_after_fits():
    sampler = AlpGmmSampler(ALL_TASKS, fit_rate=25, seed=0, history_size=100, k_max=5, random_fraction=1.0)
    run(sampler, 300, row_a_improves(300))
    assert sampler.fitted
    counts = collections.Counter(sampler.sample()[0] for _ in range(7000))
    assert all(800 <= n <= 1200 for n in counts.values())  # 1000 per row expected, sd ~30


@settings(max_examples=25, deadline=None)
@given(
    tasks=st.lists(st.sampled_from(ALL_TASKS), min_size=1, max_size=12),
    returns=st.lists(st.floats(-200.0, 50.0), min_size=1, max_size=30),
    seed=st.integers(0, 2**32 - 1),
)
def test_samples_are_always_among_the_tasks(tasks, returns, seed):
    sampler = AlpGmmSampler(tasks, fit_rate=4, seed=seed, k_max=4, random_fraction=0.1)
    for episode_return in returns:
        task = sampler.sample()
        assert task in tasks
        sampler.update(task, episode_return)
    assert all(sampler.sample() in tasks for _ in range(20))
    assert all(0.0 <= alp <= 1.0 for alp in sampler.alps)


def test_alp_is_return_change_to_nearest_earlier_episode():
    sampler = AlpGmmSampler(["A0", "A1", "A2", "G6"], fit_rate=100)
    sampler.update("A0", -50.0)  # 0.0, first episode ever
    sampler.update("A0", -40.0)  # 0.2, same task: its latest earlier episode (0.0)
    sampler.update("A2", -10.0)  # 0.8, nearest played task is A0 (0.2)
    sampler.update("A1", -25.0)  # 0.5, A0 and A2 equally near: the more recent A2 (0.8)
    sampler.update("A1", -100.0)  # clipped to 0.0, same task (0.5)
    sampler.update("G6", 10.0)  # clipped to 1.0, nearest is A2 (0.8)
    assert sampler.alps == pytest.approx((0.0, 0.2, 0.6, 0.3, 0.5, 0.2))


def test_refits_exactly_every_fit_rate_updates(monkeypatch):
    sampler = AlpGmmSampler(ALL_TASKS, fit_rate=5, seed=0, k_max=3)
    refits = []
    original = sampler._refit
    monkeypatch.setattr(sampler, "_refit", lambda: refits.append(len(sampler.alps)) or original())
    for i in range(1, 16):
        sampler.update(ALL_TASKS[i % 3], -float(i))
        assert sampler.fitted == (i >= 5)
    assert refits == [5, 10, 15]


def test_history_size_bounds_what_a_fit_sees():
    sampler = AlpGmmSampler(["A0", "B0"], fit_rate=3, history_size=4)
    for i in range(9):
        sampler.update("A0" if i % 2 else "B0", -float(i))
    assert len(sampler._rows) == 4


def test_bad_input_is_rejected():
    with pytest.raises(ValueError):
        AlpGmmSampler([], fit_rate=10)
    with pytest.raises(UnknownTaskError):
        AlpGmmSampler(["A0", "H9"], fit_rate=10)
    for fit_rate in (0, -3):
        with pytest.raises(ValueError):
            AlpGmmSampler(ALL_TASKS, fit_rate=fit_rate)
    with pytest.raises(ValueError):
        AlpGmmSampler(ALL_TASKS, fit_rate=10, random_fraction=1.5)
    with pytest.raises(ValueError):
        AlpGmmSampler(ALL_TASKS, fit_rate=10, k_min=5, k_max=3)
    with pytest.raises(ValueError):
        AlpGmmSampler(ALL_TASKS, fit_rate=10, min_return=0.0, max_return=0.0)

    sampler = AlpGmmSampler(["A0", "A1"], fit_rate=10)
    with pytest.raises(UnknownTaskError):
        sampler.update("Z7", -10.0)
    with pytest.raises(ValueError):
        sampler.update("B0", -10.0)  # on the grid, but not a task of this run
    with pytest.raises(ValueError):
        sampler.update("A0", float("nan"))
    assert sampler.alps == ()

"""ProcessBatchedEnvs: the same batch, stepped by worker processes."""

import numpy as np
import pytest

from glocal_ros.paths import objects_dir
from glocal_ros.tasks import UnknownTaskError
from sim_node.batch import BatchedEnvs
from sim_node.grasp_env import GraspEnv, GraspEnvConfig
from sim_node.parallel import ProcessBatchedEnvs, split

T = 3
CONFIG = GraspEnvConfig(max_steps=T)


def test_split_is_even_and_consecutive():
    assert split(5, 2) == [range(0, 2), range(2, 5)]
    assert split(2, 4) == [range(0, 1), range(1, 2)]
    assert sum(len(r) for r in split(7, 3)) == 7


@pytest.fixture(scope="module")
def batches():
    parallel = ProcessBatchedEnvs(3, 2, "A0", str(objects_dir()), CONFIG)
    serial = BatchedEnvs(lambda i: GraspEnv("A0", config=CONFIG), 3)
    yield parallel, serial
    parallel.close()
    serial.close()


def test_workers_match_one_process_step_for_step(batches):
    parallel, serial = batches
    rng = np.random.default_rng(0)
    first = [b.reset(tasks=["A0", "B1", "C2"], seeds=[5])[0] for b in batches]
    np.testing.assert_array_equal(first[0], first[1])
    for k in range(2 * T):
        actions = rng.uniform(-1, 1, (3, 5)).astype(np.float32)
        results = [b.step(actions, next_tasks=["D3", "", ""], global_step=k) for b in batches]
        np.testing.assert_array_equal(results[0].observations, results[1].observations)
        np.testing.assert_array_equal(results[0].terminal_observations, results[1].terminal_observations)
        assert results[0].tasks == results[1].tasks
        assert [(log.env_index, log.task, log.length) for log in results[0].finished] == \
               [(log.env_index, log.task, log.length) for log in results[1].finished]
    assert parallel.tasks == ["D3", "B1", "C2"]
    assert parallel.snapshot(2).task == "C2"


def test_a_step_of_some_envs_moves_only_them_in_the_order_named_in_workers_or_not(batches):
    """Envs 2 and 0 (one in each worker) step, in that order, for a whole episode; env 1 waits where it was."""
    rng = np.random.default_rng(1)
    for batch in batches:
        batch.reset(tasks=["A0", "B1", "C2"], seeds=[3])
    waiting = [b.snapshot(1).joint_positions for b in batches]
    for k in range(T):
        actions = rng.uniform(-1, 1, (2, 5)).astype(np.float32)
        results = [b.step(actions, next_tasks=["E4", ""], global_step=k, env_indices=[2, 0]) for b in batches]
        for result in results:
            assert result.observations.shape == (2, 63) and len(result.tasks) == 2
        np.testing.assert_array_equal(results[0].observations, results[1].observations)
        assert results[0].tasks == results[1].tasks
        assert [(log.env_index, log.task) for log in results[0].finished] == \
               [(log.env_index, log.task) for log in results[1].finished]
    assert results[0].tasks == ["E4", "A0"]  # env 2's episode ended at T: it runs its next task now
    for batch, before in zip(batches, waiting):
        assert batch.tasks == ["A0", "B1", "E4"]
        np.testing.assert_array_equal(batch.snapshot(1).joint_positions, before)
    with pytest.raises(ValueError, match="out of range"):
        batches[0].step(np.zeros((1, 5), dtype=np.float32), env_indices=[3])
    with pytest.raises(ValueError, match="repeat"):
        batches[0].step(np.zeros((2, 5), dtype=np.float32), env_indices=[1, 1])
    with pytest.raises(ValueError, match="expected 10 action values"):
        batches[0].step(np.zeros((3, 5), dtype=np.float32), env_indices=[0, 1])


def test_partial_reset_and_bad_requests(batches):
    parallel, _ = batches
    parallel.step(np.zeros((3, 5), dtype=np.float32))
    observations, interrupted = parallel.reset(env_indices=[2, 0], tasks=["E4", "A1"])
    assert observations.shape == (2, 63)
    assert sorted(log.env_index for log in interrupted) == [0, 2]
    assert parallel.tasks[0] == "A1" and parallel.tasks[2] == "E4"
    with pytest.raises(UnknownTaskError):
        parallel.reset(tasks=["A9"])
    with pytest.raises(ValueError, match="NaN"):
        parallel.step(np.full((3, 5), np.nan, dtype=np.float32))
    assert parallel.step(np.zeros((3, 5), dtype=np.float32)).observations.shape == (3, 63)


def test_a_seeded_batch_repeats_its_episodes_without_seeded_resets():
    """sim_node's ``seed``: only the first episodes are seeded, the rest follow, in workers or not."""

    def episodes(batch) -> list[np.ndarray]:
        try:
            seen = [batch.reset(tasks=["A0", "B1", "C2"])[0]]
            for _ in range(T):  # through one automatic reset
                seen.append(batch.step(np.zeros((3, 5), dtype=np.float32), next_tasks=["D3", "", ""]).observations)
            seen.append(batch.reset()[0])
            return seen
        finally:
            batch.close()

    parallel = episodes(ProcessBatchedEnvs(3, 2, "A0", str(objects_dir()), CONFIG, seed=7))
    serial = episodes(BatchedEnvs(lambda i: GraspEnv("A0", config=CONFIG), 3, seed=7))
    other_seed = episodes(BatchedEnvs(lambda i: GraspEnv("A0", config=CONFIG), 3, seed=8))
    for a, b in zip(parallel, serial):
        np.testing.assert_array_equal(a, b)
    assert not np.array_equal(serial[-1], other_seed[-1])

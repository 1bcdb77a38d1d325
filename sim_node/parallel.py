"""A batch of envs split over worker processes that step their shares in parallel.

``ProcessBatchedEnvs`` has the interface of ``BatchedEnvs`` (a
``glocal_ros.sim_contract.BatchStepper``). Requests are
checked whole in this process (``normalize_reset``, ``normalize_step``)
before any worker acts, so a malformed request changes nothing; each worker
holds a ``BatchedEnvs`` of consecutive envs and applies its share. Workers
are started with ``spawn``: the parent may already run DDS threads, which a
fork would copy in an undefined state.
"""

from __future__ import annotations

import functools
import multiprocessing as mp
import signal
from typing import Sequence

import numpy as np

from glocal_ros.sim_contract import PHASE_TRAIN, FinishStep, StepBatch
from glocal_ros.tasks import check_task
from sim_node.batch import BatchedEnvs, EnvSnapshot, normalize_reset, normalize_step
from sim_node.grasp_env import GraspEnv, GraspEnvConfig


def _worker(connection, first_index: int, num_envs: int, initial_task: str, objects_dir: str,
            config: GraspEnvConfig, gui_index: int, seed: int | None) -> None:
    # Ctrl-C reaches the whole process group; the parent decides when workers stop.
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    batch = BatchedEnvs(
        lambda i: GraspEnv(initial_task, objects_dir, config, render_mode="human" if i == gui_index else None),
        num_envs, initial_task, first_index, seed,
    )
    connection.send((True, (batch.obs_dim, batch.action_dim, batch.joint_names)))
    try:
        while True:
            command, args = connection.recv()
            if command == "close":
                break
            try:
                connection.send((True, getattr(batch, command)(*args)))
            except Exception as error:  # noqa: BLE001 - reported to the parent, which raises it
                connection.send((False, f"{type(error).__name__}: {error}"))
    except EOFError:
        pass  # the parent went away
    finally:
        batch.close()


def split(num_envs: int, workers: int) -> list[range]:
    """Consecutive env index ranges, as even as possible."""
    bounds = np.linspace(0, num_envs, workers + 1).round().astype(int)
    return [range(a, b) for a, b in zip(bounds, bounds[1:]) if b > a]


class ProcessBatchedEnvs:
    """``num_envs`` envs over ``workers`` processes; ``first_index`` numbers them from there in episode logs (an
    evaluation batch beside a training one), and ``seed`` seeds them as ``BatchedEnvs`` does."""

    def __init__(self, num_envs: int, workers: int, initial_task: str, objects_dir: str,
                 config: GraspEnvConfig, gui: bool = False, seed: int | None = None, first_index: int = 0):
        check_task(initial_task)  # a clear error here, not a worker dying at start-up
        self.first_index = first_index
        context = mp.get_context("spawn")
        self.shares = split(num_envs, workers)
        self._connections = []
        self._processes = []
        for share in self.shares:
            parent, child = context.Pipe()
            process = context.Process(
                target=_worker, name=f"sim-worker-{share.start}", daemon=True,
                args=(child, first_index + share.start, len(share), initial_task, objects_dir, config,
                      first_index if gui else -1, seed),
            )
            process.start()
            self._connections.append(parent)
            self._processes.append(process)
        self.obs_dim, self.action_dim, self.joint_names = [self._receive(w) for w in range(len(self.shares))][0]
        self.tasks = [initial_task] * num_envs

    @property
    def num_envs(self) -> int:
        return len(self.tasks)

    def reset(self, env_indices: Sequence[int] = (), tasks: Sequence[str] = (), seeds: Sequence[int] = (),
              phase: int = PHASE_TRAIN, policy_name: str = ""):
        indices, per_env_tasks, per_env_seeds = normalize_reset(self.num_envs, env_indices, tasks, seeds, phase)
        involved = []
        for worker, share in enumerate(self.shares):
            rows = [row for row, index in enumerate(indices) if index in share]
            if rows:
                local = [indices[r] - share.start for r in rows]
                self._send(worker, "apply_reset", (local, [per_env_tasks[r] for r in rows],
                                                   [per_env_seeds[r] for r in rows], phase, policy_name))
                involved.append((worker, rows))
        observations = np.empty((len(indices), self.obs_dim), dtype=np.float32)
        interrupted = []
        for worker, rows in involved:
            worker_observations, worker_interrupted = self._receive(worker)
            observations[rows] = worker_observations
            interrupted += worker_interrupted
        for index, task in zip(indices, per_env_tasks):
            if task is not None:
                self.tasks[index] = task
        return observations, sorted(interrupted, key=lambda log: log.env_index)

    def step(self, actions: np.ndarray, next_tasks: Sequence[str] = (), phase: int = PHASE_TRAIN,
             policy_name: str = "", global_step: int = 0, env_indices: Sequence[int] = ()) -> StepBatch:
        indices, actions, next_tasks = normalize_step(self.num_envs, self.action_dim, actions, next_tasks, phase,
                                                      env_indices)
        involved = []  # (worker, rows of the request it steps)
        for worker, share in enumerate(self.shares):
            rows = [row for row, index in enumerate(indices) if index in share]
            if rows:
                self._send(worker, "apply_step", (actions[rows], [next_tasks[r] for r in rows], phase, policy_name,
                                                  global_step, [indices[r] - share.start for r in rows]))
                involved.append((worker, rows))
        parts: list[tuple[list[int], StepBatch]] = [(rows, self._receive(worker)) for worker, rows in involved]
        order = np.argsort(np.concatenate([rows for rows, _ in parts]), kind="stable")  # back to the request's
        result = StepBatch(
            observations=np.concatenate([p.observations for _, p in parts])[order],
            rewards=np.concatenate([p.rewards for _, p in parts])[order],
            terminated=np.concatenate([p.terminated for _, p in parts])[order],
            truncated=np.concatenate([p.truncated for _, p in parts])[order],
            is_success=np.concatenate([p.is_success for _, p in parts])[order],
            terminal_observations=np.concatenate([p.terminal_observations for _, p in parts])[order],
            tasks=[task for _, p in parts for task in p.tasks],
            finished=[log for _, p in parts for log in p.finished],
        )
        result.tasks = [result.tasks[r] for r in order]
        row_of = {self.first_index + index: row for row, index in enumerate(indices)}
        result.finished.sort(key=lambda log: row_of[log.env_index])  # as one process lists them
        for index, task in zip(indices, result.tasks):
            self.tasks[index] = task
        return result

    def start_step(self, actions: np.ndarray, next_tasks: Sequence[str] = (), phase: int = PHASE_TRAIN,
                   policy_name: str = "", global_step: int = 0, env_indices: Sequence[int] = ()) -> FinishStep:
        """``step``, run when the returned function is called, as ``BatchedEnvs.start_step`` does."""
        return functools.partial(self.step, actions, next_tasks, phase, policy_name, global_step, env_indices)

    def snapshot(self, index: int) -> EnvSnapshot:
        worker = next(w for w, share in enumerate(self.shares) if index in share)
        self._send(worker, "snapshot", (index - self.shares[worker].start,))
        return self._receive(worker)

    def close(self) -> None:
        for connection in self._connections:
            try:
                connection.send(("close", ()))
            except (BrokenPipeError, OSError):
                pass
        for process in self._processes:
            process.join(10)
            if process.is_alive():
                process.kill()

    def _send(self, worker: int, command: str, args: tuple) -> None:
        self._connections[worker].send((command, args))

    def _receive(self, worker: int):
        try:
            ok, value = self._connections[worker].recv()
        except EOFError:
            raise RuntimeError(f"sim worker {worker} exited (exit code {self._processes[worker].exitcode})") from None
        if not ok:
            raise RuntimeError(f"sim worker {worker} failed: {value}")
        return value

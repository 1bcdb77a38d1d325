"""``glocal-ros experiment --ray ADDRESS`` (and ``bench curriculum --ray``): the runs of an experiment as Ray tasks.

The contract:

- Each (strategy, seed) run that OUT does not hold finished is one Ray task
  that reserves ``cpus_per_run`` CPUs (``DEFAULT_CPUS_PER_RUN``: the learner's
  SAC thread and the sim; the recorder and the curriculum mostly wait) and
  starts its own graph with ``experiment.launch_run``, the function a local
  experiment calls, so both start the same nodes with the same parameters.
- Its ROS domain is unique on its node: the task drops any ``ROS_DOMAIN_ID``
  the worker inherited, so ``launch`` reserves a free one there
  (``glocal_ros.domain``: a held loopback port per domain id, which two tasks
  on one node cannot both hold) and keeps discovery on loopback
  (``ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST``). Runs on different nodes may
  share an id; they never discover each other.
- Results travel through Ray, not through a shared filesystem: a task runs
  its run in a temporary folder of its node and returns the run directory as
  a tar archive (``pack_run``; about 9 MB for a smoke run, mostly the stored
  policies and their experience), which the driver unpacks into
  ``OUT/<strategy>-seed<N>/`` as the run ends (``unpack_run``: whole or not
  at all). Nodes need the project at the same path (``make setup``), not a
  shared OUT.
- Finished runs are skipped: they are never sent. A run that OUT holds
  unfinished (an earlier launch, here or on Ray, was stopped or stalled) is
  sent with its task and resumes from its journal on the node; what comes
  back replaces it. A run that fails or stalls on its node comes back too, as
  far as it got, and the same command resumes it. A run whose task is lost
  (the driver interrupted, the node gone) leaves OUT as it was: its work on
  the node since this command started is lost, and the same command starts
  it again from what OUT holds.
- ``RayCluster.connect`` refuses, before any run starts, an address where no
  Ray cluster answers (a TCP connect to its GCS port, ``CONNECT_TIMEOUT_SEC``,
  instead of ``ray.init``'s long retries) and a cluster none of whose nodes
  has the CPUs one run needs. ``local`` starts a Ray instance on this machine
  with all its CPUs, for tests and for several runs at once on one large
  machine.

Ray is imported only here, and only when an experiment asks for it: the
command line and the nodes do not pay for its import.
"""

from __future__ import annotations

import io
import os
import shutil
import signal
import socket
import tarfile
import tempfile
import time
import traceback
from contextlib import redirect_stderr, redirect_stdout
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Iterator, Sequence

if TYPE_CHECKING:
    from glocal_app.experiment import PlannedRun
    from glocal_app.processes import RunOptions

#: CPUs a run reserves unless told (``--ray-cpus-per-run``).
DEFAULT_CPUS_PER_RUN = 2
#: The address that starts a Ray instance on this machine instead of joining a cluster.
LOCAL = "local"
#: The port of a Ray head's GCS when an address gives none (``ray start --head``'s default).
DEFAULT_GCS_PORT = 6379
CONNECT_TIMEOUT_SEC = 5.0
#: How long an interrupted experiment waits for its cancelled tasks to stop their graphs cleanly.
CANCEL_WAIT_SEC = 60.0


def parse_address(address: str) -> tuple[str, int]:
    """``(host, port)`` of ``HOST[:PORT]``; ``ValueError`` for anything else (``ray://`` included)."""
    if "://" in address:
        raise ValueError(f"--ray {address}: give the Ray head's HOST:PORT (its GCS port, {DEFAULT_GCS_PORT} by "
                         f"default) or {LOCAL}, and run the command on a node of the cluster (Ray Client "
                         f"addresses are not supported)")
    host, _, port = address.rpartition(":") if ":" in address else (address, "", str(DEFAULT_GCS_PORT))
    if not host or not port.isdigit() or not 0 < int(port) < 65536:
        raise ValueError(f"--ray {address!r}: expected HOST:PORT of a Ray head (e.g. 10.0.0.5:{DEFAULT_GCS_PORT}) "
                         f"or {LOCAL}")
    return host, int(port)


def check_reachable(address: str, timeout: float = CONNECT_TIMEOUT_SEC) -> None:
    """``ValueError`` naming ``address`` unless something accepts a TCP connection on its GCS port."""
    host, port = parse_address(address)
    try:
        socket.create_connection((host, port), timeout=timeout).close()
    except OSError as error:
        raise ValueError(f"no Ray cluster answers at {address} ({error or 'timed out'}): start one with "
                         f"`.venv/bin/ray start --head` on {host}, or give --ray {LOCAL} for one on this "
                         f"machine") from None


def largest_node_cpus(nodes: Sequence[dict]) -> float:
    """The most CPUs one live node of ``ray.nodes()`` offers (0 when none)."""
    return max((node.get("Resources", {}).get("CPU", 0.0) for node in nodes if node.get("Alive")), default=0.0)


@dataclass(frozen=True)
class RunResult:
    """What a run's task sends back: its exit code, its run directory (``pack_run``), where and how long it ran."""

    code: int
    archive: bytes
    node: str
    seconds: float
    log: str  # the launch's own output, relative to the run directory


def pack_run(run_dir: Path) -> bytes:
    """``run_dir`` as an uncompressed tar archive whose one top folder is its name (bags are compressed already)."""
    stream = io.BytesIO()
    with tarfile.open(fileobj=stream, mode="w") as tar:
        tar.add(run_dir, arcname=run_dir.name)
    return stream.getvalue()


def unpack_run(archive: bytes, run_dir: Path) -> None:
    """Put the run of ``archive`` (``pack_run``) at ``run_dir``, replacing what was there.

    Unpacked beside, in a folder whose name starts with a dot (``bench_run_dirs`` skips those), and
    renamed in: ``run_dir`` is the old run or the new one, never a mix.
    """
    run_dir.parent.mkdir(parents=True, exist_ok=True)
    staging = Path(tempfile.mkdtemp(prefix=f".{run_dir.name}.", dir=run_dir.parent))
    try:
        with tarfile.open(fileobj=io.BytesIO(archive), mode="r") as tar:
            names = {member.name.split("/", 1)[0] for member in tar.getmembers()}
            if names != {run_dir.name}:
                raise ValueError(f"an archive of {sorted(names)} is not the run {run_dir.name}")
            tar.extractall(staging, filter="data")
        if run_dir.exists():
            run_dir.rename(staging / ".replaced")
        (staging / run_dir.name).rename(run_dir)
    finally:
        shutil.rmtree(staging, ignore_errors=True)


def run_task(strategy: str, seed: int, name: str, archive: bytes | None, options: RunOptions) -> RunResult:
    """The body of a run's Ray task, on its node: the run (resumed from ``archive`` if any) in a temporary folder.

    The launch's output goes to ``logs/launch-<time>.log`` in the run directory, which comes back
    with it; an exception is written there too and counts as exit code 1.
    """
    from glocal_app.experiment import launch_run

    started = time.monotonic()
    work = Path(tempfile.mkdtemp(prefix="glocal-ros-ray-"))
    try:
        run_dir = work / name
        if archive is not None:
            unpack_run(archive, run_dir)
        # A free domain of this node, discovery on loopback: never the domain the worker inherited.
        os.environ.pop("ROS_DOMAIN_ID", None)
        os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
        log = Path("logs") / f"launch-{time.strftime('%Y%m%d-%H%M%S')}.log"
        (run_dir / log).parent.mkdir(parents=True, exist_ok=True)
        # Ray blocks SIGINT in its workers (it cancels a task without a signal), and a child inherits
        # the mask: unblocked, the nodes stop cleanly on the SIGINT the launch sends them at the end.
        blocked = signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGINT})
        with open(run_dir / log, "w") as stream, redirect_stdout(stream), redirect_stderr(stream):
            try:
                code = launch_run(strategy, seed, run_dir, options)
            except Exception:  # noqa: BLE001 - the run's log says what, the driver that it failed
                traceback.print_exc()
                code = 1
            finally:
                signal.pthread_sigmask(signal.SIG_SETMASK, blocked)
        return RunResult(code, pack_run(run_dir), socket.gethostname(), time.monotonic() - started, str(log))
    finally:
        shutil.rmtree(work, ignore_errors=True)


class RayCluster:
    """A connection to a Ray cluster (or a local instance) that runs an experiment's runs as tasks."""

    def __init__(self, address: str, cpus_per_run: int):
        self.address = address
        self.cpus_per_run = cpus_per_run

    @classmethod
    def connect(cls, address: str, cpus_per_run: int | None = None) -> RayCluster:
        """Join the cluster at ``address`` (``HOST:PORT``) or start one here (``local``).

        ``ValueError`` before any run starts: no cluster answers there, or none of its nodes has
        ``cpus_per_run`` CPUs (the cluster is let go first).
        """
        cpus_per_run = DEFAULT_CPUS_PER_RUN if cpus_per_run is None else cpus_per_run
        if cpus_per_run < 1:
            raise ValueError(f"--ray-cpus-per-run must be at least 1, got {cpus_per_run}")
        if address != LOCAL:
            check_reachable(address)
        import ray

        if address == LOCAL:
            ray.init(address="local", num_cpus=os.cpu_count(), include_dashboard=False)
        else:
            try:
                ray.init(address=address)
            except (ConnectionError, RuntimeError) as error:  # e.g. another Ray version, another token
                raise ValueError(f"could not join the Ray cluster at {address}: {error}") from None
        cluster = cls(address, cpus_per_run)
        largest = largest_node_cpus(ray.nodes())
        if largest < cpus_per_run:
            cluster.close()
            where = "this machine's Ray instance" if address == LOCAL else f"the Ray cluster at {address}"
            raise ValueError(f"{where} has at most {largest:g} CPUs on a node, fewer than the {cpus_per_run} one run "
                             f"needs (--ray-cpus-per-run): add larger nodes or ask for fewer CPUs per run")
        print(f"Ray: {address}, {len([n for n in ray.nodes() if n.get('Alive')])} node(s), "
              f"{ray.cluster_resources().get('CPU', 0):g} CPUs; {cpus_per_run} CPUs per run", flush=True)
        return cluster

    def run(self, runs: Sequence[PlannedRun], options: RunOptions) -> Iterator[tuple[Path, int]]:
        """Each run as a task; as each ends, its directory is back in place and ``(run_dir, exit code)`` is yielded.

        A task that Ray could not run (its node lost, the worker killed) counts as exit code 1 and
        leaves its run directory as it was. Interrupted (Ctrl-C), the tasks still running are
        cancelled (each stops its graph as Ctrl-C stops a launch) and ``KeyboardInterrupt`` goes on.
        """
        import ray

        # As ``launch`` does: Ctrl-C and SIGTERM interrupt, also where SIGINT came ignored (a script's
        # background job); the tasks are then cancelled below.
        signal.signal(signal.SIGINT, signal.default_int_handler)
        signal.signal(signal.SIGTERM, signal.default_int_handler)
        task = ray.remote(num_cpus=self.cpus_per_run, max_calls=1)(run_task)
        pending = {}
        try:
            for strategy, seed, run_dir in runs:
                archive = pack_run(run_dir) if run_dir.exists() else None
                pending[task.remote(strategy, seed, run_dir.name, archive, options)] = run_dir
                print(f"{run_dir.name}: sent to Ray{' with its run directory (resumes)' if archive else ''}",
                      flush=True)
            while pending:
                [ready], _ = ray.wait(list(pending), num_returns=1)
                run_dir = pending.pop(ready)
                yield run_dir, self._bring_back(ready, run_dir)
        except KeyboardInterrupt:
            for reference in pending:
                ray.cancel(reference)
            ray.wait(list(pending), num_returns=len(pending), timeout=CANCEL_WAIT_SEC)
            raise

    @staticmethod
    def _bring_back(reference, run_dir: Path) -> int:
        import ray

        try:
            result: RunResult = ray.get(reference)
        except ray.exceptions.RayError as error:
            print(f"{run_dir.name}: its Ray task failed ({type(error).__name__}: {str(error).splitlines()[0]}); "
                  f"{run_dir} is as it was", flush=True)
            return 1
        unpack_run(result.archive, run_dir)
        code = 1 if result.code == 130 else result.code  # 130 there: its node stopped it, not this command's Ctrl-C
        print(f"{run_dir.name}: exit code {result.code} on {result.node} after {result.seconds / 60:.1f} min, "
              f"{len(result.archive) / 1e6:.1f} MB back; its output: {run_dir / result.log}", flush=True)
        return code

    def close(self) -> None:
        import ray

        ray.shutdown()

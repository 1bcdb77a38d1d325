"""Fixtures shared by the suite: an isolated ROS domain, node processes, a test node.

Every pytest run takes a ROS_DOMAIN_ID that no other run on this machine
holds (``glocal_ros.domain``) and keeps discovery on loopback, so parallel
runs never see each other.
"""

from __future__ import annotations

import os
import socket
import sys
import tempfile
import time
from contextlib import contextmanager
from pathlib import Path
from typing import Callable, Iterator

import pytest

from glocal_app.processes import NodeProcess
from glocal_ros.domain import reserve_domain_id
from node_common.runner import configure_discovery

REPO = Path(__file__).resolve().parent.parent
#: The smoke preset's parameter file: the nodes' parameters of the suite's runs.
SMOKE = REPO / "assets" / "params" / "smoke.yaml"


def smoke_tasks() -> list[str]:
    """The tasks of the smoke preset, sorted, as its file names them."""
    import yaml

    params = yaml.safe_load(SMOKE.read_text())
    return sorted(params["/**/curriculum_node"]["ros__parameters"]["tasks"].split(","))

_DOMAIN_ID, _DOMAIN_LOCK = reserve_domain_id()
os.environ["ROS_DOMAIN_ID"] = str(_DOMAIN_ID)
os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
configure_discovery()  # the loopback profile, for the suite's own participants as for the nodes'
os.environ["ROS_LOG_DIR"] = tempfile.mkdtemp(prefix="glocal-ros-log-")
# Nodes keep policies and curriculum journals under ROS_HOME by default: never the user's.
os.environ["ROS_HOME"] = tempfile.mkdtemp(prefix="glocal-ros-home-")
os.environ.setdefault("AMENT_PREFIX_PATH", sys.prefix)
os.environ["PYTHONUNBUFFERED"] = "1"
# rclpy checks message field types only when asked (off by default in Jazzy); unchecked, an int in a
# float32 field reaches the C conversion and is sent as 0.0. Tests and the nodes they start check.
os.environ["ROS_PYTHON_CHECK_FIELDS"] = "1"


def pytest_sessionfinish(session, exitstatus):
    _DOMAIN_LOCK.close()


@contextmanager
def node_starter(log_dir: Path) -> Iterator[Callable[..., NodeProcess]]:
    """``start(name, **params)`` starts a node process; all are stopped when the block ends."""
    started: list[NodeProcess] = []

    def start(node: str, extra_args: tuple[str, ...] = (), **params) -> NodeProcess:
        process = NodeProcess(node, log_dir, params, extra_args=extra_args, cwd=REPO)
        started.append(process)
        return process

    try:
        yield start
    finally:
        for process in reversed(started):
            process.stop()


def spun_test_node():
    """An rclpy node of the test itself, spun by a background executor, on this run's domain."""
    from node_common.runner import spinning_node

    return spinning_node(f"test_{os.getpid()}", int(os.environ["ROS_DOMAIN_ID"]), num_threads=4)


@pytest.fixture
def start_node(tmp_path):
    """``start_node(name, **params)`` starts a node process; all are stopped after the test."""
    with node_starter(tmp_path) as start:
        yield start


@pytest.fixture
def ros_node():
    """An rclpy node of the test itself, spun by a background executor."""
    with spun_test_node() as node:
        yield node


def wait_until(predicate, timeout: float, what: str, poll: float = 0.05, processes=()):
    """Poll ``predicate`` until it is truthy; fail with ``what`` and the node logs on time-out."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        value = predicate()
        if value:
            return value
        for process in processes:
            if process.process.poll() is not None:
                pytest.fail(f"{process.node} exited with {process.process.returncode} while waiting for {what}:\n"
                            f"{process.log()}")
        time.sleep(poll)
    logs = "\n".join(f"--- {p.node} ---\n{p.log()}" for p in processes)
    pytest.fail(f"timed out after {timeout} s waiting for {what}\n{logs}")


def free_port() -> int:
    """A loopback port nothing listens on (bound, then let go)."""
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return probe.getsockname()[1]


def journal_lines(state_dir: Path) -> list[str]:
    """The lines of a curriculum node's journal in ``state_dir`` (none before it is written)."""
    path = state_dir / "journal.jsonl"
    return path.read_text().splitlines() if path.is_file() else []


def wait_for_clean_exit(node: NodeProcess, timeout: float, processes=()) -> None:
    """Wait for ``node`` (a curriculum run) to end, failing on ``processes`` ending first; it must exit 0."""
    wait_until(lambda: node.process.poll() is not None, timeout, "the end of the run", processes=processes)
    assert node.process.returncode == 0, node.log()


def answers(client, request, timeout: float = 5.0) -> bool:
    """Whether ``client``'s service answers ``request`` within ``timeout``.

    A client can see a service as ready before the server has matched the
    client's response reader; a request sent then is answered into the void.
    Fixtures wait until a harmless request comes back before a test starts.
    """
    from node_common.calls import call

    try:
        return call(client, request, timeout) is not None
    except Exception:  # noqa: BLE001 - not answered yet
        return False


def store_pickled_policy(root: Path, name: str, model, **fields) -> Path:
    """A policy of the format before in the store at ``root``: stable-baselines3's zip of ``model`` (pickles) and
    a policy.json naming it, with ``fields``; returns the zip's path."""
    import json
    from dataclasses import asdict

    from learner_node.policy_store import PolicyRecord

    folder = root / name
    folder.mkdir(parents=True)
    model.save(folder / "model-1.zip")
    record = PolicyRecord(name=name, model_file="model-1.zip", **fields)
    (folder / "policy.json").write_text(json.dumps(asdict(record)))
    return folder / "model-1.zip"

"""Nodes as child processes: started as ``glocal-ros run NODE``, logged to a file, stopped cleanly."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path
from typing import Mapping, Sequence


def ros_param_text(value) -> str:
    """A Python value as ``-p name:=value`` text that ROS parses back to the same type."""
    if isinstance(value, bool):
        return "true" if value else "false"
    return str(value)


class NodeProcess:
    """One node process. Its output goes to ``<log_dir>/<node>.log``."""

    def __init__(
        self,
        node: str,
        log_dir: Path,
        params: Mapping[str, object] | None = None,
        params_file: Path | None = None,
        env: Mapping[str, str] | None = None,
        extra_args: Sequence[str] = (),
        cwd: Path | None = None,
    ):
        self.node = node
        log_dir.mkdir(parents=True, exist_ok=True)
        self.log_path = log_dir / f"{node}-{time.strftime('%Y%m%d-%H%M%S')}-{time.monotonic_ns() % 10**6}.log"
        command = [sys.executable, "-m", "glocal_app.cli", "run", node, "--ros-args"]
        if params_file is not None:
            command += ["--params-file", str(params_file)]
        for name, value in (params or {}).items():
            command += ["-p", f"{name}:={ros_param_text(value)}"]
        command += list(extra_args)
        self._log = open(self.log_path, "w")
        self.process = subprocess.Popen(
            command, stdout=self._log, stderr=subprocess.STDOUT, cwd=cwd,
            env=dict(env) if env is not None else None,
            # Own process group: a Ctrl-C in the terminal reaches the launcher,
            # which then stops the nodes in order.
            start_new_session=True,
        )

    @property
    def running(self) -> bool:
        return self.process.poll() is None

    def log(self) -> str:
        return self.log_path.read_text()

    def stop(self, sig: int = signal.SIGINT, timeout: float = 20.0) -> int:
        """Signal the node, wait for it, kill it if it does not end; its exit code."""
        if self.running:
            self.process.send_signal(sig)
            try:
                self.process.wait(timeout)
            except subprocess.TimeoutExpired:
                self.process.kill()
                self.process.wait()
        self._log.close()
        return self.process.returncode


def isolated_environment(domain_id: int, log_dir: Path) -> dict[str, str]:
    """This process's environment on ``domain_id``, discovery on loopback, ROS logs in ``log_dir``."""
    env = dict(os.environ)
    env.update(ROS_DOMAIN_ID=str(domain_id), ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST",
               ROS_LOG_DIR=str(log_dir), PYTHONUNBUFFERED="1")
    env.setdefault("AMENT_PREFIX_PATH", sys.prefix)
    return env

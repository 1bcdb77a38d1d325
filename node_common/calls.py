"""Blocking service calls from worker threads.

A node that serves a request by calling other services (the learner calls the
sim for every step) blocks in a callback while a MultiThreadedExecutor spins
the response in another thread. ``spin_until_future_complete`` would spin a
second executor and costs milliseconds per call; waiting on an event does not.
Clients used this way must sit in a ``ReentrantCallbackGroup`` (or any group
other than the waiting callback's).
"""

from __future__ import annotations

import threading
import time
from typing import Any, Callable

from rclpy.client import Client


CONTEXT_POLL_SEC = 0.1


class ServiceCallError(RuntimeError):
    """The service is missing, did not answer in time, or answered an error."""


def wait_for_service(client: Client, timeout_sec: float) -> None:
    if not client.wait_for_service(timeout_sec=timeout_sec):
        raise ServiceCallError(f"service {client.srv_name} is not available after {timeout_sec:.0f} s")


def start_call(client: Client, request: Any, timeout_sec: float = 60.0, checked: bool = False) -> Callable[[], Any]:
    """Send ``request`` now; the returned function waits for the response.

    The caller can work while the service does (the learner trains while the
    sim steps). ``checked``: the wait raises when the response says
    ``success=False``. Needs an executor spinning elsewhere.
    """
    future = client.call_async(request)
    deadline = time.monotonic() + timeout_sec
    done = threading.Event()
    future.add_done_callback(lambda _: done.set())

    def wait() -> Any:
        # A response can only come while the context spins: after a shutdown, stop waiting for it.
        while not done.wait(CONTEXT_POLL_SEC):
            if not client.context.ok():
                raise ServiceCallError(f"shut down while waiting for {client.srv_name}")
            if time.monotonic() > deadline:
                client.remove_pending_request(future)
                raise ServiceCallError(f"service {client.srv_name} did not answer within {timeout_sec:.0f} s")
        if future.exception() is not None:
            raise ServiceCallError(f"service {client.srv_name} failed: {future.exception()}")
        response = future.result()
        if checked and not response.success:
            raise ServiceCallError(f"{client.srv_name}: {response.message}")
        return response

    return wait


def call(client: Client, request: Any, timeout_sec: float = 60.0) -> Any:
    """Send ``request`` and wait for the response; needs an executor spinning elsewhere."""
    return start_call(client, request, timeout_sec)()


def call_checked(client: Client, request: Any, timeout_sec: float = 60.0) -> Any:
    """``call``, raising ``ServiceCallError`` when the response says ``success=False``."""
    return start_call(client, request, timeout_sec, checked=True)()

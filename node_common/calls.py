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
from rclpy.node import Node


CONTEXT_POLL_SEC = 0.1
#: How often a watched call looks for its servers in the graph (a graph query costs about a millisecond).
WATCH_INTERVAL_SEC = 1.0


class ServiceCallError(RuntimeError):
    """The service is missing, did not answer in time, or answered an error (then ``response`` is it)."""

    def __init__(self, message: str, response: Any = None):
        super().__init__(message)
        self.response = response


class ServerGone(ServiceCallError):
    """Every server that had the request is gone (killed, restarted): no answer will come."""


class ServerWatch:
    """Tells when the servers a request went to have all left the graph.

    A service server that is killed takes the requests it had with it, and a
    restarted one never hears of them; ``client.service_is_ready()`` cannot
    tell, since the new server makes it true again. The servers are told apart
    by the GIDs of their request readers (the DDS topic ``rq<service>Request``,
    rmw_fastrtps's naming): a killed server's GID leaves the graph when its
    participant's lease runs out (20 s by default). With no server in the
    graph at the start, ``gone`` stays False and the call's time-out decides.
    """

    def __init__(self, node: Node, service_name: str):
        self.node = node
        self.topic = f"rq{service_name}Request"
        self.servers = self._gids()

    def gone(self) -> bool:
        return bool(self.servers) and not (self.servers & self._gids())

    def _gids(self) -> set[bytes]:
        infos = self.node.get_subscriptions_info_by_topic(self.topic, no_mangle=True)
        return {bytes(info.endpoint_gid) for info in infos}


def wait_for_service(client: Client, timeout_sec: float) -> None:
    if not client.wait_for_service(timeout_sec=timeout_sec):
        raise ServiceCallError(f"service {client.srv_name} is not available after {timeout_sec:.0f} s")


def start_call(client: Client, request: Any, timeout_sec: float = 60.0, checked: bool = False,
               watch: ServerWatch | None = None) -> Callable[[], Any]:
    """Send ``request`` now; the returned function waits for the response.

    The caller can work while the service does (the learner trains while the
    sim steps). ``checked``: the wait raises when the response says
    ``success=False``. ``watch``: the wait raises ``ServerGone`` once the
    servers it watches are gone. Needs an executor spinning elsewhere.
    """
    future = client.call_async(request)
    deadline = time.monotonic() + timeout_sec
    done = threading.Event()
    future.add_done_callback(lambda _: done.set())

    def wait() -> Any:
        next_watch = time.monotonic() + WATCH_INTERVAL_SEC
        # A response can only come while the context spins: after a shutdown, stop waiting for it.
        while not done.wait(CONTEXT_POLL_SEC):
            if not client.context.ok():
                raise ServiceCallError(f"shut down while waiting for {client.srv_name}")
            if time.monotonic() > deadline:
                client.remove_pending_request(future)
                raise ServiceCallError(f"service {client.srv_name} did not answer within {timeout_sec:.0f} s")
            if watch is not None and time.monotonic() > next_watch:
                next_watch = time.monotonic() + WATCH_INTERVAL_SEC
                if watch.gone():
                    client.remove_pending_request(future)
                    raise ServerGone(f"the server of {client.srv_name} went away before it answered")
        if future.exception() is not None:
            raise ServiceCallError(f"service {client.srv_name} failed: {future.exception()}")
        response = future.result()
        if checked and not response.success:
            raise ServiceCallError(f"{client.srv_name}: {response.message}", response)
        return response

    return wait


def call(client: Client, request: Any, timeout_sec: float = 60.0) -> Any:
    """Send ``request`` and wait for the response; needs an executor spinning elsewhere."""
    return start_call(client, request, timeout_sec)()


def call_checked(client: Client, request: Any, timeout_sec: float = 60.0, watch: ServerWatch | None = None) -> Any:
    """``call``, raising ``ServiceCallError`` when the response says ``success=False``."""
    return start_call(client, request, timeout_sec, checked=True, watch=watch)()

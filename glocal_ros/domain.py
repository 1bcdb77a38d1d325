"""Reserving a ROS_DOMAIN_ID that no other run on this machine is using.

As ROS's domain_coordinator does, a domain id is held by binding a loopback
TCP port derived from it (above the ports DDS uses); the reservation lasts as
long as the returned socket stays open. Tests and ``glocal-ros launch`` use it
so that parallel runs never discover each other.
"""

from __future__ import annotations

import random
import socket

PORT_BASE = 32768
DOMAIN_IDS = range(1, 101)


def reserve_domain_id() -> tuple[int, socket.socket]:
    """A free domain id and the socket that holds it (close it to release the id)."""
    candidates = list(DOMAIN_IDS)
    random.shuffle(candidates)
    for domain_id in candidates:
        lock = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
        try:
            lock.bind(("127.0.0.1", PORT_BASE + domain_id))
            return domain_id, lock
        except OSError:
            lock.close()
    raise RuntimeError(f"every ROS domain id {DOMAIN_IDS.start}..{DOMAIN_IDS.stop - 1} is taken on this machine")

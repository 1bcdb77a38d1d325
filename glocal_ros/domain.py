"""The ROS_DOMAIN_ID of a run: the one the user set, else one that no other run on this machine is using.

As ROS's domain_coordinator does, a domain id is held by binding a loopback
TCP port derived from it (above the ports DDS uses); the reservation lasts as
long as the returned socket stays open. Tests and ``glocal-ros launch`` use it
so that parallel runs never discover each other.

A ``ROS_DOMAIN_ID`` set in the environment is the user's choice (a viewer
such as RViz already runs on it) and is kept: ``choose_domain_id`` then only
holds it if it is free, so that runs choosing a free domain keep off it, and
says when another run on this machine holds it already (its nodes and this
run's would then see each other, which is only right under distinct
namespaces).
"""

from __future__ import annotations

import os
import random
import socket
from dataclasses import dataclass
from typing import Mapping

PORT_BASE = 32768
#: Where a free domain is looked for (0 is left to users: it is what an unset variable means).
DOMAIN_IDS = range(1, 101)
#: Valid ROS_DOMAIN_ID values: rmw derives UDP ports from the id, and above 232 they leave the port range.
MAX_DOMAIN_ID = 232
ENVIRONMENT_VARIABLE = "ROS_DOMAIN_ID"


def hold_domain_id(domain_id: int) -> socket.socket | None:
    """The socket that holds ``domain_id`` on this machine, or None when another process holds it."""
    lock = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
    try:
        lock.bind(("127.0.0.1", PORT_BASE + domain_id))
    except OSError:
        lock.close()
        return None
    return lock


def reserve_domain_id() -> tuple[int, socket.socket]:
    """A free domain id and the socket that holds it (close it to release the id)."""
    candidates = list(DOMAIN_IDS)
    random.shuffle(candidates)
    for domain_id in candidates:
        lock = hold_domain_id(domain_id)
        if lock is not None:
            return domain_id, lock
    raise RuntimeError(f"every ROS domain id {DOMAIN_IDS.start}..{DOMAIN_IDS.stop - 1} is taken on this machine")


def domain_id_from_environment(environ: Mapping[str, str] = os.environ) -> int | None:
    """The ROS_DOMAIN_ID the user set; None when unset or empty (ROS reads an empty one as unset too).

    Raises ``ValueError`` for a value that is not an id from 0 to ``MAX_DOMAIN_ID``: better said now
    than by every node failing to create its participant.
    """
    text = environ.get(ENVIRONMENT_VARIABLE, "").strip()
    if not text:
        return None
    if not text.isdigit() or int(text) > MAX_DOMAIN_ID:
        raise ValueError(f"{ENVIRONMENT_VARIABLE}={text!r} is not a domain id from 0 to {MAX_DOMAIN_ID}")
    return int(text)


@dataclass
class Domain:
    """The domain a run uses and how it got it; ``close()`` releases the hold (if any)."""

    domain_id: int
    from_environment: bool  # the user's ROS_DOMAIN_ID, else a free one chosen here
    lock: socket.socket | None  # None: the user's id, already held by another run on this machine

    @property
    def shared(self) -> bool:
        """Whether another run on this machine holds the same domain (only ever for the user's own id)."""
        return self.lock is None

    def describe(self) -> str:
        if not self.from_environment:
            return f"ROS_DOMAIN_ID {self.domain_id} (a free one; set ROS_DOMAIN_ID to choose)"
        text = f"ROS_DOMAIN_ID {self.domain_id} (from the environment)"
        if self.shared:
            text += (f"; note: another run on this machine holds domain {self.domain_id} too, and the two graphs "
                     f"see each other unless their namespaces differ")
        return text

    def close(self) -> None:
        if self.lock is not None:
            self.lock.close()


def choose_domain_id(environ: Mapping[str, str] = os.environ) -> Domain:
    """The user's ROS_DOMAIN_ID (held when free), else a free domain id reserved for this run."""
    domain_id = domain_id_from_environment(environ)
    if domain_id is None:
        domain_id, lock = reserve_domain_id()
        return Domain(domain_id, from_environment=False, lock=lock)
    return Domain(domain_id, from_environment=True, lock=hold_domain_id(domain_id))

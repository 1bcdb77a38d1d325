"""The physics client of an env: pybullet_utils' ``BulletClient`` with each function bound once.

``BulletClient`` binds its client id to a pybullet function on every call
(``__getattr__``: a module lookup, ``inspect.isbuiltin``, a new
``functools.partial``), about 3% of a control step on this machine kind
(``glocal-ros bench physics``). ``PhysicsClient`` keeps each bound function
on the instance after its first use, so later calls find it there: the same
pybullet functions run with the same arguments, and the simulation is
unchanged to the bit. ``disconnect`` is not kept: ``BulletClient`` marks the
client disconnected when it hands that one out.
"""

from __future__ import annotations

from pybullet_utils.bullet_client import BulletClient


class PhysicsClient(BulletClient):
    """A ``BulletClient`` whose functions are bound to its client id once each."""

    def __getattr__(self, name: str):
        attribute = super().__getattr__(name)
        if name != "disconnect":
            self.__dict__[name] = attribute
        return attribute

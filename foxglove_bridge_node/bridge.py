"""The Foxglove side of foxglove_bridge_node, without ROS: a WebSocket server, one channel per forwarded topic,
and who wants which topic.

Protocol: the Foxglove WebSocket protocol as the pinned foxglove-sdk serves it (subprotocol
``foxglove.sdk.v1``; foxglove_bridge's older ``foxglove.websocket.v1`` is refused with HTTP 400). The SDK
answers what it does not understand (a malformed message, a subscription to a channel it never advertised)
with a status message of level error and keeps the connection and the server up.

Channels: each forwarded topic is one channel named as the topic (``/tf``, ``/robot1/tf``), encoding
``cdr``, schema ``pkg/msg/Type`` in ``ros2msg`` (the type's definition followed by those it uses, as
foxglove_bridge and a bag's MCAP schema record give it: ``glocal_ros.recording.message_definition``).
Messages go out as the bytes the DDS delivered, never decoded here: forwarding costs a copy per client.

Demand: the server tells ``TopicBridge`` when a client subscribes to or leaves a channel (from its own
thread); the bridge counts clients per topic and calls ``on_demand_change`` (which must only wake the
ROS side: it runs on the server's thread). The ROS side then reads ``demand()`` and subscribes to
exactly the topics some client wants, so an idle bridge costs the graph nothing but discovery.

Assets: ``package://PKG/path`` URIs (the Panda's meshes in robot_description) are served from the
package's share directory, found by ``share_dir(PKG)``; a path that leaves that directory is refused.
"""

from __future__ import annotations

import re
import threading
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

import foxglove
from foxglove import Channel, Context, Schema
from foxglove.websocket import ChannelView, Client, WebSocketServer

#: What the channels carry and the server advertises: ROS 2's serialized messages.
MESSAGE_ENCODING = "cdr"
SCHEMA_ENCODING = "ros2msg"
#: The prefix of what ``package_asset`` serves: ROS package URIs (as URDF meshes name them).
PACKAGE_SCHEME = "package://"


@dataclass(frozen=True)
class TopicSelection:
    """Which of the graph's topics the bridge forwards: those under ``namespace`` (all for ``/``) whose name
    matches ``include`` (a regular expression, whole name; empty: every one) and not ``exclude``
    (empty: none)."""

    namespace: str = "/"
    include: str = ""
    exclude: str = ""

    def __post_init__(self) -> None:
        for what, pattern in (("include", self.include), ("exclude", self.exclude)):
            try:
                re.compile(pattern)
            except re.error as error:
                raise ValueError(f"topic {what} pattern {pattern!r} is not a regular expression: {error}") from None

    def accepts(self, topic: str) -> bool:
        prefix = self.namespace.rstrip("/") + "/"
        if not topic.startswith(prefix):
            return False
        if self.include and not re.fullmatch(self.include, topic):
            return False
        return not (self.exclude and re.fullmatch(self.exclude, topic))


def package_asset(uri: str, share_dir: Callable[[str], Path | None]) -> bytes | None:
    """The file a ``package://PKG/path`` URI names, under ``share_dir(PKG)``; None for anything else.

    Refused (None): another scheme, an unknown package, a path that resolves outside the package's share
    directory (``..``, a link out of it): a remote client must not read the host's files through it.
    """
    if not uri.startswith(PACKAGE_SCHEME):
        return None
    package, _, relative = uri.removeprefix(PACKAGE_SCHEME).partition("/")
    root = share_dir(package) if package and relative else None
    if root is None:
        return None
    root = root.resolve()
    path = (root / relative).resolve()
    if not path.is_relative_to(root) or not path.is_file():
        return None
    return path.read_bytes()


class _Listener:
    """The server's callbacks (run on its thread), passed on to the bridge."""

    def __init__(self, bridge: TopicBridge):
        self._bridge = bridge

    def on_subscribe(self, client: Client, channel: ChannelView) -> None:
        self._bridge._client_subscribed(client.id, channel.topic, +1)

    def on_unsubscribe(self, client: Client, channel: ChannelView) -> None:
        self._bridge._client_subscribed(client.id, channel.topic, -1)


class TopicBridge:
    """A running Foxglove WebSocket server on ``host``:``port`` and the channels advertised on it.

    ``advertise`` and ``withdraw`` change the channels, ``forward`` sends a serialized message to every
    client subscribed to its topic, ``demand`` says which topics clients want (and how many clients each).
    A port that cannot be bound raises ``OSError`` naming it, before anything is advertised.
    """

    def __init__(self, host: str, port: int, on_demand_change: Callable[[], None] = lambda: None,
                 asset_handler: Callable[[str], bytes | None] | None = None, name: str = "glocal_ros"):
        self._lock = threading.Lock()
        self._channels: dict[str, Channel] = {}
        self._clients: dict[str, set[int]] = {}  # topic -> ids of the clients subscribed to it
        self._on_demand_change = on_demand_change
        # A context of its own: the SDK's global one would also feed any other sink of this process.
        self._context = Context()
        try:
            self.server: WebSocketServer = foxglove.start_server(
                name=name, host=host, port=port, supported_encodings=[MESSAGE_ENCODING],
                server_listener=_Listener(self), asset_handler=asset_handler, context=self._context)
        except RuntimeError as error:  # the SDK's FoxgloveError: "Failed to bind port: Address already in use"
            raise OSError(f"cannot serve Foxglove on {host}:{port}: {error}") from None
        self.host = host

    @property
    def port(self) -> int:
        return self.server.port

    def advertise(self, topic: str, msgtype: str, definition: str) -> bool:
        """Offer ``topic`` (type ``pkg/msg/Type``, its ros2msg ``definition``) to clients; False if it already is."""
        with self._lock:
            if topic in self._channels:
                return False
            schema = Schema(name=msgtype, encoding=SCHEMA_ENCODING, data=definition.encode())
            self._channels[topic] = Channel(topic, schema=schema, message_encoding=MESSAGE_ENCODING,
                                            context=self._context)
            return True

    def withdraw(self, topic: str) -> None:
        """Stop offering ``topic`` (its clients are unsubscribed: the server says so through the listener)."""
        with self._lock:
            channel = self._channels.pop(topic, None)
        if channel is not None:
            channel.close()

    def advertised(self) -> set[str]:
        with self._lock:
            return set(self._channels)

    def demand(self) -> dict[str, int]:
        """Topics that some client is subscribed to, with how many clients."""
        with self._lock:
            return {topic: len(clients) for topic, clients in self._clients.items() if clients}

    def forward(self, topic: str, data: bytes, log_time_ns: int) -> None:
        """One serialized message of ``topic`` to its subscribed clients (none: dropped)."""
        channel = self._channels.get(topic)  # a dict read: no lock on the message path
        if channel is not None:
            channel.log(data, log_time=log_time_ns)

    def stop(self) -> None:
        self.server.stop()

    def _client_subscribed(self, client_id: int, topic: str, change: int) -> None:
        with self._lock:
            clients = self._clients.setdefault(topic, set())
            (clients.add if change > 0 else clients.discard)(client_id)
        self._on_demand_change()

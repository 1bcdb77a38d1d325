"""foxglove_bridge_node against a real WebSocket client on loopback.

One bridge process (real rclpy, Fast DDS, the suite's domain) is shared by the module; the test's own
node publishes /tf (as sim_node does, about 20 Hz) and a latched /glocal/curriculum_state. The client is
the ``websockets`` library speaking the Foxglove protocol as foxglove-sdk 0.30 serves it (subprotocol
``foxglove.sdk.v1``): it lists the channels, subscribes, and decodes each message with nothing but the
schema the server advertised (rosbags, on an empty typestore).
"""

from __future__ import annotations

import json
import socket
import struct
import time

import pytest
from websockets.exceptions import InvalidStatus
from websockets.sync.client import ClientConnection, connect

from conftest import free_port, node_starter, spun_test_node, wait_until
from foxglove_bridge_node.bridge import TopicSelection, package_asset
from glocal_ros.recording import BagWriter, graph_typestore, message_definition
from glocal_ros.topics import CURRICULUM_STATE, TF

SUBPROTOCOL = "foxglove.sdk.v1"
MESSAGE_DATA = 0x01  # the protocol's binary opcode of a message from a subscribed channel
STATUS_ERROR = 2
WAIT_SEC = 60.0
UNKNOWN_TYPE_TOPIC = "/glocal/feedback_of_unknown_type"  # generous: the machine is shared


class FoxgloveClient:
    """A protocol client: what the server advertised, its status messages, and the messages received."""

    def __init__(self, port: int):
        self._connection = connect(f"ws://127.0.0.1:{port}", subprotocols=[SUBPROTOCOL], open_timeout=30)
        self.ws: ClientConnection = self._connection.__enter__()
        self.channels: dict[str, dict] = {}  # topic -> the advertised channel
        self.statuses: list[dict] = []
        self.messages: dict[int, list[bytes]] = {}  # subscription id -> payloads
        self.server_info: dict | None = None

    def pump(self, until, timeout: float = WAIT_SEC, what: str = "the server"):
        """Read what the server sends until ``until()`` is truthy."""
        deadline = time.monotonic() + timeout
        while not until():
            left = deadline - time.monotonic()
            if left <= 0:
                pytest.fail(f"timed out waiting for {what}; channels {sorted(self.channels)}, "
                            f"statuses {self.statuses}")
            try:
                frame = self.ws.recv(timeout=min(left, 0.5))
            except TimeoutError:
                continue
            if isinstance(frame, bytes):
                if frame[0] == MESSAGE_DATA:
                    subscription, _log_time = struct.unpack_from("<IQ", frame, 1)
                    self.messages.setdefault(subscription, []).append(frame[13:])
                continue
            message = json.loads(frame)
            if message["op"] == "serverInfo":
                self.server_info = message
            elif message["op"] == "advertise":
                self.channels.update({channel["topic"]: channel for channel in message["channels"]})
            elif message["op"] == "unadvertise":
                self.channels = {t: c for t, c in self.channels.items() if c["id"] not in message["channelIds"]}
            elif message["op"] == "status":
                self.statuses.append(message)
        return until()

    def send(self, op: str, **fields) -> None:
        self.ws.send(json.dumps({"op": op, **fields}))

    def subscribe(self, subscription: int, topic: str) -> None:
        self.pump(lambda: topic in self.channels, what=f"{topic} to be advertised")
        self.send("subscribe", subscriptions=[{"id": subscription, "channelId": self.channels[topic]["id"]}])

    def decoded(self, subscription: int, topic: str) -> list:
        """What arrived on ``subscription``, decoded with only the schema advertised for ``topic``."""
        from rosbags.typesys import Stores, get_types_from_msg, get_typestore

        channel = self.channels[topic]
        assert (channel["encoding"], channel["schemaEncoding"]) == ("cdr", "ros2msg")
        store = get_typestore(Stores.EMPTY)
        store.register(get_types_from_msg(channel["schema"], channel["schemaName"]))
        return [store.deserialize_cdr(data, channel["schemaName"]) for data in self.messages.get(subscription, [])]

    def close(self) -> None:
        self._connection.__exit__(None, None, None)


@pytest.fixture(scope="module")
def graph(tmp_path_factory):
    """(the bridge process, its port, the test's node, the run_id of the curriculum state it latched)."""
    from glocal_interfaces.action import Train
    from glocal_interfaces.msg import CurriculumState
    from geometry_msgs.msg import TransformStamped
    from tf2_msgs.msg import TFMessage

    from node_common import names, qos

    port = free_port()
    run_id = "bridge-test-seed7"
    with spun_test_node() as node, node_starter(tmp_path_factory.mktemp("bridge-logs")) as start:
        node.create_publisher(CurriculumState, names.CURRICULUM_STATE, qos.LATCHED).publish(
            CurriculumState(run_id=run_id, strategy="glocal", total_steps=1234, learned_tasks=["A0", "B1"]))
        tf = node.create_publisher(TFMessage, names.TF, qos.VIEWER)

        def send_tf() -> None:
            transform = TransformStamped(child_frame_id="object")
            transform.header.frame_id = "world"
            transform.header.stamp = node.get_clock().now().to_msg()
            transform.transform.translation.z = 0.1
            tf.publish(TFMessage(transforms=[transform]))

        node.create_timer(0.05, send_tf)
        # A type without a schema here (an action's feedback, as learner/train's hidden topic has): skipped.
        node.create_publisher(Train.Impl.FeedbackMessage, UNKNOWN_TYPE_TOPIC, 1)
        bridge = start("foxglove_bridge_node", port=port, discovery_period_sec=0.5)
        wait_until(lambda: _accepts(port), WAIT_SEC, "the bridge's port", processes=[bridge])
        yield bridge, port, node, run_id
        assert bridge.running, f"the bridge ended:\n{bridge.log()}"


def _accepts(port: int) -> bool:
    with socket.socket() as probe:
        return probe.connect_ex(("127.0.0.1", port)) == 0


@pytest.fixture
def client(graph):
    clients: list[FoxgloveClient] = []

    def connect_client() -> FoxgloveClient:
        clients.append(FoxgloveClient(graph[1]))
        return clients[-1]

    yield connect_client
    for opened in clients:
        opened.close()


def test_a_client_lists_subscribes_and_decodes_what_arrives_against_the_advertised_schema(graph, client):
    bridge, _, _, run_id = graph
    viewer = client()
    viewer.pump(lambda: {TF.name, CURRICULUM_STATE.name} <= set(viewer.channels), what="the two topics")
    assert viewer.server_info["supportedEncodings"] == ["cdr"]
    wait_until(lambda: f"not forwarding {UNKNOWN_TYPE_TOPIC}" in bridge.log(), WAIT_SEC,
               "the bridge to skip the type it has no schema for", processes=[bridge])
    assert UNKNOWN_TYPE_TOPIC not in viewer.channels
    typestore = graph_typestore()
    for spec in (TF, CURRICULUM_STATE):
        channel = viewer.channels[spec.name]
        assert channel["schemaName"] == spec.msgtype  # pkg/msg/Type, as foxglove_bridge names it
        assert channel["schema"] == message_definition(spec.msgtype, typestore)
    viewer.subscribe(1, TF.name)
    viewer.subscribe(2, CURRICULUM_STATE.name)
    viewer.pump(lambda: len(viewer.messages.get(1, [])) >= 3 and viewer.messages.get(2), what="/tf and the state")
    transforms = viewer.decoded(1, TF.name)
    assert {t.child_frame_id for message in transforms for t in message.transforms} == {"object"}
    assert transforms[-1].transforms[0].transform.translation.z == pytest.approx(0.1)
    (state,) = viewer.decoded(2, CURRICULUM_STATE.name)  # latched: sent once, delivered to the late bridge
    assert (state.run_id, state.total_steps, list(state.learned_tasks)) == (run_id, 1234, ["A0", "B1"])


def test_the_bridge_serves_clients_that_come_and_go_and_subscribes_only_while_one_listens(graph, client):
    bridge, port, node, run_id = graph
    with pytest.raises(InvalidStatus):  # foxglove_bridge's older subprotocol: HTTP 400, and no harm done
        with connect(f"ws://127.0.0.1:{port}", subprotocols=["foxglove.websocket.v1"], open_timeout=30):
            pass
    first = client()
    first.subscribe(1, CURRICULUM_STATE.name)
    first.subscribe(2, TF.name)
    first.pump(lambda: first.messages.get(1) and first.messages.get(2), what="the first client's messages")
    wait_until(lambda: node.count_subscribers(TF.name) == 1, WAIT_SEC, "the bridge's /tf subscription",
               processes=[bridge])
    first.close()
    wait_until(lambda: node.count_subscribers(TF.name) == 0, WAIT_SEC,
               "the bridge to drop /tf once no client listens", processes=[bridge])

    second = client()
    second.pump(lambda: CURRICULUM_STATE.name in second.channels, what="the channels")
    second.send("subscribe", subscriptions=[{"id": 7, "channelId": 987654}])
    second.pump(lambda: second.statuses, what="an error about the unknown channel")
    assert second.statuses[-1]["level"] == STATUS_ERROR and "987654" in second.statuses[-1]["message"]
    # A latched topic that an earlier client already had: this one gets the latest state too.
    second.subscribe(3, CURRICULUM_STATE.name)
    third = client()
    third.subscribe(4, CURRICULUM_STATE.name)
    for viewer, subscription in ((second, 3), (third, 4)):
        viewer.pump(lambda: viewer.messages.get(subscription), what="the latched state for a later client")
        assert viewer.decoded(subscription, CURRICULUM_STATE.name)[-1].run_id == run_id
    third.send("unsubscribe", subscriptionIds=[4])
    third.close()
    assert bridge.running


def test_a_malformed_message_gets_an_error_and_the_bridge_keeps_serving(graph, client):
    bridge = graph[0]
    viewer = client()
    viewer.pump(lambda: TF.name in viewer.channels, what="the channels")
    for bad in ("not json", json.dumps({"op": "no such op"}), json.dumps({"op": "subscribe"})):
        count = len(viewer.statuses)
        viewer.ws.send(bad)
        viewer.pump(lambda: len(viewer.statuses) > count, what=f"an error for {bad!r}")
        assert viewer.statuses[-1]["level"] == STATUS_ERROR, viewer.statuses[-1]
    viewer.subscribe(1, TF.name)  # the same connection still works
    viewer.pump(lambda: viewer.messages.get(1), what="/tf after the errors")
    assert bridge.running


def test_a_taken_port_ends_the_bridge_with_a_clear_error(graph, tmp_path):
    port = graph[1]
    with node_starter(tmp_path) as start:
        second = start("foxglove_bridge_node", port=port)
        wait_until(lambda: not second.running, WAIT_SEC, "the second bridge to give up")
    assert second.process.returncode == 1
    assert f"cannot serve Foxglove on 127.0.0.1:{port}" in second.log() and "in use" in second.log()


# --- without ROS --------------------------------------------------------------------------------------------

def test_the_schema_sent_is_the_one_a_bag_holds(tmp_path):
    from mcap.reader import make_reader

    with_bag = BagWriter(tmp_path / "bag", [TF])
    with_bag.write(TF.name, 1, bytes(8))
    with_bag.close()
    with open(next((tmp_path / "bag").glob("*.mcap")), "rb") as stream:
        schemas = {schema.name: schema for schema in make_reader(stream).get_summary().schemas.values()}
    assert schemas[TF.msgtype].data.decode() == message_definition(TF.msgtype, graph_typestore())


def test_assets_are_served_from_the_package_share_and_nowhere_else(tmp_path):
    share = tmp_path / "share" / "glocal_ros"
    (share / "robots").mkdir(parents=True)
    (share / "robots" / "link0.dae").write_bytes(b"mesh")
    (tmp_path / "secret").write_bytes(b"no")
    (share / "robots" / "out").symlink_to(tmp_path / "secret")
    shares = {"glocal_ros": share}.get
    assert package_asset("package://glocal_ros/robots/link0.dae", shares) == b"mesh"
    for refused in ("package://glocal_ros/../../secret", "package://glocal_ros/robots/out", "file:///etc/passwd",
                    "package://other/robots/link0.dae", "package://glocal_ros/", "package://glocal_ros/robots"):
        assert package_asset(refused, shares) is None, refused


def test_the_topic_selection_follows_namespace_and_patterns():
    assert TopicSelection().accepts("/tf") and TopicSelection().accepts("/robot1/tf")
    ns = TopicSelection("/robot1")
    assert ns.accepts("/robot1/tf") and ns.accepts("/robot1/clock") and not ns.accepts("/tf")
    assert not ns.accepts("/robot10/tf")
    picked = TopicSelection("/", include=r"/glocal/.*|/tf", exclude=r"/glocal/episodes")
    assert picked.accepts("/tf") and picked.accepts("/glocal/curriculum_state")
    assert not picked.accepts("/glocal/episodes") and not picked.accepts("/joint_states")
    with pytest.raises(ValueError, match="not a regular expression"):
        TopicSelection(include="(")


def test_the_bridge_and_the_plan_agree_on_foxglove_defaults():
    from foxglove_bridge_node.foxglove_bridge_node import DEFAULT_ADDRESS, DEFAULT_PORT
    from glocal_app.processes import FOXGLOVE_HOST, FOXGLOVE_PORT

    assert (DEFAULT_PORT, DEFAULT_ADDRESS) == (FOXGLOVE_PORT, FOXGLOVE_HOST)

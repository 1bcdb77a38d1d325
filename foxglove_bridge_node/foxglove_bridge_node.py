"""foxglove_bridge_node: the graph's topics live in Foxglove, over the Foxglove WebSocket protocol.

What foxglove_bridge does on a full ROS install, for this graph without one: a WebSocket server (the
pinned foxglove-sdk, ``foxglove_bridge_node.bridge``) on ``address``:``port``, one channel per topic of the
graph, each carrying the topic's messages as the DDS delivered them (CDR) with the type's ros2msg
schema, so that Foxglove decodes them as it decodes a bag.

Parameters: ``port`` (8765, Foxglove's default), ``address`` (127.0.0.1: only this host can connect;
another address, e.g. 0.0.0.0, serves every host that reaches the port, with no authentication: an
explicit choice, logged as a warning), ``topic_include`` / ``topic_exclude`` (regular expressions over
the whole topic name; empty: every topic / none) and ``discovery_period_sec`` (how often the graph is
looked at for new topics, and for publishers that need a subscription's QoS changed).

Topics: every topic under the node's namespace (so ``--ros-args -r __ns:=/robot1`` forwards
``/robot1/tf`` and, remapped like every node of a namespaced graph, ``/robot1/clock``) whose single type
the graph's typestore knows (Jazzy's types and glocal_interfaces). Types it does not know are skipped
and logged once: there would be no schema to send.

Cost: a topic is subscribed only while some client is subscribed to its channel, raw (never
deserialized), and unsubscribed when the last client leaves. With no client, the bridge only looks at
the graph every ``discovery_period_sec`` (``glocal-ros bench foxglove`` measures what that costs a
training run).

QoS: a subscription takes the topic's QoS from the table (``glocal_ros.topics``; unknown topics:
reliable, volatile, depth 10), adapted to what its publishers offer as the recorder adapts it
(``node_common.graph.adapted_qos``), so latched topics (robot_description, curriculum_state,
task_assignment, tf_static, the object marker) arrive transient-local. A client that subscribes to a
latched topic later than another gets the latest message too: the subscription is made again, and the
publishers send their latched history again (to every client of that topic; a latched message repeated
is harmless).

Times: a message's log time is the node's clock when it arrived (the sim's /clock under
``use_sim_time``, the same time base as the messages' stamps).
"""

from __future__ import annotations

import ipaddress
from pathlib import Path

from ament_index_python.packages import PackageNotFoundError, get_package_share_directory
from rclpy.clock import Clock, ClockType
from rclpy.node import Node
from rclpy.subscription import Subscription

from foxglove_bridge_node.bridge import TopicBridge, TopicSelection, package_asset
from glocal_ros.recording import graph_typestore, message_definition, table_topic
from glocal_ros.topics import QosSpec
from node_common import qos
from node_common.graph import adapted_qos, message_class
from node_common.params import declare
from node_common.runner import spin_node

#: Foxglove's own default port (foxglove_bridge's, the SDK's ``start_server``'s); glocal_app.processes
#: plans the same one (a test compares them).
DEFAULT_PORT = 8765
DEFAULT_ADDRESS = "127.0.0.1"
#: A topic the table does not know (another node's): reliable publishers and best-effort ones alike
#: are adapted to at the next look at the graph.
UNKNOWN_TOPIC_QOS = QosSpec(reliable=True, transient_local=False, depth=10)


def share_dir(package: str) -> Path | None:
    """A ROS package's share directory, through the ament index (None when not installed)."""
    try:
        return Path(get_package_share_directory(package))
    except (PackageNotFoundError, ValueError):
        return None


def is_loopback(address: str) -> bool:
    if address == "localhost":
        return True
    try:
        return ipaddress.ip_address(address).is_loopback
    except ValueError:
        return False


class FoxgloveBridgeNode(Node):
    def __init__(self) -> None:
        super().__init__("foxglove_bridge_node")
        port = declare(self, "port", DEFAULT_PORT, "TCP port of the Foxglove WebSocket server",
                       min_value=1, max_value=65535)
        address = declare(self, "address", DEFAULT_ADDRESS, "address to serve on: 127.0.0.1 (this host only), "
                          "or e.g. 0.0.0.0 to let other hosts connect (no authentication)")
        include = declare(self, "topic_include", "", "regular expression a forwarded topic's full name must "
                          "match; empty: every topic under the node's namespace")
        exclude = declare(self, "topic_exclude", "", "regular expression of topics not to forward; empty: none")
        period = declare(self, "discovery_period_sec", 1.0, "seconds between looks at the graph for new "
                         "topics and their publishers", min_value=0.1, max_value=60.0)
        self.selection = TopicSelection(self.get_namespace(), include, exclude)
        self.typestore = graph_typestore()
        self._forwarded_types: dict[str, str] = {}  # advertised topic -> its type
        self._forwarding: dict[str, tuple[Subscription, QosSpec]] = {}
        self._client_counts: dict[str, int] = {}  # clients per subscribed topic, when last looked at
        self._skipped_types: set[tuple[str, str]] = set()
        # Woken from the server's thread; subscriptions are made and destroyed on the executor's.
        self._demand_changed = self.create_guard_condition(self._follow_demand)
        self.bridge = TopicBridge(address, port, on_demand_change=self._demand_changed.trigger,
                                  asset_handler=lambda uri: package_asset(uri, share_dir))
        # Steady: under use_sim_time a timer on the node's clock would stop with the sim.
        self.create_timer(period, self._discover, clock=Clock(clock_type=ClockType.STEADY_TIME))
        self._discover()
        where = f"ws://{address}:{self.bridge.port}"
        self.get_logger().info(f"serving Foxglove on {where}: the topics under {self.get_namespace()}")
        if not is_loopback(address):
            self.get_logger().warning(f"{where} accepts other hosts: anyone who reaches the port sees the graph's "
                                      f"topics (no authentication)")

    def _discover(self) -> None:
        """Advertise the new topics, withdraw those gone, adapt subscriptions to their publishers."""
        present: dict[str, str] = {}
        for topic, types in self.get_topic_names_and_types():
            if not self.selection.accepts(topic):
                continue
            if len(types) != 1 or not self._known(types[0]):
                if (topic, ",".join(types)) not in self._skipped_types:
                    self._skipped_types.add((topic, ",".join(types)))
                    self.get_logger().warning(f"not forwarding {topic}: type {', '.join(types)} has no schema here")
                continue
            present[topic] = types[0]
        for topic, msgtype in present.items():
            if self._forwarded_types.get(topic) != msgtype:
                if topic in self._forwarded_types:  # the type changed: a new channel
                    self._withdraw(topic)
                self.bridge.advertise(topic, msgtype, message_definition(msgtype, self.typestore))
                self._forwarded_types[topic] = msgtype
        for topic in set(self._forwarded_types) - set(present):
            self._withdraw(topic)
        for topic, (_, subscribed) in list(self._forwarding.items()):
            wanted = self._qos(topic)
            if (wanted.reliable, wanted.transient_local) != (subscribed.reliable, subscribed.transient_local):
                self._subscribe(topic)
        self._follow_demand()

    def _known(self, msgtype: str) -> bool:
        try:
            message_definition(msgtype, self.typestore)
            message_class(msgtype)
        except (KeyError, ImportError, AttributeError, ValueError):
            return False
        return True

    def _withdraw(self, topic: str) -> None:
        self._unsubscribe(topic)
        self.bridge.withdraw(topic)
        del self._forwarded_types[topic]

    def _follow_demand(self) -> None:
        """Subscribe to the topics clients want, drop the others; re-deliver latched ones to a newcomer."""
        demand = {topic: count for topic, count in self.bridge.demand().items() if topic in self._forwarded_types}
        for topic in set(self._forwarding) - set(demand):
            self._unsubscribe(topic)
        for topic, clients in demand.items():
            subscription = self._forwarding.get(topic)
            newcomer = clients > self._client_counts.get(topic, 0)
            if subscription is None or (subscription[1].transient_local and newcomer):
                self._subscribe(topic)
            self._client_counts[topic] = clients

    def _qos(self, topic: str) -> QosSpec:
        spec = table_topic(topic)
        table = spec.qos if spec is not None and spec.msgtype == self._forwarded_types[topic] else UNKNOWN_TOPIC_QOS
        return adapted_qos(table, [info.qos_profile for info in self.get_publishers_info_by_topic(topic)])

    def _subscribe(self, topic: str) -> None:
        self._unsubscribe(topic)  # first: both at once would forward twice what reaches both
        wanted = self._qos(topic)
        clock = self.get_clock()
        forward = self.bridge.forward
        subscription = self.create_subscription(
            message_class(self._forwarded_types[topic]), topic,
            lambda data: forward(topic, data, clock.now().nanoseconds), qos.profile(wanted), raw=True)
        self._forwarding[topic] = (subscription, wanted)

    def _unsubscribe(self, topic: str) -> None:
        subscription = self._forwarding.pop(topic, None)
        self._client_counts.pop(topic, None)
        if subscription is not None:
            self.destroy_subscription(subscription[0])

    def close(self) -> None:
        self.bridge.stop()


def main(args=None) -> int:
    return spin_node(FoxgloveBridgeNode, args)


if __name__ == "__main__":
    raise SystemExit(main())

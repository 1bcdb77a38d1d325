"""recorder_node: every topic of the graph into one rosbag2 directory (MCAP, zstd chunks), as ``ros2 bag record``.

Names: the topics of ``glocal_ros.topics.RECORDED_TOPICS``, resolved under
the node's namespace (and its remappings): started with
``--ros-args -r __ns:=/robot1`` it records ``/robot1/glocal/episodes``, and
the bag stores the resolved names, as ``ros2 bag record`` does.

Several pairs: ``pair_namespaces`` (comma-separated, e.g. ``pair0,pair1``,
relative to the node's namespace like any name; default "", one pair in the
node's own namespace) records the topics a sim/learner pair publishes
(``TopicSpec.of_pair``) under each pair's namespace, ``/pair1/glocal/episodes``,
and the curriculum's under the node's own: one bag says which pair ran what.

QoS: every topic is subscribed raw (serialized: written as it travelled)
at start with the table's QoS, so that a latched message of a publisher
that comes up later is not missed. Every ``GRAPH_POLL_SEC``, and at once
when a subscription reports a publisher of incompatible QoS, the recorder
looks at each topic's publishers: the topic's channel in the bag records
the QoS profiles they offer (those seen first; the table's when no
publisher was ever seen), and when the offers and the subscription do not
match (a best-effort publisher, a volatile one on a latched topic) the
subscription is made again, adapted to the offers as rosbag2's recorder
adapts it: reliable only if every publisher is, transient local only if
every one is.

Times, as rosbag2 Jazzy writes them: a message's ``log_time`` is the node's
clock when the recorder received it (with ``use_sim_time:=true`` the sim
clock from /clock, as ``ros2 bag record --use-sim-time``; that clock reads 0
until the first /clock message), its ``publish_time`` the publisher's source
timestamp (the DDS writer's, from the publisher host's system clock), which
rclpy hands to a two-argument callback in its message info. The recorder's
own timers run on the steady clock: they must tick while sim time stands
still.

EpisodeRecord.seq is checked as episodes arrive, per pair (each sim counts
its own): every gap (an episode the recorder never got) is logged as a
warning when it is seen, and the total with every gap when the bag closes (``glocal-ros bag check`` does the same
on a bag afterwards). A recorder that was killed leaves a bag without
metadata.yaml: ``glocal-ros bag repair`` recovers it, up to the last flush:
every ``flush_interval_sec`` the pending chunk is closed and synced to disk.

A bag that cannot be written (a full disk) is closed at its last flush,
whole and readable (``BagWriter``); the node logs why and what was lost,
and exits with code 1: a recording with a hole is not a recording.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path
from typing import Callable

import rclpy.logging
from glocal_interfaces.msg import EpisodeRecord
from rclpy.clock import Clock, ClockType
from rclpy.duration import Duration
from rclpy.event_handler import QoSRequestedIncompatibleQoSInfo, SubscriptionEventCallbacks
from rclpy.node import Node
from rclpy.qos import QoSProfile
from rclpy.serialization import deserialize_message
from rclpy.subscription import Subscription
from rosbags.interfaces import Qos, QosDurability, QosHistory, QosLiveliness, QosReliability, QosTime

from glocal_ros.recording import BagWriter, RecordingStopped, SequenceTracker, episode_seq_from_cdr
from glocal_ros.topics import EPISODES, RECORDED_TOPICS, QosSpec, TopicSpec
from node_common import qos
from node_common.graph import adapted_qos, message_class
from node_common.params import declare
from node_common.runner import spin_node

#: How often the recorder looks at the publishers of its topics (rosbag2 polls every 0.1 s): a
#: publisher that needs the subscription adapted loses what it sends before the next look.
GRAPH_POLL_SEC = 0.5
#: The least queue of a reliable subscription: a burst (N envs ending together) must not overflow it.
MIN_RELIABLE_DEPTH = 1000


def subscription_qos(offered: QosSpec) -> QoSProfile:
    """A subscription matching ``offered``, with a queue of ``MIN_RELIABLE_DEPTH`` at least when reliable."""
    return qos.profile(replace(offered, depth=max(offered.depth, MIN_RELIABLE_DEPTH)) if offered.reliable else offered)


def _enum(kind, value, unknown):
    """rmw's enum value as rosbags' enum (both number them as rmw does); ``unknown`` for one rosbags lacks."""
    try:
        return kind(int(value))
    except ValueError:
        return unknown


def _bag_time(duration: Duration) -> QosTime:
    # Infinite (2**63 - 1 ns) comes out as rmw's RMW_DURATION_INFINITE {9223372036, 854775807}, as rosbag2 writes it.
    sec, nsec = divmod(duration.nanoseconds, 10**9)
    return QosTime(sec=sec, nsec=nsec)


def bag_qos(profile: QoSProfile) -> Qos:
    """A publisher's QoS as seen in the graph, for the bag's ``offered_qos_profiles``.

    Discovery does not carry history and depth: the graph reports them as
    unknown and 0, and the bag says so, as rosbag2's does.
    """
    return Qos(
        history=_enum(QosHistory, profile.history, QosHistory.UNKNOWN),
        depth=int(profile.depth),
        reliability=_enum(QosReliability, profile.reliability, QosReliability.UNKNOWN),
        durability=_enum(QosDurability, profile.durability, QosDurability.UNKNOWN),
        deadline=_bag_time(profile.deadline),
        lifespan=_bag_time(profile.lifespan),
        liveliness=_enum(QosLiveliness, profile.liveliness, QosLiveliness.UNKNOWN),
        liveliness_lease_duration=_bag_time(profile.liveliness_lease_duration),
        avoid_ros_namespace_conventions=bool(profile.avoid_ros_namespace_conventions),
    )


@dataclass
class _Topic:
    """One recorded topic: the table's entry, its name as resolved here, and the subscription as it is now."""

    spec: TopicSpec  # the table's
    name: str  # resolved under the node's namespace: the name in the bag
    qos: QosSpec  # what ``subscription`` was made with
    subscription: Subscription | None = None


class RecorderNode(Node):
    def __init__(self) -> None:
        super().__init__("recorder_node")
        output = declare(self, "output", "bag", "rosbag2 directory to create (must not exist)")
        flush_interval = declare(self, "flush_interval_sec", 2.0, "seconds between chunk flushes to disk: "
                                 "the most a killed recorder loses", min_value=0.1, max_value=86_400.0)
        pairs = declare(self, "pair_namespaces", "", "the sim/learner pairs whose topics to record, comma-separated "
                        "namespaces (e.g. pair0,pair1); '' for one pair in this node's own namespace")
        self.pair_namespaces = pair_namespace_list(pairs)
        self.topics = [_Topic(spec, self.resolve_topic_name(name), spec.qos)
                       for spec, name in recorded_names(self.pair_namespaces)]
        self.episode_seqs = {topic.name: SequenceTracker() for topic in self.topics if topic.spec is EPISODES}
        self.writer = BagWriter(Path(output), [replace(topic.spec, name=topic.name) for topic in self.topics])
        self.exit_code = 0
        # Triggered from a subscription's QoS event, run after it: the event's handler belongs to the
        # subscription that the look may replace.
        self._look_now = self.create_guard_condition(self._look_at_publishers)
        for topic in self.topics:
            self._subscribe(topic, topic.qos)
        # Steady: under use_sim_time, timers of the node's clock would stop with the sim.
        steady = Clock(clock_type=ClockType.STEADY_TIME)
        self.create_timer(flush_interval, self._flush, clock=steady)
        self.create_timer(GRAPH_POLL_SEC, self._look_at_publishers, clock=steady)
        self.get_logger().info(f"recording {len(self.topics)} topics under {self.get_namespace()} into {output}")

    def _subscribe(self, topic: _Topic, offered: QosSpec) -> None:
        if topic.subscription is not None:
            # Before the new one: both at once would record twice what reaches both.
            self.destroy_subscription(topic.subscription)
        topic.qos = offered
        topic.subscription = self.create_subscription(
            message_class(topic.spec.msgtype), topic.name, self._writer_for(topic.name), subscription_qos(offered),
            raw=True, event_callbacks=SubscriptionEventCallbacks(incompatible_qos=self._incompatible_publisher),
        )

    def _incompatible_publisher(self, _: QoSRequestedIncompatibleQoSInfo) -> None:
        # Instead of rclpy's default warning ("No messages will be received from it"): the
        # subscription is adapted to it (if the graph already lists it; else at the next poll).
        self._look_now.trigger()

    def _look_at_publishers(self) -> None:
        """Record each topic's offered QoS once its publishers show; adapt subscriptions they do not match."""
        for topic in self.topics:
            offers = [info.qos_profile for info in self.get_publishers_info_by_topic(topic.name)]
            if not offers:
                continue
            if not self.writer.has_topic(topic.name):
                self._guarded(self.writer.add_topic, topic.name, [bag_qos(offer) for offer in offers])
            wanted = adapted_qos(topic.spec.qos, offers)
            if (wanted.reliable, wanted.transient_local) != (topic.qos.reliable, topic.qos.transient_local):
                self.get_logger().info(
                    f"{topic.name}: subscribing {'reliable' if wanted.reliable else 'best effort'}, "
                    f"{'transient local' if wanted.transient_local else 'volatile'}, as its "
                    f"{len(offers)} publisher(s) offer")
                self._subscribe(topic, wanted)

    def _flush(self) -> None:
        self._guarded(self.writer.flush)

    def _guarded(self, write: Callable[..., object], *args) -> None:
        """``write(*args)``, ending the node if the bag was closed (``_stop``)."""
        try:
            write(*args)
        except RecordingStopped as stopped:
            self._stop(stopped)

    def _stop(self, stopped: RecordingStopped) -> None:
        """The bag is closed (see ``BagWriter``): say so once, and end the node."""
        if self.exit_code:
            return
        self.exit_code = 1
        self.get_logger().error(f"recording stopped: {stopped}")
        self.context.try_shutdown()

    def _writer_for(self, topic: str):
        def write(data: bytes, info: dict) -> None:
            log_time = self.get_clock().now().nanoseconds  # first: the time of receipt, as near as it gets
            try:
                if not self.writer.has_topic(topic):  # its first message came before a look at its publishers
                    self.writer.add_topic(topic, [bag_qos(i.qos_profile)
                                                  for i in self.get_publishers_info_by_topic(topic)])
                self.writer.write(topic, log_time, data, info.get("source_timestamp") or None)
            except RecordingStopped as stopped:
                self._stop(stopped)

        if topic not in self.episode_seqs:
            return write

        def write_and_check(data: bytes, info: dict) -> None:
            write(data, info)  # first: a message that fails the check is still recorded
            self._check_episode_seq(topic, data)

        return write_and_check

    def _check_episode_seq(self, topic: str, data: bytes) -> None:
        """Warn about a gap in EpisodeRecord.seq as soon as it shows.

        The seq is read from the CDR bytes without decoding the record (its
        arrays can be large); an encoding that parser does not handle is
        decoded in full instead.
        """
        seq = episode_seq_from_cdr(data)
        if seq is None:
            seq = deserialize_message(data, EpisodeRecord).seq
        tracker = self.episode_seqs[topic]
        where = f"{topic}: " if len(self.episode_seqs) > 1 else ""
        highest = tracker.highest
        tracker.add(seq)
        if highest is None:
            if seq:
                self.get_logger().info(f"{where}first episode has seq {seq}: seq 0..{seq - 1} came before the "
                                       f"recording")
        elif seq > highest + 1:
            missing = f"{highest + 1}" if seq == highest + 2 else f"{highest + 1}..{seq - 1}"
            self.get_logger().warning(f"{where}episode seq gap: {missing} missing (got {seq} after {highest})")
        elif seq <= highest:
            self.get_logger().warning(f"{where}episode seq {seq} after {highest}: a duplicate or out of order")

    def close(self) -> None:
        """Close the bag and report what it holds.

        The report does not go through the node's logger: close() runs after
        SIGINT/SIGTERM shut the context down (``node_common.runner``), which
        took the node's /rosout publisher with it, and rcl then prints "Failed
        to publish log message to rosout" for every line logged there. A
        logger of its own name is bound to no /rosout publisher: it writes to
        the console and the ROS log file only.
        """
        self.writer.close()
        logger = rclpy.logging.get_logger(f"{self.get_logger().name}.bag")
        counts = ", ".join(f"{topic} {count}" for topic, count in self.writer.counts.items() if count)
        logger.info(f"closed {self.writer.path}: {counts or 'no messages'}")
        for topic, tracker in self.episode_seqs.items():
            check = tracker.result()
            # Two calls, not one picked per topic: rclpy refuses one call site logging at two severities.
            if check.ok:
                logger.info(f"{topic}: {check.summary()}")
            else:
                logger.warning(f"{topic}: {check.summary()}")


def pair_namespace_list(text: str) -> list[str]:
    """``pair_namespaces`` as a list of names, relative or absolute ("" alone: one pair in the node's own
    namespace); an empty entry among several, or a repeat, refused."""
    namespaces = [part.strip() if part.strip() in ("", "/") else part.strip().rstrip("/") for part in text.split(",")]
    if len(namespaces) > 1 and ("" in namespaces or len(set(namespaces)) != len(namespaces)):
        raise ValueError(f"pair_namespaces {text!r}: expected distinct namespaces, e.g. pair0,pair1")
    return namespaces


def recorded_names(pair_namespaces: list[str]) -> list[tuple[TopicSpec, str]]:
    """Each topic to record, with its name as the node resolves it: a pair's topics under each pair's
    namespace (``of_pair``), the curriculum's under the node's own."""
    def under(namespace: str, spec: TopicSpec) -> str:
        return f"{namespace.rstrip('/')}/{spec.relative_name}" if namespace else spec.relative_name

    return [(spec, under(namespace, spec)) for spec in RECORDED_TOPICS
            for namespace in (pair_namespaces if spec.of_pair else [""])]


def main(args=None) -> int:
    return spin_node(RecorderNode, args)


if __name__ == "__main__":
    raise SystemExit(main())

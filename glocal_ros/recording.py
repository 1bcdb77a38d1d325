"""Writing the graph's messages to a rosbag2 directory (metadata.yaml v9 + MCAP), as rosbag2 Jazzy does.

ROS-free: messages arrive already CDR-serialized (the recorder subscribes
raw), so nothing is re-encoded. Chunks are zstd-compressed (STORAGE mode;
MESSAGE mode is rejected by rosbag2's MCAP plugin and FILE mode makes a
``.mcap.zstd`` that MCAP tools cannot open). Every message definition is
embedded as ros2msg, so rosbags, the ``mcap`` library and Foxglove can decode
the bag without glocal_interfaces installed.

What a bag holds, field by field as ``ros2 bag record`` (Jazzy) writes it
(``Rosbag2Writer`` adds to rosbags' writer what it leaves out):
- each MCAP channel's metadata: ``offered_qos_profiles`` (what the topic's
  publishers offered when the recorder first saw the topic, else the table's
  QoS) and ``topic_type_hash`` (the type's RIHS01 hash, as in metadata.yaml's
  ``type_description_hash``);
- each message's ``log_time``: the recorder node's clock when it received the
  message (the sim clock under ``use_sim_time``), and ``publish_time``: the
  publisher's source timestamp;
- ``ros_distro: jazzy`` in metadata.yaml and in the metadata record the MCAP
  file embeds: the distro whose message definitions and hashes the bag holds.

Topic names are stored resolved: a recorder under the namespace ``/robot1``
stores ``/robot1/glocal/episodes``. ``table_topic`` is the one place that
maps a recorded name back to its entry of the topic table, under any
namespace; every reader of bags by topic (bag check, the analysis, replay)
goes through it.

Reading side: ``open_bag`` (a user-facing ValueError for a missing or killed
recorder's bag), ``message_counts``, and the EpisodeRecord.seq checks
(``SequenceTracker`` live in the recorder, ``episode_sequence`` on a bag).
"""

from __future__ import annotations

import bisect
import os
import struct
import threading
from collections import defaultdict
from contextlib import contextmanager
from dataclasses import dataclass, field
from io import BytesIO
from pathlib import Path
from typing import Iterable, Iterator, Sequence

from rosbags.interfaces import Connection
from rosbags.rosbag2 import CompressionFormat, CompressionMode, Reader, ReaderError, StoragePlugin, Writer, WriterError
from rosbags.rosbag2.metadata import QosDurability, QosHistory, QosLiveliness, QosReliability, QosTime
from rosbags.rosbag2.storage_mcap import Channel, McapWriter, write_channel, write_record, write_string, write_uint16
from rosbags.rosbag2.storage_mcap import write_uint32, write_uint64
from rosbags.rosbag2.writer import Qos
from rosbags.typesys import Stores, TypesysError, get_types_from_msg, get_typestore
from rosbags.typesys.store import Typestore
from ruamel.yaml import YAML

from glocal_ros.paths import interface_definitions_dir
from glocal_ros.topics import EPISODES, GRAPH_TOPICS, RECORDED_TOPICS, TopicSpec

INTERFACE_PACKAGE = "glocal_interfaces"
#: The space a recording bag keeps free for closing itself on a full disk (see ``BagWriter``).
RESERVE_FILE = ".space-reserve"
#: metadata.yaml's ``ros_distro``: the distro whose message definitions and RIHS01 hashes the bag holds
#: (the graph's typestore is Jazzy's). rosbag2 writes its own ``$ROS_DISTRO`` there; rosbags writes "rosbags".
ROS_DISTRO = "jazzy"


def graph_typestore(definitions_dir: Path | None = None) -> Typestore:
    """Jazzy's standard types plus glocal_interfaces, read from its .msg files."""
    typestore = get_typestore(Stores.ROS2_JAZZY)
    folder = definitions_dir or interface_definitions_dir()
    types = {}
    for msg_file in sorted(folder.glob("*.msg")):
        types.update(get_types_from_msg(msg_file.read_text(), f"{INTERFACE_PACKAGE}/msg/{msg_file.stem}"))
    typestore.register(types)
    return typestore



def message_definition(msgtype: str, typestore: Typestore) -> str:
    """``msgtype``'s ros2msg schema text, as a bag's MCAP schema record holds it.

    The type's own fields, then each type it uses after a line of 80 ``=`` and ``MSG: pkg/Name``: the
    text rosbags' writer embeds for a channel (the recorder's bags) and the text foxglove_bridge sends
    with a channel, so a live viewer decodes what it gets as it decodes a bag. ``KeyError`` for a type
    the typestore does not know.
    """
    try:
        text, _ = typestore.generate_msgdef(msgtype, ros_version=2)
    except TypesysError as error:  # rosbags' own error for an unknown type
        raise KeyError(msgtype) from error
    return text

# --- topic names under a namespace ---------------------------------------------------------------

def table_topic(name: str, specs: Iterable[TopicSpec] = GRAPH_TOPICS) -> TopicSpec | None:
    """The entry of the topic table that ``name`` is, under any namespace; None for another topic.

    ``/glocal/episodes`` and ``/robot1/glocal/episodes`` are both ``EPISODES``:
    a recorder resolves the table's names under its own namespace, as
    ``ros2 bag record`` does, and a bag stores the resolved names. The table's
    names are absolute, so a suffix match falls on a namespace boundary; the
    longest match wins should one table name ever end another.
    """
    found = None
    for spec in specs:
        if name.endswith(spec.name) and (found is None or len(spec.name) > len(found.name)):
            found = spec
    return found


def topic_namespace(name: str, spec: TopicSpec) -> str | None:
    """The namespace (``/`` for the root) under which ``name`` is ``spec``, None when it is not ``spec``."""
    if table_topic(name, (spec,)) is None:
        return None
    return name[: -len(spec.name)] or "/"


def in_namespace(namespace: str, spec: TopicSpec) -> str:
    """``spec``'s name under ``namespace`` (``/`` or ``/robot1``), as a recorder there stores it."""
    return namespace.rstrip("/") + spec.name


def _table_qos(spec: TopicSpec) -> Qos:
    """The QoS the table says ``spec``'s publishers offer: a bag's record when no publisher was seen."""
    zero = QosTime(sec=0, nsec=0)  # RMW_DURATION_UNSPECIFIED: the publishers' default
    return Qos(
        history=QosHistory.KEEP_LAST,
        depth=spec.qos.depth,
        reliability=QosReliability.RELIABLE if spec.qos.reliable else QosReliability.BEST_EFFORT,
        durability=QosDurability.TRANSIENT_LOCAL if spec.qos.transient_local else QosDurability.VOLATILE,
        deadline=zero,
        lifespan=zero,
        liveliness=QosLiveliness.AUTOMATIC,
        liveliness_lease_duration=zero,
        avoid_ros_namespace_conventions=False,
    )


# --- rosbags' writer, completed to what rosbag2 Jazzy writes ----------------------------------------

class _McapStorage(McapWriter):
    """rosbags' MCAP storage plus what rosbag2's MCAP plugin writes and rosbags does not.

    A channel's metadata gets ``topic_type_hash`` beside ``offered_qos_profiles``;
    a message gets its own ``publish_time`` (rosbags writes the log time in
    both fields); the metadata record embedded at close says ``ros_distro``.
    Mirrors ``McapWriter.add_connection`` and ``write`` of the pinned rosbags
    (constraints.txt; test_recorder_bag_details checks the result).
    """

    def add_connection(self, connection: Connection, offered_qos_profiles: str) -> None:
        metadata = BytesIO()
        write_string(metadata, "offered_qos_profiles")
        write_string(metadata, offered_qos_profiles)
        write_string(metadata, "topic_type_hash")
        write_string(metadata, connection.digest)
        self.channels.append(Channel(connection.id, connection.msgtype, connection.topic,
                                     connection.ext.serialization_format, metadata.getvalue()))
        self.channel_stats[connection.id] = 0
        write_channel(self.chunk.bio, self.channels[-1], self.schemas)

    def write(self, connection: Connection, timestamp: int, data: bytes | memoryview,
              publish_time: int | None = None) -> None:
        """A message record: ``timestamp`` is its log time, ``publish_time`` (default: the same) its send time."""
        self.message_start_time = min(timestamp, self.message_start_time)
        self.message_end_time = max(timestamp, self.message_end_time)
        self.channel_stats[connection.id] += 1
        self.chunk.message_start_time = min(timestamp, self.chunk.message_start_time)
        self.chunk.message_end_time = max(timestamp, self.chunk.message_end_time)
        self.chunk.msgs[connection.id].append((timestamp, self.chunk.bio.tell()))
        record = BytesIO()
        write_uint16(record, connection.id)
        write_uint32(record, 0)  # sequence: unused, 0 as rosbags writes it
        write_uint64(record, timestamp)
        write_uint64(record, timestamp if publish_time is None else publish_time)
        record.write(data)
        write_record(self.chunk.bio, 0x05, record)
        if self.chunk.bio.tell() > 2**20:
            self.close_chunk()

    def close(self, version: int, metadata: str) -> None:
        super().close(version, _with_ros_distro(metadata))


def _with_ros_distro(text: str) -> str:
    """rosbags' metadata YAML with ``ros_distro`` set to ``ROS_DISTRO`` (rosbags writes "rosbags")."""
    yaml = YAML(typ="safe")
    yaml.default_flow_style = False
    data = yaml.load(text)
    information = data.get("rosbag2_bagfile_information", data)  # the file wraps it, the MCAP record does not
    information["ros_distro"] = ROS_DISTRO
    out = BytesIO()
    yaml.dump(data, out)
    return out.getvalue().decode()


class Rosbag2Writer(Writer):
    """rosbags' ``Writer`` (MCAP) writing what rosbag2 Jazzy writes: see ``_McapStorage`` and ``write``."""

    STORAGE_PLUGINS = {**Writer.STORAGE_PLUGINS, StoragePlugin.MCAP: _McapStorage}

    def __init__(self, path: Path | str) -> None:
        super().__init__(path, version=9, storage_plugin=StoragePlugin.MCAP)
        self.set_compression(CompressionMode.STORAGE, CompressionFormat.ZSTD)

    def write(self, connection: Connection, timestamp: int, data: bytes | memoryview,
              publish_time: int | None = None) -> None:
        """``Writer.write`` with the message's ``publish_time`` (ns) besides its log time ``timestamp``."""
        if not self.storage:
            raise WriterError(f"{self.path} is not open for writing")
        self.storage.write(connection, timestamp, data, publish_time)
        self.counts[connection.id] += 1
        self.min_timestamp = min(timestamp, self.min_timestamp)
        self.max_timestamp = max(timestamp, self.max_timestamp)

    def close(self) -> None:
        super().close()
        # rosbags writes metadata.yaml with its own ros_distro; rewritten the way it is written (tmp, replace).
        tmp = self.metapath.with_suffix(".yaml.tmp")
        tmp.write_text(_with_ros_distro(self.metapath.read_text()), "utf8")
        tmp.replace(self.metapath)


class RecordingStopped(OSError):
    """The bag could not be written (disk full, I/O error) and was closed at its last flush.

    The bag is whole and readable (summary, footer, metadata.yaml): it holds
    every message up to that flush. ``lost`` counts the messages written
    after it, which are not in the bag.
    """

    def __init__(self, path: Path, error: OSError, kept: int, lost: int):
        super().__init__(error.errno, f"cannot write {path}: {error.strerror or error}; the bag was closed "
                                      f"at its last flush with {kept} messages ({lost} after it lost)")
        self.kept = kept
        self.lost = lost

    def __str__(self) -> str:
        return self.strerror


@dataclass(frozen=True)
class _Flushed:
    """What the writers' summaries need, as of the last flush: where a failed bag is cut back to."""

    offset: int
    chunks: int
    counts: dict[int, int]
    timestamps: tuple[int, int]  # rosbags Writer's (min, max)
    mcap_stats: dict[int, int]
    mcap_times: tuple[int, int]


class BagWriter:
    """A rosbag2 directory being written; thread-safe ``add_topic``, ``write`` and ``flush``.

    ``topics`` are the topics as they are stored (names resolved under the
    recorder's namespace). A topic's channel is written when the recorder
    first sees it (``add_topic``, with the QoS its publishers offer) or, at
    the latest, with its first message (the table's QoS); at close, every
    topic never seen is added with the table's QoS, so that the bag lists all
    of them.

    rosbags' MCAP writer keeps a chunk in memory until it holds 1 MiB, so a
    killed writer loses everything since its last full chunk. ``flush``
    closes the pending chunk and pushes the file to disk; a topic's schema and
    channel records go into the chunk before its first message, so what a
    kill can lose is what came after the last flush, and ``glocal-ros bag
    repair`` recovers every chunk before it.

    A write or flush that fails (a full disk) cuts the file back to the last
    flush, frees a reserve of ``RESERVE_BYTES`` taken at open, and closes the
    bag there, so that its summary and metadata.yaml still fit; it then raises
    ``RecordingStopped``, and so does every later write. This reaches into
    rosbags' ``Writer`` and ``McapWriter`` (``storage.close_chunk``,
    ``storage.bio``, their counters), which rosbags does not offer as API:
    constraints.txt pins the version, and test_bags checks it.
    """

    #: Room for a closing summary (chunk indexes: ~100 bytes a chunk, a chunk per flush or MiB)
    #: and metadata.yaml: enough for ~80,000 chunks.
    RESERVE_BYTES = 8 * 2**20

    def __init__(self, path: Path, topics: Sequence[TopicSpec] = RECORDED_TOPICS, typestore: Typestore | None = None):
        self.path = Path(path)
        self.typestore = typestore or graph_typestore()
        self._writer = Rosbag2Writer(self.path)
        self._writer.open()
        self._reserve = self.path / RESERVE_FILE
        try:
            with self._reserve.open("wb") as reserve:
                os.posix_fallocate(reserve.fileno(), 0, self.RESERVE_BYTES)
        except OSError as error:
            raise OSError(error.errno, f"cannot reserve {self.RESERVE_BYTES} bytes at {self._reserve} for "
                                       f"closing the bag: {error.strerror or error}") from error
        self._specs = {spec.name: spec for spec in topics}
        self._connections: dict[str, Connection] = {}
        self._lock = threading.Lock()
        self.counts = {spec.name: 0 for spec in topics}
        self._flushed_counts = dict(self.counts)
        self._flushed: _Flushed | None = None
        self._stopped: RecordingStopped | None = None
        self._unflushed = True  # the MCAP header
        self.flush()

    @property
    def stopped(self) -> RecordingStopped | None:
        """Why the bag was closed early, None while it records."""
        return self._stopped

    def has_topic(self, topic: str) -> bool:
        """Whether ``topic``'s channel is written (its offered QoS then fixed)."""
        return topic in self._connections

    def add_topic(self, topic: str, offered_qos: Sequence[Qos] = ()) -> bool:
        """Write ``topic``'s channel with the QoS profiles its publishers offer (none: the table's).

        A channel record cannot change once written: the first call for a
        topic decides, later ones return False.
        """
        with self._lock:
            if self._stopped:
                raise self._stopped
            if topic in self._connections:
                return False
            self._add_connection(topic, offered_qos)
            return True

    def _add_connection(self, topic: str, offered_qos: Sequence[Qos]) -> Connection:
        spec = self._specs[topic]
        # Into the pending chunk (memory), so no disk error here: it reaches the disk with the chunk.
        connection = self._writer.add_connection(topic, spec.msgtype, typestore=self.typestore,
                                                 offered_qos_profiles=list(offered_qos) or [_table_qos(spec)])
        self._connections[topic] = connection
        self._unflushed = True
        return connection

    def write(self, topic: str, timestamp_ns: int, data: bytes, publish_time_ns: int | None = None) -> None:
        """One message: ``timestamp_ns`` is its log time, ``publish_time_ns`` (default: the same) its send time."""
        with self._lock:
            if self._stopped:
                raise self._stopped
            connection = self._connections.get(topic) or self._add_connection(topic, ())
            try:
                self._writer.write(connection, timestamp_ns, data, publish_time_ns)
            except OSError as error:
                self._close_at_last_flush(error, unwritten=1)
            self.counts[topic] += 1
            self._unflushed = True

    def flush(self) -> None:
        """Close the pending chunk and sync the file: a kill after this loses nothing written before it."""
        with self._lock:
            if self._stopped:
                raise self._stopped
            if not self._unflushed:
                return
            storage = self._writer.storage
            try:
                if storage.chunk.bio.tell():  # an empty chunk would index no message at bogus times
                    storage.close_chunk()
                storage.bio.flush()
                os.fsync(storage.bio.fileno())
            except OSError as error:
                self._close_at_last_flush(error, unwritten=0)
            self._unflushed = False
            self._flushed_counts = dict(self.counts)
            self._flushed = _Flushed(storage.bio.tell(), len(storage.chunks), dict(self._writer.counts),
                                     (self._writer.min_timestamp, self._writer.max_timestamp),
                                     dict(storage.channel_stats),
                                     (storage.message_start_time, storage.message_end_time))

    def close(self) -> None:
        with self._lock:
            if self._stopped:
                return
            for topic in self._specs:
                if topic not in self._connections:
                    self._add_connection(topic, ())
            self._reserve.unlink(missing_ok=True)
            self._writer.close()

    def _close_at_last_flush(self, error: OSError, unwritten: int) -> None:
        """Cut the bag back to its last flush, close it there, and raise ``RecordingStopped``."""
        writer, storage, flushed = self._writer, self._writer.storage, self._flushed
        if flushed is None:  # the flush at open: no bag yet to keep
            raise OSError(error.errno, f"cannot write {storage.path}: {error.strerror or error}") from error
        # The buffered file may hold bytes it failed to write: drop it unflushed, reopen at the cut.
        os.ftruncate(storage.bio.fileno(), flushed.offset)
        os.close(storage.bio.fileno())
        try:
            storage.bio.close()
        except OSError:
            pass  # its buffer, which the cut dropped, and the descriptor closed above
        self._reserve.unlink(missing_ok=True)
        storage.bio = storage.path.open("r+b")
        storage.bio.seek(flushed.offset)
        del storage.chunks[flushed.chunks:]
        storage.chunk = type(storage.chunk)(2**63 - 1, 0, BytesIO(), defaultdict(list))
        # A channel added since the flush lost its record with the cut, but the summary lists
        # every channel (with its schema) again at close: it stays, with no message.
        storage.channel_stats = {cid: flushed.mcap_stats.get(cid, 0) for cid in storage.channel_stats}
        storage.message_start_time, storage.message_end_time = flushed.mcap_times
        writer.counts = {cid: flushed.counts.get(cid, 0) for cid in writer.counts}
        writer.min_timestamp, writer.max_timestamp = flushed.timestamps
        lost = sum(self.counts.values()) - sum(self._flushed_counts.values()) + unwritten
        self.counts = dict(self._flushed_counts)
        self._stopped = RecordingStopped(storage.path, error, sum(self.counts.values()), lost)
        try:
            writer.close()
        except OSError as close_error:
            storage.abort()
            raise OSError(close_error.errno, f"{self._stopped}; closing failed too ({close_error.strerror}): "
                                             f"`glocal-ros bag repair {self.path}` recovers the flushed chunks") \
                from error
        raise self._stopped from error


@contextmanager
def open_bag(bag: Path) -> Iterator[Reader]:
    """A rosbags Reader on a closed bag; ValueError (a message for the user) when there is none.

    A recorder that was killed leaves no metadata.yaml and MCAP files without
    a summary, which rosbags refuses: the message says how to repair them.
    """
    bag = Path(bag)
    if not bag.is_dir():
        raise ValueError(f"no bag directory at {bag}")
    hint = f"a killed recorder's bag? `glocal-ros bag repair {bag}` recovers it"
    if not (bag / "metadata.yaml").is_file():
        raise ValueError(f"{bag} has no metadata.yaml ({hint})")
    reader = Reader(bag)
    try:
        reader.open()
    except ReaderError as error:
        raise ValueError(f"cannot read {bag}: {error} ({hint})") from error
    try:
        yield reader
    finally:
        reader.close()


def message_counts(bag: Path) -> dict[str, int]:
    """Messages per topic of a closed bag, from its metadata."""
    with open_bag(bag) as reader:
        return {connection.topic: connection.msgcount for connection in reader.connections}


@dataclass
class SequenceCheck:
    """What a stream of EpisodeRecord.seq values looks like: range, holes, repeats."""

    count: int = 0
    first: int | None = None  # lowest seq seen
    last: int | None = None  # highest seq seen
    gaps: list[tuple[int, int]] = field(default_factory=list)  # (first_missing, last_missing), inclusive
    duplicates: list[int] = field(default_factory=list)  # each repeated arrival, sorted

    @property
    def ok(self) -> bool:
        """No gap and no duplicate (a first seq above 0 only means the recording began late)."""
        return not self.gaps and not self.duplicates

    @property
    def missing(self) -> int:
        return sum(last - first + 1 for first, last in self.gaps)

    def summary(self) -> str:
        if not self.count:
            return "no episodes"
        text = f"{self.count} episodes, seq {self.first}..{self.last}"
        if self.gaps:
            shown = ", ".join(_seq_range(*gap) for gap in self.gaps[:10])
            more = f" and {len(self.gaps) - 10} more" if len(self.gaps) > 10 else ""
            text += f"; {self.missing} missing in {len(self.gaps)} gaps: {shown}{more}"
        else:
            text += "; no gaps"
        if self.duplicates:
            shown = ", ".join(str(seq) for seq in self.duplicates[:10])
            text += f"; {len(self.duplicates)} duplicates: {shown}{' ...' if len(self.duplicates) > 10 else ''}"
        if self.first:
            text += f" (seq 0..{self.first - 1} precede the recording)"
        return text


def _seq_range(first: int, last: int) -> str:
    return str(first) if first == last else f"{first}..{last}"


class SequenceTracker:
    """Seq values as they arrive, kept as sorted runs of consecutive values.

    Memory grows with the number of gaps, not of episodes, so the recorder can
    track a run of millions of episodes; late arrivals that fill a gap close
    it, and a value inside a run is a duplicate.
    """

    def __init__(self) -> None:
        self._starts: list[int] = []  # run starts, sorted: the bisect key
        self._ends: list[int] = []  # inclusive run ends
        self.count = 0
        self.duplicates: list[int] = []

    @property
    def highest(self) -> int | None:
        return self._ends[-1] if self._ends else None

    def add(self, seq: int) -> None:
        self.count += 1
        i = bisect.bisect_right(self._starts, seq) - 1  # the run starting at or before seq
        if i >= 0 and seq <= self._ends[i]:
            bisect.insort(self.duplicates, seq)
            return
        joins_left = i >= 0 and self._ends[i] == seq - 1
        joins_right = i + 1 < len(self._starts) and self._starts[i + 1] == seq + 1
        if joins_left and joins_right:
            self._ends[i] = self._ends.pop(i + 1)
            del self._starts[i + 1]
        elif joins_left:
            self._ends[i] = seq
        elif joins_right:
            self._starts[i + 1] = seq
        else:
            self._starts.insert(i + 1, seq)
            self._ends.insert(i + 1, seq)

    def result(self) -> SequenceCheck:
        if not self._starts:
            return SequenceCheck(count=self.count)
        gaps = [(end + 1, start - 1) for end, start in zip(self._ends, self._starts[1:])]
        return SequenceCheck(self.count, self._starts[0], self._ends[-1], gaps, list(self.duplicates))


def sequence_check(seqs: Iterable[int]) -> SequenceCheck:
    tracker = SequenceTracker()
    for seq in seqs:
        tracker.add(seq)
    return tracker.result()


def episode_topics(bag: Path) -> list[str]:
    """The bag's EpisodeRecord topics: the table's ``/glocal/episodes`` under whatever namespace it was recorded."""
    with open_bag(bag) as reader:
        return sorted({c.topic for c in reader.connections if table_topic(c.topic) is EPISODES})


def episode_sequence(bag: Path, topic: str | None = None) -> SequenceCheck:
    """The seq values of the bag's EpisodeRecords on ``topic``, checked for gaps and duplicates.

    ``topic`` defaults to the bag's one episodes topic (``episode_topics``);
    ValueError when it holds several (one per namespace: seq counts per sim
    node, so they are checked one by one).
    """
    if topic is None:
        found = episode_topics(bag)
        if len(found) > 1:
            raise ValueError(f"{bag} has episodes of several sim nodes ({', '.join(found)}): name one")
        topic = found[0] if found else EPISODES.name
    typestore = graph_typestore()
    tracker = SequenceTracker()
    with open_bag(bag) as reader:
        connections = [connection for connection in reader.connections if connection.topic == topic]
        if connections:  # an empty selection would mean every topic to rosbags
            for connection, _, data in reader.messages(connections=connections):
                tracker.add(int(typestore.deserialize_cdr(data, connection.msgtype).seq))
    return tracker.result()


# CDR encapsulation identifiers (the first two bytes of every serialized message).
_CDR_BE, _CDR_LE = b"\x00\x00", b"\x00\x01"


def episode_seq_from_cdr(data: bytes) -> int | None:
    """EpisodeRecord.seq read straight from its CDR bytes, None for an encoding not handled.

    The recorder checks every episode as it arrives; decoding only the header
    and seq (a dozen bytes) instead of the whole record (every observation,
    action and joint position) keeps that check free. Layout after the 4-byte
    encapsulation header: Header.stamp (int32 sec, uint32 nanosec), frame_id
    (uint32 length including the NUL, bytes), then seq, a uint64 aligned to 8
    relative to the end of the encapsulation header. Only classic CDR (XCDR1,
    what rmw_fastrtps sends) is parsed; anything else returns None and the
    caller decodes the message fully.
    """
    kind = bytes(data[:2])
    if kind not in (_CDR_BE, _CDR_LE):
        return None
    order = "<" if kind == _CDR_LE else ">"
    (frame_id_length,) = struct.unpack_from(order + "I", data, 4 + 8)
    offset = 8 + 4 + frame_id_length
    offset = (offset + 7) & ~7
    if 4 + offset + 8 > len(data):
        return None
    (seq,) = struct.unpack_from(order + "Q", data, 4 + offset)
    return seq

"""Repairing the bag of a recorder that was killed (SIGKILL, power loss, OOM), and copying part of a bag.

Such a bag has MCAP files without summary and footer, and no metadata.yaml
(rosbags writes both on close), so no reader accepts it. Every record that
reached the disk whole is still there: ``repair_bag`` reads the MCAP files
record by record (``mcap``'s StreamReader, which needs no summary), drops the
truncated tail, writes what it recovered through ``Rosbag2Writer`` as
``BagWriter`` does (same schemas, channels with their offered QoS profiles
and type hashes, each message's log and publish times, zstd chunks,
metadata.yaml v9) into a fresh directory, then swaps it in and keeps the
damaged original next to it as ``BAG.damaged``: nothing is deleted.

What is lost: the recorder's writer keeps the chunk being filled in memory
until its next flush (every few seconds, or 1 MiB of messages), so the
messages after the last complete chunk never reached the disk. The space
the recorder reserved for closing (``RESERVE_FILE``) is freed first: a disk
that filled up then has room for the repaired copy.

``copy_topics`` writes the same way a new bag holding only some topics of an
intact one (a benchmark keeps a run's curriculum and learner topics, a few
hundred kilobytes, where the whole bag is tens of megabytes). ROS-free.
"""

from __future__ import annotations

import shutil
import tempfile
from dataclasses import dataclass, field
from pathlib import Path, PurePath
from typing import BinaryIO, Callable, Iterator

from mcap.records import Channel, Chunk, Message, Schema
from mcap.stream_reader import StreamReader, breakup_chunk
from rosbags.interfaces import Connection
from rosbags.rosbag2 import Reader, ReaderError
from rosbags.rosbag2.metadata import parse_qos
from ruamel.yaml import YAML, YAMLError
from rosbags.typesys import Stores, get_types_from_idl, get_types_from_msg, get_typestore

from glocal_ros.recording import RESERVE_FILE, Rosbag2Writer

DAMAGED_SUFFIX = ".damaged"
#: The channel of a topic that ``copy_topics`` leaves out.
_LEFT_OUT = object()
_IDL_SEPARATOR = "=" * 80 + "\n"


@dataclass
class RepairResult:
    """What ``repair_bag`` did: ``repaired`` is False for a bag that was intact (left as it was)."""

    bag: Path
    repaired: bool
    counts: dict[str, int]  # messages per topic in the bag as it is now
    damaged: Path | None = None  # where the original went
    dropped_chunks: int = 0  # complete-looking chunks that failed to decompress
    dropped_bytes: int = 0  # trailing bytes that held no complete record
    skipped_messages: int = 0  # messages of a channel without schema (not writable to rosbag2)


@dataclass
class _Recovery:
    """State of one repair: the output writer and the connections made so far."""

    writer: Rosbag2Writer
    connections: dict[tuple[str, str, str, str], Connection] = field(default_factory=dict)
    counts: dict[str, int] = field(default_factory=dict)
    dropped_chunks: int = 0
    dropped_bytes: int = 0
    skipped_messages: int = 0


def mcap_files(bag: Path) -> list[Path]:
    """The bag's MCAP files, in split order (rosbag2 numbers them ``NAME_0.mcap``, ``NAME_1.mcap``, ...)."""

    def split_index(path: Path) -> tuple[int, str]:
        stem, _, number = path.stem.rpartition("_")
        return (int(number), path.name) if stem and number.isdigit() else (-1, path.name)

    return sorted(bag.glob("*.mcap"), key=split_index)


def bag_is_intact(bag: Path) -> bool:
    """rosbags reads the bag and every MCAP file in it is one that metadata.yaml names."""
    metadata = bag / "metadata.yaml"
    if not metadata.is_file():
        return False
    try:
        with Reader(bag):
            pass
        info = YAML(typ="safe").load(metadata.read_text())["rosbag2_bagfile_information"]
        named = {PurePath(name).name for name in info["relative_file_paths"]}
    except (ReaderError, OSError, KeyError, TypeError, ValueError, YAMLError):
        return False
    # A file metadata.yaml does not name: a later split the recorder was killed in.
    return {path.name for path in mcap_files(bag)} <= named


def _rihs01(schema: Schema) -> str:
    """The type hash rosbag2 keeps per topic, computed from the definition embedded in the MCAP."""
    typestore = get_typestore(Stores.EMPTY)
    text = schema.data.decode()
    if schema.encoding == "ros2msg":
        typestore.register(get_types_from_msg(text, schema.name))
    elif schema.encoding in ("ros2idl", "omgidl"):
        if text.startswith(_IDL_SEPARATOR + "IDL: "):
            for definition in text.split(_IDL_SEPARATOR)[1:]:
                typestore.register(get_types_from_idl(definition.split("\n", 1)[1]))
        else:
            typestore.register(get_types_from_idl(text))
    else:
        raise ValueError(f"schema {schema.name} has encoding {schema.encoding!r}, not a ROS 2 one")
    return typestore.hash_rihs01(schema.name)


def _records(stream: BinaryIO, recovery: _Recovery) -> Iterator[Schema | Channel | Message]:
    """Every complete Schema, Channel and Message record of one MCAP file, chunks unpacked.

    Reading stops at the first record that cannot be read whole: after a
    kill that is the chunk (or message index) being written.
    """
    size = stream.seek(0, 2)
    stream.seek(0)
    good_end = 0
    reader = StreamReader(stream, emit_chunks=True, validate_crcs=True)
    try:
        for record in reader.records:
            if isinstance(record, Chunk):
                try:
                    inner = breakup_chunk(record, validate_crc=True)
                except Exception:  # noqa: BLE001 - any decoding failure means a damaged chunk
                    recovery.dropped_chunks += 1
                    inner = []
                yield from (r for r in inner if isinstance(r, (Schema, Channel, Message)))
            elif isinstance(record, (Schema, Channel, Message)):
                yield record
            good_end = stream.tell()
    except Exception:  # noqa: BLE001 - the truncated tail: EndOfFile, short struct, bad magic
        pass
    else:
        good_end = size
    recovery.dropped_bytes += size - good_end


def copy_topics(bag: Path, destination: Path, keep: Callable[[str], bool]) -> dict[str, int]:
    """Write a new bag at ``destination`` with the messages of ``bag``'s topics that ``keep`` accepts, as
    they were recorded (definitions, QoS profiles, log and publish times); the messages copied per topic.

    ``ValueError`` for a bag that is not intact (repair it first) and for a ``destination`` that exists.
    """
    bag, destination = Path(bag), Path(destination)
    if not bag_is_intact(bag):
        raise ValueError(f"{bag} is not an intact MCAP rosbag2 bag (glocal-ros bag repair first)")
    if destination.exists():
        raise ValueError(f"{destination} exists: a copy never overwrites")
    writer = Rosbag2Writer(destination)
    copy = _Recovery(writer)
    try:
        writer.open()
        for path in mcap_files(bag):
            _recover_file(path, copy, keep)
        writer.close()
    except BaseException:
        writer.abort()
        shutil.rmtree(destination, ignore_errors=True)
        raise
    return dict(copy.counts)


def _recover_file(path: Path, recovery: _Recovery, keep: Callable[[str], bool] | None = None) -> None:
    """Write every message of ``path`` (of a topic ``keep`` accepts, when given) through ``recovery``."""
    schemas: dict[int, Schema] = {}
    channels: dict[int, object] = {}  # a Connection; None: a channel without schema; _LEFT_OUT: not copied
    with path.open("rb") as stream:
        for record in _records(stream, recovery):
            if isinstance(record, Schema):
                schemas[record.id] = record
            elif isinstance(record, Channel):
                if keep is None or keep(record.topic):
                    channels[record.id] = _connection(record, schemas.get(record.schema_id), recovery)
                else:
                    channels[record.id] = _LEFT_OUT
            else:
                connection = channels.get(record.channel_id)
                if connection is _LEFT_OUT:
                    continue
                if connection is None:
                    recovery.skipped_messages += 1
                    continue
                recovery.writer.write(connection, record.log_time, record.data, record.publish_time)
                recovery.counts[connection.topic] += 1


def _connection(channel: Channel, schema: Schema | None, recovery: _Recovery) -> Connection | None:
    """The output connection for a channel: one per (topic, type, QoS, encoding), across files."""
    if schema is None:
        return None
    qos_text = channel.metadata.get("offered_qos_profiles", "")
    key = (channel.topic, schema.name, qos_text, channel.message_encoding)
    if key not in recovery.connections:
        recovery.connections[key] = recovery.writer.add_connection(
            channel.topic,
            schema.name,
            msgdef=schema.data.decode(),
            # The hash the recorder wrote (rosbag2's MCAP plugin writes it too), else computed from the schema.
            rihs01=channel.metadata.get("topic_type_hash") or _rihs01(schema),
            serialization_format=channel.message_encoding,
            offered_qos_profiles=parse_qos(qos_text),
        )
        recovery.counts.setdefault(channel.topic, 0)
    return recovery.connections[key]


def _damaged_path(bag: Path) -> Path:
    """``BAG.damaged``, or ``BAG.damaged.2``, ... when an earlier repair left one."""
    candidate = bag.with_name(bag.name + DAMAGED_SUFFIX)
    number = 1
    while candidate.exists():
        number += 1
        candidate = bag.with_name(f"{bag.name}{DAMAGED_SUFFIX}.{number}")
    return candidate


def repair_bag(bag: Path) -> RepairResult:
    """Make ``bag`` readable again from whatever its MCAP files hold; see the module doc.

    Raises ValueError for something that is not an MCAP rosbag2 directory or
    holds no complete record; the bag is then left as it was.
    """
    bag = Path(bag)
    if not bag.is_dir():
        raise ValueError(f"no bag directory at {bag}")
    files = mcap_files(bag)
    if not files:
        raise ValueError(f"{bag} holds no .mcap file: not an MCAP rosbag2 bag")
    if bag_is_intact(bag):
        with Reader(bag) as reader:
            counts = {connection.topic: connection.msgcount for connection in reader.connections}
        return RepairResult(bag, repaired=False, counts=counts)

    # The new bag is written beside the old one (same file system, so the swap
    # is two renames), in a folder of its own so that its MCAP file gets the
    # bag's name.
    (bag / RESERVE_FILE).unlink(missing_ok=True)
    workdir = Path(tempfile.mkdtemp(prefix=f".{bag.name}.repair-", dir=bag.parent))
    writer = Rosbag2Writer(workdir / bag.name)
    recovery = _Recovery(writer)
    try:
        writer.open()
        for path in files:
            _recover_file(path, recovery)
        if not recovery.connections:
            raise ValueError(f"{bag}: no complete channel record in {', '.join(p.name for p in files)}, "
                             "nothing to recover (left as it was)")
        writer.close()
    except BaseException:
        writer.abort()
        shutil.rmtree(workdir, ignore_errors=True)
        raise
    damaged = _damaged_path(bag)
    bag.rename(damaged)
    (workdir / bag.name).rename(bag)
    workdir.rmdir()
    return RepairResult(bag, True, dict(recovery.counts), damaged, recovery.dropped_chunks,
                        recovery.dropped_bytes, recovery.skipped_messages)

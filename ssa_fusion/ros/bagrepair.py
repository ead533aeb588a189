"""Repair a rosbag2 MCAP bag whose recorder never closed it (SIGKILL, power loss).

Such a bag has no ``metadata.yaml`` and its ``.mcap`` has no summary, no footer and maybe a
torn last record, so plain readers (``rosbags.rosbag2.Reader``, ``ros2 bag``) refuse it.
`repair` reads every complete record of its ``.mcap`` file(s) (`bagio.read_bag` recovers
the same messages) and writes a new, closed rosbag2 v9 MCAP bag: the same topics, message
types, message definitions, QoS profiles and CDR bytes, each message at its original log
time (ns). Only the last, incomplete chunk is lost. The bytes are copied, never decoded, so
any ROS 2 message type is kept, not only those this project knows.
"""

from __future__ import annotations

import contextlib
import re
import shutil
import struct
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

from rosbags.rosbag2 import StoragePlugin, Writer
from rosbags.rosbag2.enums import CompressionFormat, CompressionMode

from ssa_fusion.ros.bagio import MCAP_MAGIC, ROS_DISTRO, BagError, set_ros_distro, typestore

if TYPE_CHECKING:
    from mcap.records import Channel, Schema

SEPARATOR = "=" * 80


@dataclass(frozen=True)
class _Topic:
    """One connection of the repaired bag: topic, type and what rosbag2 stores with it."""

    topic: str
    msgtype: str
    msgdef: str
    rihs01: str
    qos: tuple[Any, ...] = ()


@dataclass
class _Scan:
    """What the complete records of one or more MCAP files hold."""

    topics: dict[tuple[str, str], _Topic] = field(default_factory=dict)
    messages: list[tuple[int, int, tuple[str, str], bytes]] = field(default_factory=list)
    """(log time ns, order read, (topic, type), CDR bytes)."""
    discarded_bytes: int = 0
    """Bytes after the last complete record (the torn end), over all files."""
    complete: bool = True
    """Every file ended with its footer and magic (its writer closed it)."""


@dataclass
class RepairResult:
    """What `repair` wrote."""

    out: Path
    """The repaired bag directory."""
    counts: dict[str, int]
    """Messages written per topic."""
    sources: list[Path]
    """The ``.mcap`` files read."""
    discarded_bytes: int
    """Bytes at the end of the input that held no complete record (the lost tail)."""
    complete: bool
    """The input had been closed properly (nothing needed repair; it was copied)."""

    def line(self, bag: Path) -> str:
        """One line for the user: where, and how many messages per topic."""
        per_topic = ", ".join(f"{t} {n}" for t, n in sorted(self.counts.items()))
        total = sum(self.counts.values())
        tail = ("the input was complete already" if self.complete else
                f"dropped an incomplete tail of {self.discarded_bytes} bytes"
                if self.discarded_bytes else "no torn record at the end")
        return (f"repaired {bag} -> {self.out}: recovered {total} messages ({per_topic}); "
                f"{tail}")


def repaired_path(bag: Path) -> Path:
    """Return ``<bag>_repaired`` next to the input (for ``x.mcap``: ``x_repaired``)."""
    bag = Path(bag)
    name = bag.stem if bag.is_file() else bag.name
    return bag.parent / f"{name}_repaired"


def mcap_files(bag: Path) -> list[Path]:
    """Return the ``.mcap`` files of a bag directory (sorted), or the bare ``.mcap`` file.

    BagError when there are none.
    """
    bag = Path(bag)
    if not bag.exists():
        raise BagError(f"{bag}: no such bag")
    if bag.is_file():
        if bag.suffix != ".mcap":
            raise BagError(f"{bag}: not a rosbag2 directory nor an .mcap file")
        return [bag]
    files = sorted(p for p in bag.glob("*.mcap") if p.is_file())
    if not files:
        raise BagError(f"{bag}: not a rosbag2 MCAP bag (no .mcap file in it)")
    return files


def repair(bag: Path | str, out: Path | str | None = None) -> RepairResult:
    """Write the complete records of bag `bag` as a new closed rosbag2 v9 MCAP bag.

    `bag`: a rosbag2 directory or a bare ``.mcap``; the new bag goes to `out` (default
    `repaired_path`). BagError (the message names the file and why): no such bag, not an MCAP
    bag, an unreadable file, an existing `out`, or no complete message to recover.
    """
    bag = Path(bag)
    files = mcap_files(bag)
    target = Path(out) if out is not None else repaired_path(bag)
    if target.exists():
        raise BagError(f"{target} exists already; choose another --out or delete it")
    scan = _Scan()
    for f in files:
        _scan_file(f, scan)
    if not scan.messages:
        raise BagError(f"{bag}: no complete message to recover")
    scan.messages.sort(key=lambda m: (m[0], m[1]))
    counts = _write(target, scan, _ros_distro(bag))
    return RepairResult(target, counts, files, scan.discarded_bytes, scan.complete)


def _scan_file(path: Path, scan: _Scan) -> None:
    """Add the schemas, channels and messages of the complete records of `path` to `scan`."""
    from mcap.exceptions import McapError
    from mcap.records import Channel, Footer, Message, Schema
    from mcap.stream_reader import StreamReader

    try:
        f = path.open("rb")
    except OSError as exc:
        raise BagError(f"{path}: cannot read: {exc.strerror or exc}") from exc
    with f:
        try:
            head = f.read(len(MCAP_MAGIC))
        except OSError as exc:
            raise BagError(f"{path}: cannot read: {exc.strerror or exc}") from exc
        if head != MCAP_MAGIC:
            raise BagError(f"{path}: not an MCAP file (no MCAP magic at its start)")
        f.seek(0)
        size = path.stat().st_size
        schemas: dict[int, Schema] = {}
        channels: dict[int, _Topic | None] = {}
        good_end = len(MCAP_MAGIC)
        footer = False
        try:
            for record in StreamReader(f, validate_crcs=True).records:
                if isinstance(record, Schema):
                    schemas[record.id] = record
                elif isinstance(record, Channel):
                    channels[record.id] = _topic(path, record, schemas.get(record.schema_id))
                elif isinstance(record, Message):
                    conn = channels.get(record.channel_id)
                    if conn is None:
                        continue  # a channel without schema or type: nothing to write it as
                    key = (conn.topic, conn.msgtype)
                    scan.topics.setdefault(key, conn)
                    scan.messages.append((record.log_time, len(scan.messages), key,
                                          bytes(record.data)))
                elif isinstance(record, Footer):
                    footer = True
                good_end = f.tell()
        except (McapError, EOFError, ValueError, struct.error):
            pass  # the torn end of an unfinished file: keep what came before
        except OSError as exc:
            raise BagError(f"{path}: cannot read: {exc.strerror or exc}") from exc
    if footer:  # after the footer comes the closing magic only
        good_end = size
    scan.discarded_bytes += max(0, size - good_end)
    scan.complete = scan.complete and footer


def _topic(path: Path, channel: Channel, schema: Schema | None) -> _Topic | None:
    """Return the connection to write `channel`'s messages on, or None without a schema."""
    if schema is None or not schema.name:
        return None
    if channel.message_encoding != "cdr":
        raise BagError(f"{path}: topic {channel.topic} is {channel.message_encoding!r} "
                       "encoded; a rosbag2 bag holds CDR")
    msgdef = schema.data.decode("utf-8", errors="replace")
    meta = dict(channel.metadata)
    rihs01 = meta.get("topic_type_hash", "")
    if not rihs01.startswith("RIHS01_"):
        rihs01 = _rihs01(path, channel.topic, schema.name, schema.encoding, msgdef)
    qos: tuple[Any, ...] = ()
    if "offered_qos_profiles" in meta:
        from rosbags.rosbag2.metadata import parse_qos

        try:
            qos = tuple(parse_qos(meta["offered_qos_profiles"]))
        except Exception:  # rosbags raises several types on malformed YAML: keep none
            qos = ()
    return _Topic(channel.topic, schema.name, msgdef, rihs01, qos)


def _rihs01(path: Path, topic: str, msgtype: str, encoding: str, msgdef: str) -> str:
    """Return the RIHS01 type hash of `msgtype`.

    As its recorded definition `msgdef` gives it (the hash rosidl computes), else as the
    project's typestore knows the type.
    """
    from rosbags.typesys import Stores, get_types_from_idl, get_types_from_msg, get_typestore

    try:
        store = get_typestore(Stores.EMPTY)
        if encoding == "ros2msg":
            types = get_types_from_msg(msgdef, msgtype)
        elif msgdef.startswith(f"{SEPARATOR}\nIDL: "):
            types = {}
            for part in msgdef.split(SEPARATOR)[1:]:
                types.update(get_types_from_idl(part.split("\n", 1)[1]))
        else:
            types = get_types_from_idl(msgdef)
        store.register(types)
        return str(store.hash_rihs01(msgtype))
    except Exception:  # rosbags raises several types on a definition it cannot parse
        known = typestore()
        if msgtype in known.fielddefs:
            return str(known.hash_rihs01(msgtype))
    raise BagError(f"{path}: cannot parse the message definition of {msgtype} on {topic}")


def _ros_distro(bag: Path) -> str:
    """Return the ros_distro of the input's metadata.yaml if it has one, else this project's."""
    try:
        found = re.search(r"^\s*ros_distro:\s*(\w+)", (bag / "metadata.yaml").read_text(),
                          re.MULTILINE)
    except (OSError, UnicodeDecodeError):
        return ROS_DISTRO
    return found.group(1) if found and found.group(1) != "rosbags" else ROS_DISTRO


def _write(target: Path, scan: _Scan, distro: str) -> dict[str, int]:
    """Write `scan` as a new bag at `target`; remove what was written if that fails."""
    try:
        writer = Writer(target, version=9, storage_plugin=StoragePlugin.MCAP)
        writer.set_compression(CompressionMode.STORAGE, CompressionFormat.ZSTD)
        writer.open()
    except Exception as exc:  # rosbags WriterError, OSError
        raise BagError(f"{target}: cannot write: {exc}") from exc
    counts: dict[str, int] = {}
    try:
        conns = {key: writer.add_connection(t.topic, t.msgtype, msgdef=t.msgdef,
                                            rihs01=t.rihs01, offered_qos_profiles=list(t.qos))
                 for key, t in scan.topics.items()}
        for t_ns, _, key, data in scan.messages:
            writer.write(conns[key], t_ns, data)
            counts[key[0]] = counts.get(key[0], 0) + 1
        writer.close()
        set_ros_distro(target, distro)
    except Exception as exc:
        with contextlib.suppress(OSError):  # a full disk fails the abort's flush too
            writer.abort()
        shutil.rmtree(target, ignore_errors=True)
        why = exc.strerror if isinstance(exc, OSError) and exc.strerror else exc
        raise BagError(f"{target}: cannot write: {why}; nothing written there, the input "
                       f"bag is unchanged") from exc
    return counts

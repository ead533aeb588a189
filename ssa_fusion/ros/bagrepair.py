"""Repair a rosbag2 MCAP bag whose recorder never closed it (SIGKILL, power loss).

Such a bag has no ``metadata.yaml`` and its ``.mcap`` has no summary, no footer and maybe a
torn last record, so plain readers (``rosbags.rosbag2.Reader``, ``ros2 bag``) refuse it.
`repair` reads every complete record of its ``.mcap`` file(s) (`bagio.read_bag` recovers
the same messages) and writes a new, closed rosbag2 v9 MCAP bag: the same topics, message
types, message definitions, QoS profiles and CDR bytes, each message at its original log
time (ns). A damaged file (a flipped byte, a block of garbage in the middle) loses only the
damaged chunk (`mcap_salvage`: every intact chunk before and after it is kept, and the
messages of the damaged chunk's readable start); the result says which byte and time ranges
were lost. The bytes are copied, never decoded, so any ROS 2 message type is kept, not only
those this project knows.
"""

from __future__ import annotations

import contextlib
import re
import shutil
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

from rosbags.rosbag2 import StoragePlugin, Writer
from rosbags.rosbag2.enums import CompressionFormat, CompressionMode

from ssa_fusion.core.earth.timescales import iso
from ssa_fusion.ros.bagio import ROS_DISTRO, BagError, set_ros_distro, typestore
from ssa_fusion.ros.mcap_salvage import LostRange, salvage

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
    lost: list[tuple[Path, LostRange]] = field(default_factory=list)
    """The damaged parts of each file (a torn end included)."""
    orphans: int = 0
    """Messages on a channel whose definition was lost with a damaged part."""
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
    lost: list[tuple[Path, LostRange]]
    """The damaged parts of the input, by file (a torn end included)."""
    orphans: int
    """Messages not kept: their channel's definition was lost with a damaged part."""
    complete: bool
    """The input had been closed properly and nothing in it was damaged."""

    @property
    def discarded_bytes(self) -> int:
        """Bytes of the input in damaged parts."""
        return sum(r.end - r.start for _, r in self.lost)

    def line(self, bag: Path) -> str:
        """One line for the user: where, how many messages per topic, what was lost."""
        per_topic = ", ".join(f"{t} {n}" for t, n in sorted(self.counts.items()))
        total = sum(self.counts.values())
        return (f"repaired {bag} -> {self.out}: recovered {total} messages ({per_topic}); "
                f"{self.losses()}")

    def losses(self) -> str:
        """Return what was lost, in words: nothing, a torn end, or damaged parts and times."""
        if self.complete and not self.lost:
            return "the input was complete already"
        if not self.lost:
            return "no torn record at the end"
        parts = [_lost_words(r) for _, r in self.lost]
        orphans = (f"; {self.orphans} messages dropped with their channel's definition"
                   if self.orphans else "")
        return f"lost {self.discarded_bytes} bytes in {len(parts)} part(s): " + "; ".join(
            parts) + orphans


def _lost_words(r: LostRange) -> str:
    """One damaged part in words: bytes, why, and the messages' time range when known."""
    when = (f", messages {iso(r.t_start_ns * 1e-9)} .. {iso(r.t_end_ns * 1e-9)}"
            if r.t_start_ns is not None and r.t_end_ns is not None else "")
    kept = f", {r.messages_kept} of its messages kept" if r.messages_kept else ""
    return f"bytes {r.start}..{r.end} ({r.why}{when}{kept})"


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
    return RepairResult(target, counts, files, scan.lost, scan.orphans,
                        scan.complete and not scan.lost)


def _scan_file(path: Path, scan: _Scan) -> None:
    """Add the schemas, channels and messages of the intact records of `path` to `scan`."""
    try:
        found = salvage(path)
    except OSError as exc:
        raise BagError(f"{path}: cannot read: {exc.strerror or exc}") from exc
    except ValueError as exc:
        raise BagError(str(exc)) from exc
    conns = {cid: _topic(path, ch, found.schemas.get(ch.schema_id))
             for cid, ch in found.channels.items()}
    for record in found.messages:
        conn = conns.get(record.channel_id)
        if conn is None:
            scan.orphans += 1  # its channel (or schema) was lost: nothing to write it as
            continue
        key = (conn.topic, conn.msgtype)
        scan.topics.setdefault(key, conn)
        scan.messages.append((record.log_time, len(scan.messages), key, bytes(record.data)))
    scan.lost.extend((path, r) for r in found.lost)
    scan.complete = scan.complete and found.footer


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

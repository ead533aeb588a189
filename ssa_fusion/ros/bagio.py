"""rosbag2 (MCAP storage, version 9) reading and writing through `rosbags`, no ROS needed.

The recorder, the offline replay, the live evaluation and the report all go through this
module so that every bag the project writes has the same layout:
``<dir>/metadata.yaml`` + ``<dir>/<dir>.mcap`` (profile ``ros2``, schema encoding
``ros2msg``, message encoding ``cdr``). The readers of a bag's measurements and estimates
read through `read_records`, which takes a catalog's batches as their rows.
"""

from __future__ import annotations

import errno
import os
import sys
from collections import Counter
from collections.abc import Callable, Iterable, Iterator, Mapping
from dataclasses import dataclass
from functools import partial
from pathlib import Path
from typing import TYPE_CHECKING, Any, cast

import numpy as np
from rosbags.interfaces import (
    Qos,
    QosDurability,
    QosHistory,
    QosLiveliness,
    QosReliability,
    QosTime,
)
from rosbags.rosbag2 import StoragePlugin, Writer
from rosbags.rosbag2.enums import CompressionFormat, CompressionMode
from rosbags.rosbag2.storage_mcap import McapWriter
from rosbags.typesys import Stores, get_types_from_msg, get_typestore
from rosbags.typesys.store import Typestore

from ssa_fusion.core.base.types import Cause, Kind
from ssa_fusion.core.earth.timescales import EPOCH_MAX
from ssa_fusion.ros.mcap_salvage import MAGIC as MCAP_MAGIC
from ssa_fusion.ros.mcap_salvage import salvage

if TYPE_CHECKING:
    from mcap.records import Schema
    from rclpy.duration import Duration
    from rclpy.qos import QoSProfile

    from ssa_fusion.ros.interfaces import Message
    from ssa_fusion.ros.messages import MsgClasses

ROS_DISTRO = "kilted"
MSG_PACKAGE = "ssa_fusion_msgs"
MSG_TYPES = ("Measurement", "StateEstimate", "MeasurementBatch", "EstimateBatch", "Meteo",
             "ConjunctionBatch")
MEASUREMENT = f"{MSG_PACKAGE}/msg/Measurement"
STATE_ESTIMATE = f"{MSG_PACKAGE}/msg/StateEstimate"
MEASUREMENT_BATCH = f"{MSG_PACKAGE}/msg/MeasurementBatch"
ESTIMATE_BATCH = f"{MSG_PACKAGE}/msg/EstimateBatch"
METEO = f"{MSG_PACKAGE}/msg/Meteo"
CONJUNCTION_BATCH = f"{MSG_PACKAGE}/msg/ConjunctionBatch"


class BagError(RuntimeError):
    """A bag cannot be read or written; the message says which file and why."""


def _msg_dir() -> Path:
    """Return share/ssa_fusion_msgs/msg of the first prefix (AMENT_PREFIX_PATH, sys.prefix)."""
    prefixes = [p for p in os.environ.get("AMENT_PREFIX_PATH", "").split(os.pathsep) if p]
    for prefix in [*prefixes, sys.prefix]:
        d = Path(prefix) / "share" / MSG_PACKAGE / "msg"
        if d.is_dir():
            return d
    raise BagError(f"cannot find {MSG_PACKAGE} message definitions: is the package installed?")


_TYPESTORE: Typestore | None = None


def typestore() -> Typestore:
    """Return the Kilted typestore with the ssa_fusion_msgs types registered (cached)."""
    global _TYPESTORE
    if _TYPESTORE is None:
        store = get_typestore(Stores.ROS2_KILTED)
        types: dict[str, Any] = {}
        for name in MSG_TYPES:
            text = (_msg_dir() / f"{name}.msg").read_text()
            types.update(get_types_from_msg(text, f"{MSG_PACKAGE}/msg/{name}"))
        store.register(types)
        _TYPESTORE = store
    return _TYPESTORE


LATCHED_QOS = Qos(history=QosHistory.KEEP_LAST, depth=1, reliability=QosReliability.RELIABLE,
                  durability=QosDurability.TRANSIENT_LOCAL, deadline=QosTime(0, 0),
                  lifespan=QosTime(0, 0), liveliness=QosLiveliness.SYSTEM_DEFAULT,
                  liveliness_lease_duration=QosTime(0, 0),
                  avoid_ros_namespace_conventions=False)
"""`ros.qos.CONFIG_QOS` as a bag records it (latched: the settings topic), without rclpy:
what offline writers (replay, import) offer for ``/ssa/config``."""


def qos_from_rclpy(profile: QoSProfile) -> Qos:
    """Return an rclpy QoSProfile as a rosbags Qos (metadata.yaml offered_qos_profiles)."""

    def t(d: Duration) -> QosTime:
        ns = int(d.nanoseconds)
        return QosTime(ns // 1_000_000_000, ns % 1_000_000_000)

    return Qos(history=QosHistory(int(profile.history)), depth=int(profile.depth),
               reliability=QosReliability(int(profile.reliability)),
               durability=QosDurability(int(profile.durability)), deadline=t(profile.deadline),
               lifespan=t(profile.lifespan), liveliness=QosLiveliness(int(profile.liveliness)),
               liveliness_lease_duration=t(profile.liveliness_lease_duration),
               avoid_ros_namespace_conventions=bool(profile.avoid_ros_namespace_conventions))


def rosbags_classes() -> MsgClasses:
    """Return the `messages.MsgClasses` of the typestore (messages for bags, no ROS)."""
    from ssa_fusion.ros.messages import MsgClasses

    t = typestore().types
    return MsgClasses(t["builtin_interfaces/msg/Time"], t["std_msgs/msg/Header"],
                      t[MEASUREMENT], t[STATE_ESTIMATE], t[MEASUREMENT_BATCH], t[ESTIMATE_BATCH],
                      numpy_arrays=True, meteo=t[METEO], conjunction_batch=t[CONJUNCTION_BATCH])


class BagFullError(OSError):
    """No room on the bag's disk for a message and the bag's closing records (ENOSPC)."""


CLOSE_RESERVE = 64 * 1024
"""Bytes kept free for a bag's closing records beyond what `BagWriter` counts (summary
offsets, footer, the file systems' last partial blocks)."""
RECORD_OVERHEAD = 64
"""Bytes an MCAP message record and its index entry add to the message (31 + 16, rounded)."""
TOPIC_RESERVE = 4096
"""Bytes kept per topic for its metadata.yaml entry and its summary records."""
CHUNK_RESERVE = 256
"""Bytes kept per written chunk for its chunk index in the summary."""
ZSTD_LEVEL = 1
"""The chunks' zstd level: on the demo's bag 2.4x the default 3's speed at its ratio."""


class BagWriter:
    """Append CDR messages to a new rosbag2 v9 MCAP bag (zstd-compressed chunks).

    ``flush()`` closes the pending MCAP chunk and pushes it to the file so that, after a
    crash, a reader recovers everything written up to the last flush.

    A write that the disk (``statvfs``: blocks available to the user) could not hold
    together with what closing the bag needs (the pending chunk, its index, the summary and
    metadata.yaml) raises `BagFullError` before writing anything: the bag can then be closed
    whole with every message before it, rather than torn by ENOSPC mid-record. The check
    costs one ``statvfs`` per `CLOSE_RESERVE` / 4 bytes written.
    """

    def __init__(self, path: Path | str) -> None:
        self.path = Path(path)
        self._writer = Writer(self.path, version=9, storage_plugin=StoragePlugin.MCAP)
        # zstd-compressed MCAP chunks, like rosbag2's mcap presets: any MCAP reader reads them
        self._writer.set_compression(CompressionMode.STORAGE, CompressionFormat.ZSTD)
        self._writer.open()
        storage = cast(McapWriter, self._writer.storage)
        storage.compressor = partial(cast(Any, storage.compressor), level=ZSTD_LEVEL)  # zstd's
        self._connections: dict[str, Any] = {}
        self.counts: dict[str, int] = {}
        self._room = 0  # bytes that may still be written before the disk is asked again
        self.closed = False

    def add_topic(self, topic: str, msgtype: str, qos: Iterable[Qos] = ()) -> None:
        """Register `topic` of `msgtype` ("pkg/msg/Name"); a no-op if already registered.

        The type hash (RIHS01) and definition come from the typestore; they equal rosidl's.
        """
        if topic in self._connections:
            return
        self._connections[topic] = self._writer.add_connection(
            topic, msgtype, typestore=typestore(), offered_qos_profiles=list(qos)
        )
        self.counts[topic] = 0

    def has_topic(self, topic: str) -> bool:
        """Return True when `topic` is registered."""
        return topic in self._connections

    def write(self, topic: str, t_ns: int, cdr: bytes | memoryview) -> None:
        """Write one CDR-serialized message received (or stamped) at `t_ns`.

        Raises `BagFullError` (nothing written) when the disk could not hold it and the bag's
        closing records.
        """
        need = len(cdr) + RECORD_OVERHEAD
        if need > self._room:
            self._room = self._free_after_close()
            if need > self._room:
                raise BagFullError(errno.ENOSPC, f"No space left on device for a {need}-byte "
                                            f"message ({max(self._room, 0)} bytes free beyond "
                                            f"what closing the bag needs)", str(self.path))
            self._room = min(self._room, CLOSE_RESERVE // 4)  # ask the disk again soon
        self._writer.write(self._connections[topic], int(t_ns), cdr)
        self.counts[topic] += 1
        self._room -= need

    def _free_after_close(self) -> int:
        """Bytes the disk has beyond what closing the bag would write (may be negative)."""
        storage = self._writer.storage
        assert isinstance(storage, McapWriter)
        fs = os.statvfs(self.path)
        unflushed = storage.bio.tell() - os.fstat(storage.bio.fileno()).st_size
        pending = storage.chunk.bio.tell() + RECORD_OVERHEAD * sum(
            len(m) for m in storage.chunk.msgs.values())
        definitions = sum(len(s.data) for s in storage.schemas)
        closing = (pending + 2 * definitions + CHUNK_RESERVE * (len(storage.chunks) + 1)
                   + TOPIC_RESERVE * len(self._connections) + CLOSE_RESERVE)
        return fs.f_bavail * fs.f_frsize - unflushed - closing

    def write_msg(self, topic: str, t_ns: int, msg: Message) -> None:
        """Serialize a rosbags message object with the typestore and write it."""
        conn = self._connections[topic]
        self.write(topic, t_ns, typestore().serialize_cdr(msg, conn.msgtype))

    def flush(self) -> None:
        """Close the pending MCAP chunk and push the file to disk (a crash keeps it)."""
        storage = self._writer.storage
        if storage is None:
            return
        assert isinstance(storage, McapWriter)  # its chunking is what a flush reaches into
        if storage.chunk.bio.tell():
            storage.close_chunk()
        storage.bio.flush()
        os.fsync(storage.bio.fileno())

    def close(self) -> None:
        """Write the MCAP summary and metadata.yaml (with ros_distro); a no-op once closed."""
        if self._writer.storage is None or self.closed:
            return
        self.closed = True
        self._writer.close()
        set_ros_distro(self.path)


def set_ros_distro(path: Path, distro: str = ROS_DISTRO) -> None:
    """Name `distro` as ros_distro in the metadata.yaml of bag directory `path`.

    `rosbags.rosbag2.Writer` writes ``rosbags`` there.
    """
    meta = Path(path) / "metadata.yaml"
    text = meta.read_text().replace("ros_distro: rosbags", f"ros_distro: {distro}")
    meta.write_text(text)


Decoders = Mapping[str, Callable[[bytes], Any]]
"""Per topic, a function of a message's CDR bytes that stands for its full decoding."""


@dataclass
class BagMessage:
    """One message of a bag: its topic, type ("pkg/msg/Name"), log time (ns), message."""

    topic: str
    msgtype: str
    t_ns: int
    msg: Message


def read_bag(path: Path | str, topics: Iterable[str] | None = None,
             undecodable: Counter[str] | None = None,
             decoders: Decoders | None = None) -> Iterator[BagMessage]:
    """Return the messages of a bag in log-time order.

    Deserialized with the Kilted + ssa_fusion_msgs typestore. `path` is a rosbag2
    directory (metadata.yaml + storage files, as this project or `ros2 bag record` writes
    them) or a bare ``.mcap`` file. Unknown message types raise
    BagError naming topic and type. A message whose bytes do not decode as its type (a
    malformed payload the recorder stored as it arrived) is skipped and counted by topic
    in `undecodable` (when given): one bad message does not make the bag unreadable.
    `decoders`: per topic, a function of the CDR bytes that replaces the full decoding (e.g.
    `cdr_rows.measurement_batch_rows`, the rows alone); a ValueError of it counts the
    message as undecodable.
    """
    path = Path(path)
    if not path.exists():
        raise BagError(f"{path}: no such bag")
    wanted = set(topics) if topics is not None else None
    mcaps = [path] if path.is_file() else sorted(path.glob("*.mcap")) if path.is_dir() else []
    for f in mcaps:
        _check_mcap_magic(f)
    if path.is_file() and path.suffix == ".mcap":
        if _mcap_finished(path):
            yield from _read_mcap_file(path, wanted, undecodable, decoders)
        else:
            yield from _recover_mcap_file(path, wanted, undecodable, decoders)
        return
    if not (path / "metadata.yaml").exists():
        # metadata.yaml and the MCAP summary are written at close: a recorder killed
        # (SIGKILL, power loss) leaves neither. Recover what was flushed to the .mcap.
        files = sorted(path.glob("*.mcap")) if path.is_dir() else []
        if not files:
            raise BagError(f"{path}: not a rosbag2 directory (no metadata.yaml) nor an .mcap "
                           "file")
        recovered = [m for f in files
                     for m in _recover_mcap_file(f, wanted, undecodable, decoders)]
        yield from sorted(recovered, key=lambda m: m.t_ns)
        return
    from rosbags.highlevel import AnyReader

    try:
        with AnyReader([path], default_typestore=typestore()) as reader:
            conns = [c for c in reader.connections if wanted is None or c.topic in wanted]
            if not conns:  # none of the topics asked for (rosbags reads all for none)
                return
            _check_types(path, [(c.topic, c.msgtype) for c in conns])
            for conn, t_ns, raw in reader.messages(connections=conns):
                msg = _decode(reader.deserialize, raw, conn.msgtype, conn.topic, undecodable,
                              decoders)
                if msg is not None:
                    yield BagMessage(conn.topic, conn.msgtype, t_ns, msg)
    except BagError:
        raise
    except Exception as exc:  # rosbags raises several unrelated types; name the file
        raise BagError(f"{path}: cannot read bag: {exc}") from exc


def _check_types(path: Path, topic_types: list[tuple[str, str]]) -> None:
    """Raise BagError for a topic whose type the typestore does not know."""
    store = typestore()
    for topic, msgtype in topic_types:
        if msgtype not in store.fielddefs:
            raise BagError(f"{path}: topic {topic} has unknown message type {msgtype}")


def _decode(deserialize: Callable[[bytes, str], Message], data: bytes, msgtype: str,
            topic: str, undecodable: Counter[str] | None,
            decoders: Decoders | None = None) -> Message | None:
    """Return ``deserialize(data, msgtype)``, or None if the bytes are no such message.

    `decoders`: as `read_bag`. None is counted under `topic` in `undecodable`.
    """
    own = decoders.get(topic) if decoders else None
    try:
        return own(data) if own is not None else deserialize(data, msgtype)
    except Exception:  # rosbags/CDR raise several unrelated types on malformed bytes
        if undecodable is not None:
            undecodable[topic] += 1
        return None


def _mcap_message(store: Typestore, path: Path, schema: Schema | None, topic: str, data: bytes,
                  log_time: int, undecodable: Counter[str] | None,
                  decoders: Decoders | None = None) -> BagMessage | None:
    """Return one MCAP record of `topic` as a `BagMessage` (None: its bytes do not decode).

    `store`: the rosbags type store; `schema`: the record's MCAP schema (None: it has none).
    BagError for a schema the store does not know.
    """
    if schema is None or schema.name not in store.fielddefs:
        name = schema.name if schema else "(no schema)"
        raise BagError(f"{path}: topic {topic} has unknown type {name}")
    msg = _decode(store.deserialize_cdr, data, schema.name, topic, undecodable, decoders)
    return None if msg is None else BagMessage(topic, schema.name, log_time, msg)


def _read_mcap_file(path: Path, wanted: set[str] | None,
                    undecodable: Counter[str] | None = None,
                    decoders: Decoders | None = None) -> Iterator[BagMessage]:
    """Return the messages of a bare MCAP file (ROS 2 profile, CDR).

    In log-time order via its index when it has one, else in file order.
    """
    from mcap.exceptions import McapError
    from mcap.reader import make_reader

    store = typestore()
    try:
        with path.open("rb") as f:
            reader = make_reader(f)
            for schema, channel, message in reader.iter_messages(
                    topics=list(wanted) if wanted is not None else None, log_time_order=True):
                if channel.message_encoding != "cdr":
                    raise BagError(f"{path}: topic {channel.topic} is not CDR encoded")
                got = _mcap_message(store, path, schema, channel.topic, message.data,
                                    message.log_time, undecodable, decoders)
                if got is not None:
                    yield got
    except BagError:
        raise
    except (McapError, OSError, ValueError, EOFError) as exc:
        raise BagError(f"{path}: cannot read MCAP file: {exc}") from exc




def _check_mcap_magic(path: Path) -> None:
    """Raise BagError unless `path` starts like an MCAP file (its magic bytes)."""
    try:
        with open(path, "rb") as f:
            head = f.read(len(MCAP_MAGIC))
    except OSError as exc:
        raise BagError(f"{path}: cannot read: {exc}") from exc
    if head != MCAP_MAGIC:
        raise BagError(f"{path}: not an MCAP file (it does not start with the MCAP magic "
                       "bytes)")


def _mcap_finished(path: Path) -> bool:
    """Return True when the MCAP file ends with its closing magic (its writer closed it)."""
    with path.open("rb") as f:
        f.seek(0, os.SEEK_END)
        if f.tell() < 2 * len(MCAP_MAGIC):
            return False
        f.seek(-len(MCAP_MAGIC), os.SEEK_END)
        return f.read() == MCAP_MAGIC


def _recover_mcap_file(path: Path, wanted: set[str] | None,
                       undecodable: Counter[str] | None = None,
                       decoders: Decoders | None = None) -> Iterator[BagMessage]:
    """Return the messages of an MCAP file its writer never closed, in log-time order.

    No summary, no footer, maybe a torn last record or a damaged part: every intact record
    is read (`mcap_salvage.salvage`). Everything the recorder flushed (a whole chunk per
    `flush_period`) is there.
    """
    store = typestore()
    found = salvage(path)
    out: list[BagMessage] = []
    for record in found.messages:
        channel = found.channels.get(record.channel_id)
        if channel is None or (wanted is not None and channel.topic not in wanted):
            continue
        got = _mcap_message(store, path, found.schemas.get(channel.schema_id), channel.topic,
                            record.data, record.log_time, undecodable, decoders)
        if got is not None:
            out.append(got)
    out.sort(key=lambda m: m.t_ns)
    yield from out


# ------------------------------------------------------------------------------------------
# records: a batch's rows as the messages they mean
# ------------------------------------------------------------------------------------------
ROW_TOPICS = {MEASUREMENT_BATCH: ("/ssa/measurement", MEASUREMENT),
              ESTIMATE_BATCH: ("/ssa/estimate", STATE_ESTIMATE)}
"""Per batch type, the topic and type of the messages its rows are (`topics.TOPIC_MEASUREMENT`
and `topics.TOPIC_ESTIMATE`)."""
BATCH_TOPICS = {"/ssa/measurement": "/ssa/measurement_batch",
                "/ssa/estimate": "/ssa/estimate_batch"}
"""Per message topic, the topic of its batches (`topics.TOPIC_MEASUREMENT_BATCH`,
`topics.TOPIC_ESTIMATE_BATCH`): reading the one reads the other."""
ROW_BATCHES = frozenset(BATCH_TOPICS.values())
"""The batch topics (whose refusals count rows)."""
_NS = 1_000_000_000
_KINDS = np.zeros(256, bool)
_KINDS[[int(k) for k in Kind]] = True
REFUSED_WHY: dict[str, str] = {
    Cause.REJECTED_KIND: "a measurement kind ssa_fusion does not know",
    Cause.REJECTED_MALFORMED: "an epoch no ROS time carries (before 1970, after 2038-01-19), "
                              "or a batch whose columns disagree in length",
}
"""What each cause of `read_records` means, for the line that says what was left out."""


def read_records(path: Path | str, topics: Iterable[str] | None = None,
                 undecodable: Counter[str] | None = None,
                 refused: Counter[tuple[str, str]] | None = None) -> Iterator[BagMessage]:
    """Return the messages of a bag as `read_bag` does, a batch's rows as messages of their own.

    Every MeasurementBatch and EstimateBatch is replaced by its rows (`batch_records`): a
    Measurement on /ssa/measurement, a StateEstimate on /ssa/estimate per row, each the
    message that row published alone would have been, at the batch's log time; so that a
    bag recorded with batches reads as if it had been recorded one message each, and a bag
    of both gives the union. Asking for /ssa/measurement or /ssa/estimate (`topics`) reads
    their batch topics too.

    Measurements and estimates (single messages and rows alike) that no reader can take are
    left out and counted in `refused` (when given) by (topic recorded on, cause):
    ``rejected_kind`` for a measurement kind the core does not know, ``rejected_malformed``
    for an epoch before 1970 or after 2038-01-19 (no ROS time carries it) and for every row
    of a batch whose columns disagree in length (`REFUSED_WHY`). Messages that do not
    decode are counted in `undecodable`, as `read_bag` counts them.
    """
    wanted = None
    if topics is not None:
        wanted = set(topics)
        wanted |= {BATCH_TOPICS[t] for t in wanted if t in BATCH_TOPICS}
    for m in read_bag(path, wanted, undecodable):
        if m.msgtype in ROW_TOPICS:
            yield from batch_records(m, refused)
        elif m.msgtype in (MEASUREMENT, STATE_ESTIMATE):
            cause = _record_problem(m)
            if not cause:
                yield m
            elif refused is not None:
                refused[m.topic, cause] += 1
        else:
            yield m


def _record_problem(m: BagMessage) -> str:
    """Return why a Measurement or StateEstimate message is refused (`read_records`), or ""."""
    stamp = m.msg.header.stamp
    ns = int(stamp.sec) * _NS + int(stamp.nanosec)
    if not 0 <= ns <= EPOCH_MAX * _NS:
        return Cause.REJECTED_MALFORMED
    if m.msgtype == MEASUREMENT and not _KINDS[int(m.msg.kind) & 0xFF]:
        return Cause.REJECTED_KIND
    return ""


def batch_records(batch: BagMessage, refused: Counter[tuple[str, str]] | None = None
                  ) -> list[BagMessage]:
    """Return the rows of a MeasurementBatch or EstimateBatch as Measurement or StateEstimate.

    One vectorised pass over the columns, then one message per row: each row is, to the
    bit, the message the same measurement or estimate published alone is (SI values as the
    batch carries them; stamp the row's epoch; frame_id the row's station or frame for a
    measurement, the batch's header.frame_id for an estimate), on the per-message topic
    (`ROW_TOPICS`), at the batch's log time, in epoch order (a stable sort: publishers
    write their rows in epoch order). Rows refused as `read_records` says are counted in
    `refused` by (the batch's topic, cause).
    """
    msg = batch.msg
    measurements = batch.msgtype == MEASUREMENT_BATCH
    n = len(msg.object_id)
    ns = np.asarray(msg.stamp_ns, dtype=np.int64)
    columns: dict[str, Any] = {"shard_key": msg.shard_key, "stamp_ns": ns}
    if measurements:
        columns.update(kind=msg.kind, source=msg.source, frame_id=msg.frame_id, z=msg.z,
                       covariance=msg.covariance, horizon=msg.horizon)
        width = {"z": 3, "covariance": 9}
    else:
        columns.update(state=msg.state, covariance=msg.covariance, nis=msg.nis)
        width = {"state": 6, "covariance": 36}
    if any(len(v) != n * width.get(k, 1) for k, v in columns.items()):
        if refused is not None and n:
            refused[batch.topic, Cause.REJECTED_MALFORMED] += n
        return []
    cause = np.full(n, "", dtype=object)
    cause[(ns < 0) | (ns > int(EPOCH_MAX) * _NS)] = Cause.REJECTED_MALFORMED
    if measurements:
        kind = np.asarray(msg.kind, dtype=np.uint8)
        cause[(cause == "") & ~_KINDS[kind]] = Cause.REJECTED_KIND
    bad = cause != ""
    if refused is not None and bad.any():
        for c, k in zip(*np.unique(cause[bad].astype(str), return_counts=True), strict=True):
            refused[batch.topic, str(c)] += int(k)
    keep = np.flatnonzero(~bad)
    keep = keep[np.argsort(ns[keep], kind="stable")]
    if not len(keep):
        return []
    c = rosbags_classes()
    t_ns = ns[keep]
    sec, nanosec = (t_ns // _NS).tolist(), (t_ns % _NS).tolist()
    ids = np.asarray(msg.object_id, dtype=object)[keep].tolist()
    keys = np.asarray(msg.shard_key, dtype=np.uint32)[keep].tolist()
    cov = np.asarray(msg.covariance, dtype=np.float64).reshape(n, -1)[keep]
    topic, msgtype = ROW_TOPICS[batch.msgtype]
    time, header = c.time, c.header
    if measurements:
        frames = np.asarray(msg.frame_id, dtype=object)[keep].tolist()
        z = np.asarray(msg.z, dtype=np.float64).reshape(n, 3)[keep]
        make = c.measurement
        rows = [make(header=header(stamp=time(sec=s, nanosec=q), frame_id=f), object_id=o,
                     kind=k, source=src, z=zi, covariance=ci, horizon=h, shard_key=key)
                for s, q, f, o, k, src, zi, ci, h, key in zip(
                    sec, nanosec, frames, ids, kind[keep].tolist(),
                    np.asarray(msg.source, dtype=np.uint8)[keep].tolist(), z, cov,
                    np.asarray(msg.horizon, dtype=np.float64)[keep].tolist(), keys,
                    strict=True)]
    else:
        frame, source = str(msg.header.frame_id), int(msg.update_source)
        x = np.asarray(msg.state, dtype=np.float64).reshape(n, 6)[keep]
        make = c.estimate
        rows = [make(header=header(stamp=time(sec=s, nanosec=q), frame_id=frame), object_id=o,
                     state=xi, covariance=ci, update_source=source, nis=v, shard_key=key)
                for s, q, o, xi, ci, v, key in zip(
                    sec, nanosec, ids, x, cov,
                    np.asarray(msg.nis, dtype=np.float64)[keep].tolist(), keys, strict=True)]
    return [BagMessage(topic, msgtype, batch.t_ns, row) for row in rows]


def left_out(undecodable: Counter[str], refused: Counter[tuple[str, str]]) -> list[str]:
    """Return one line per topic (and cause) of what `read_records` left out."""
    lines = [f"{n} message(s) on {topic} do not decode as their type; skipped"
             for topic, n in undecodable.items()]
    lines += [f"{n} {'row(s) of batches' if topic in ROW_BATCHES else 'message(s)'} on "
              f"{topic} refused ({cause}: {REFUSED_WHY.get(cause, cause)}); skipped"
              for (topic, cause), n in sorted(refused.items())]
    return lines



def counts_left_out(undecodable: Counter[str], refused: Counter[tuple[str, str]]
                    ) -> dict[str, int]:
    """Return what `read_records` left out as counts: ``undecodable TOPIC``, ``CAUSE TOPIC``."""
    out = {f"undecodable {topic}": n for topic, n in undecodable.items()}
    out.update({f"{cause} {topic}": n for (topic, cause), n in sorted(refused.items())})
    return out

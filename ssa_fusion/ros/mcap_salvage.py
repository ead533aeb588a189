"""Every intact record of an MCAP file, whatever happened to the rest of it: `salvage`.

A recorder killed mid-write leaves a file without summary or footer and a torn last record;
a disk or a copy can also damage the middle of a file (a flipped bit, a block of garbage).
`salvage` reads the file record by record (MCAP's framing: opcode, uint64 length, content)
and keeps every schema, channel and message it can trust:

* a chunk whose compressed records decompress and match their CRC is taken whole;
* a damaged chunk (its data do not decompress, or its CRC fails) gives the messages that
  parse, one by one, from the part of it that decompresses, and the rest of it is counted
  lost, with the chunk's time range (its header's message start and end times);
* bytes that are no record (garbage, a record whose length runs past the end) are skipped
  up to the next offset where a chunk (or another record) starts that checks out (its header
  fields are consistent and its data decompress), and counted as lost bytes;
* channels and schemas lost with a damaged chunk are taken from the summary section when
  the file still has one (MCAP repeats them there).

Pure Python on the `mcap` library's record parsers and `zstandard`/`lz4` (as the `mcap`
reader uses them); nothing is decoded beyond the MCAP records, so any message type is kept.
"""

from __future__ import annotations

import io
import struct
import zlib
from dataclasses import dataclass, field
from pathlib import Path

from mcap.data_stream import ReadDataStream
from mcap.records import Channel, Footer, Message, Schema

MAGIC = b"\x89MCAP0\r\n"
"""The 8 bytes an MCAP file starts and ends with."""
OP_SCHEMA, OP_CHANNEL, OP_MESSAGE, OP_CHUNK, OP_FOOTER = 0x03, 0x04, 0x05, 0x06, 0x02
KNOWN_OPCODES = frozenset(range(0x01, 0x10))
"""Opcodes of the MCAP specification (Header .. DataEnd)."""
_RECORD_HEAD = struct.Struct("<BQ")
_CHUNK_HEAD = struct.Struct("<QQQI")
_MESSAGE_HEAD = 22
"""Bytes of a message record before its data: channel id, sequence, log and publish time."""
COMPRESSIONS = ("", "zstd", "lz4")


@dataclass(frozen=True)
class LostRange:
    """A part of the file that could not be read.

    Attributes
    ----------
    start, end : int
        Byte offsets in the file.
    t_start_ns, t_end_ns : int or None
        Log-time range of the messages it held (a damaged chunk's header), ns since the
        Unix epoch; None where unknown (garbage between records).
    messages_kept : int
        Messages recovered from it anyway (the decodable start of a damaged chunk).
    why : str
        One line: what was wrong.
    """

    start: int
    end: int
    t_start_ns: int | None
    t_end_ns: int | None
    messages_kept: int
    why: str


@dataclass
class Salvage:
    """What `salvage` read from one MCAP file."""

    schemas: dict[int, Schema] = field(default_factory=dict)
    channels: dict[int, Channel] = field(default_factory=dict)
    messages: list[Message] = field(default_factory=list)
    lost: list[LostRange] = field(default_factory=list)
    """Damaged parts, in file order (a torn end included)."""
    footer: bool = False
    """The file ended with its footer (its writer closed it)."""
    size: int = 0
    """Bytes in the file."""

    @property
    def lost_bytes(self) -> int:
        """Bytes of the file in damaged parts."""
        return sum(r.end - r.start for r in self.lost)


def salvage(path: Path) -> Salvage:
    """Return every intact schema, channel and message of MCAP file `path`.

    OSError when the file cannot be read; ValueError when it does not start with the MCAP
    magic. Never raises on damage inside the file: that is in `Salvage.lost`.
    """
    data = Path(path).read_bytes()
    if not data.startswith(MAGIC):
        raise ValueError(f"{path}: not an MCAP file (no MCAP magic at its start)")
    out = Salvage(size=len(data))
    _take_summary(data, out)
    pos = len(MAGIC)
    while pos < len(data):
        if data[pos:] == MAGIC and out.footer:
            break
        step = _record(data, pos, out)
        if step is None:
            nxt = _resync(data, pos + 1)
            out.lost.append(LostRange(pos, nxt, None, None, 0,
                                      "bytes that are no MCAP record" if nxt < len(data)
                                      else "an incomplete record at the end"))
            pos = nxt
        else:
            pos = step
    return out


def _record(data: bytes, pos: int, out: Salvage) -> int | None:
    """Take the record at `pos` into `out`; return the offset after it, None if none is there."""
    head = _head(data, pos)
    if head is None:
        return None
    op, end = head
    content = data[pos + _RECORD_HEAD.size:end]
    if op == OP_CHUNK:
        if _chunk_fields(content) is None:
            return None
        _take_chunk(content, pos, end, out)
    elif op in (OP_SCHEMA, OP_CHANNEL, OP_MESSAGE):
        if not _take_plain(op, content, out):
            return None
    elif op == OP_FOOTER:
        out.footer = True
    return end


def _head(data: bytes, pos: int) -> tuple[int, int] | None:
    """(opcode, end offset) of a plausible record header at `pos`, else None."""
    if pos + _RECORD_HEAD.size > len(data):
        return None
    op, length = _RECORD_HEAD.unpack_from(data, pos)
    end = pos + _RECORD_HEAD.size + length
    if op not in KNOWN_OPCODES or end > len(data):
        return None
    return op, end


def _chunk_fields(content: bytes) -> tuple[int, int, int, int, str, bytes] | None:
    """(start ns, end ns, uncompressed size, crc, compression, records) of a chunk, or None."""
    try:
        start, end, size, crc = _CHUNK_HEAD.unpack_from(content, 0)
        pos = _CHUNK_HEAD.size
        (n,) = struct.unpack_from("<I", content, pos)
        compression = content[pos + 4:pos + 4 + n].decode("ascii")
        pos += 4 + n
        (m,) = struct.unpack_from("<Q", content, pos)
        records = content[pos + 8:]
    except (struct.error, UnicodeDecodeError):
        return None
    # a chunk of schemas and channels only (a flush before the first message) carries no
    # time range: rosbags writes (2**63 - 1, 0) there
    no_messages = (start, end) == (2**63 - 1, 0)
    if compression not in COMPRESSIONS or m != len(records) or (start > end and not no_messages):
        return None
    if compression == "" and size != m:
        return None
    return start, end, size, crc, compression, records


def _decompress(compression: str, records: bytes, size: int) -> tuple[bytes, bool]:
    """Return the decompressed bytes of a chunk (as many as come out) and whether all did."""
    if compression == "":
        return records, True
    if compression == "zstd":
        import zstandard

        part = io.BytesIO()
        try:
            with zstandard.ZstdDecompressor().stream_reader(io.BytesIO(records)) as r:
                while chunk := r.read(1 << 16):
                    part.write(chunk)
        except zstandard.ZstdError:
            return part.getvalue(), False
        got = part.getvalue()
        return got, len(got) == size
    import lz4.frame

    try:
        got = lz4.frame.decompress(records)
    except RuntimeError:
        return b"", False
    return got, len(got) == size


def _take_chunk(content: bytes, start: int, end: int, out: Salvage) -> None:
    """Take a chunk's records: all of them when intact, the parseable start when not."""
    fields = _chunk_fields(content)
    assert fields is not None
    t0, t1, size, crc, compression, records = fields
    raw, whole = _decompress(compression, records, size)
    intact = whole and (crc == 0 or zlib.crc32(raw) == crc)
    before = len(out.messages)
    complete = _take_inner(raw, out)
    if not (intact and complete):
        why = ("a chunk whose data do not decompress" if not whole else
               "a chunk whose CRC does not match its data" if not intact else
               "a chunk with a malformed record")
        out.lost.append(LostRange(start, end, t0, t1, len(out.messages) - before, why))


def _take_inner(raw: bytes, out: Salvage) -> bool:
    """Take the records of a chunk's decompressed bytes; False if one of them is broken."""
    pos = 0
    while pos < len(raw):
        head = _head(raw, pos)
        if head is None:
            return False
        op, end = head
        if op in (OP_SCHEMA, OP_CHANNEL, OP_MESSAGE) and not _take_plain(
                op, raw[pos + _RECORD_HEAD.size:end], out):
            return False
        pos = end
    return True


def _parse(op: int, content: bytes) -> Schema | Channel | Message:
    """One schema, channel or message record from its content (the `mcap` library's parsers).

    ValueError when the content is not exactly one such record.
    """
    stream = _stream(content)
    record: Schema | Channel | Message
    if op == OP_MESSAGE:
        if len(content) < _MESSAGE_HEAD:
            raise ValueError("a message record shorter than its header")
        record = Message.read(stream, len(content))
    else:
        record = (Schema if op == OP_SCHEMA else Channel).read(stream)
    if stream.count != len(content):
        raise ValueError("a record whose fields do not fill it")
    return record


def _take_plain(op: int, content: bytes, out: Salvage) -> bool:
    """Parse a schema, channel or message record into `out`; False if it does not parse."""
    try:
        record = _parse(op, content)
    except Exception:  # the mcap parsers raise struct.error, UnicodeDecodeError, ValueError...
        return False
    if isinstance(record, Schema):
        out.schemas.setdefault(record.id, record)
    elif isinstance(record, Channel):
        out.channels.setdefault(record.id, record)
    else:
        out.messages.append(record)
    return True


def _resync(data: bytes, pos: int) -> int:
    """Return the next offset from `pos` where an intact chunk starts (else the data's end)."""
    while True:
        pos = data.find(bytes([OP_CHUNK]), pos)
        if pos < 0:
            return len(data)
        head = _head(data, pos)
        if head is not None:
            fields = _chunk_fields(data[pos + _RECORD_HEAD.size:head[1]])
            if fields is not None:
                raw, whole = _decompress(fields[4], fields[5], fields[2])
                if whole and (fields[3] == 0 or zlib.crc32(raw) == fields[3]):
                    return pos
        pos += 1


def _take_summary(data: bytes, out: Salvage) -> None:
    """Schemas and channels from the summary section, when the footer is intact."""
    tail = _RECORD_HEAD.size + 20 + len(MAGIC)
    if len(data) < len(MAGIC) + tail or not data.endswith(MAGIC):
        return
    pos = len(data) - tail
    head = _head(data, pos)
    if head is None or head[0] != OP_FOOTER:
        return
    try:
        footer = Footer.read(_stream(data[pos + _RECORD_HEAD.size:head[1]]))
    except Exception:  # a damaged footer: no summary to trust
        return
    start = footer.summary_start
    if not len(MAGIC) <= start < pos:
        return
    while start < pos:
        rec = _head(data, start)
        if rec is None:
            return
        op, end = rec
        if op in (OP_SCHEMA, OP_CHANNEL):
            _take_plain(op, data[start + _RECORD_HEAD.size:end], out)
        start = end


def _stream(content: bytes) -> ReadDataStream:
    """Return a `mcap` data stream over `content`."""
    return ReadDataStream(io.BytesIO(content))

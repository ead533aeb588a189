"""Batch messages read off their CDR bytes faster than a generic decoder reads them.

A catalog run's summary reads tens of millions of rows in batches, whose generic decoding
(`rosbags`' type store: a checked string per row and column) took most of its time.
`measurement_batch_rows` counts a ``ssa_fusion_msgs/msg/MeasurementBatch``'s rows without
decoding them; `estimate_batch_columns` decodes an ``EstimateBatch`` into its columns (the
fields `messages.estimate_batch_from_msg` reads), numeric arrays as views of the bytes.

A batch's row count is the length of its first array, ``object_id``, which follows the
header and the two key words:

    encapsulation (4 bytes) | stamp.sec int32 | stamp.nanosec uint32 | frame_id string
    | key_lo uint32 | key_hi uint32 | object_id: count uint32, then the strings ...

(OMG XCDR1 as ROS 2 writes it: a string is a uint32 length counting its NUL, then the bytes;
a uint32 is aligned to 4 bytes from the end of the encapsulation header). The bytes a row
needs at the least bound the count: a count the message cannot hold raises ValueError, as a
payload too short for its header does, so a malformed message is refused as the full
decoder refuses it.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass
from typing import Literal

import numpy as np

__all__ = ["MEASUREMENT_ROW_MIN_BYTES", "EstimateBatchColumns", "estimate_batch_columns",
           "measurement_batch_rows"]

_ENCAPSULATION = 4
_BYTE_ORDER: dict[bytes, Literal["big", "little"]] = {b"\x00\x00": "big", b"\x00\x01": "little"}
"""Representation identifiers of plain CDR (big and little endian)."""
MEASUREMENT_ROW_MIN_BYTES = 4 + 1 + 4 + 1 + 1 + 4 + 1 + 8 + 3 * 8 + 9 * 8 + 8
"""The fewest bytes of one MeasurementBatch row: its object_id (length, NUL), shard_key,
kind, source, frame_id (length, NUL), stamp_ns, z (3), covariance (9), horizon."""


class _Cursor:
    """Reads a CDR message's fields in order; alignment counts from the encapsulation's end."""

    def __init__(self, data: bytes) -> None:
        order = _BYTE_ORDER.get(bytes(data[:2]))
        if order is None:
            raise ValueError(f"not plain CDR (encapsulation {bytes(data[:4])!r})")
        self.body = data if isinstance(data, bytes) else bytes(data)  # not copied when bytes
        self.at = _ENCAPSULATION
        self.end = "<" if order == "little" else ">"

    def _align(self, n: int) -> None:
        self.at += -(self.at - _ENCAPSULATION) % n

    def _need(self, n: int) -> None:
        if self.at + n > len(self.body):
            raise ValueError(f"payload of {len(self.body) - _ENCAPSULATION} bytes ends inside "
                             f"a field ({n} bytes needed at byte {self.at - _ENCAPSULATION})")

    def u8(self) -> int:
        """Return the next uint8."""
        self._need(1)
        self.at += 1
        return self.body[self.at - 1]

    def u32(self) -> int:
        """Return the next uint32 (aligned to 4)."""
        self._align(4)
        self._need(4)
        value: int = struct.unpack_from(self.end + "I", self.body, self.at)[0]
        self.at += 4
        return value

    def string(self) -> str:
        """Return the next string (its length counts the NUL)."""
        n = self.u32()
        self._need(n)
        self.at += n
        return self.body[self.at - n:self.at - 1].decode()

    def strings(self) -> list[str]:
        """Return the next sequence of strings."""
        count = self.u32()
        body, fmt, at, size = self.body, self.end + "I", self.at, len(self.body)
        out: list[str] = []
        for _ in range(count):
            at += -(at - _ENCAPSULATION) % 4
            if at + 4 > size:
                raise ValueError(f"payload ends before string {len(out)} of {count}")
            n = struct.unpack_from(fmt, body, at)[0]
            at += 4 + n
            if at > size:
                raise ValueError(f"payload of {size} bytes ends inside string {len(out)} of "
                                 f"{count}")
            out.append(body[at - n:at - 1].decode())
        self.at = at
        return out

    def array(self, code: str) -> np.ndarray:
        """Return the next sequence of numbers of numpy type `code` ('u4', 'i8', 'f8')."""
        n = self.u32()
        size = int(code[1:])
        if n:  # no padding before an empty sequence's (absent) first element
            self._align(size)
        self._need(n * size)
        out = np.frombuffer(self.body, self.end + code, n, self.at)
        self.at += n * size
        return out


@dataclass(frozen=True)
class EstimateBatchColumns:
    """An ``EstimateBatch``'s fields as its bytes hold them (m, m/s; row-major columns)."""

    stamp_sec: int
    stamp_nanosec: int
    frame_id: str
    update_source: int
    key_lo: int
    key_hi: int
    object_id: list[str]
    shard_key: np.ndarray
    stamp_ns: np.ndarray
    state: np.ndarray
    covariance: np.ndarray
    nis: np.ndarray


def estimate_batch_columns(data: bytes) -> EstimateBatchColumns:
    """Return a serialized ``EstimateBatch``'s fields (for `messages.estimate_batch_from_msg`).

    ValueError for bytes that are no such message (an unknown encapsulation, a field cut
    short).
    """
    c = _Cursor(data)
    sec, nanosec, frame = c.u32(), c.u32(), c.string()
    return EstimateBatchColumns(
        stamp_sec=sec - (1 << 32) if sec >= 1 << 31 else sec, stamp_nanosec=nanosec,
        frame_id=frame, update_source=c.u8(), key_lo=c.u32(), key_hi=c.u32(),
        object_id=c.strings(), shard_key=c.array("u4"), stamp_ns=c.array("i8"),
        state=c.array("f8"), covariance=c.array("f8"), nis=c.array("f8"))


def measurement_batch_rows(data: bytes) -> int:
    """Return the rows of a serialized ``MeasurementBatch`` (CDR bytes as a bag holds them).

    ValueError for bytes that are no such message: an unknown encapsulation, a payload
    shorter than its header, or a row count the payload cannot hold.
    """
    c = _Cursor(data)
    c.u32(), c.u32(), c.string(), c.u32(), c.u32()  # stamp, frame_id, key_lo, key_hi
    rows = c.u32()
    if rows * MEASUREMENT_ROW_MIN_BYTES > len(c.body) - c.at:
        raise ValueError(f"{rows} rows cannot fit in a payload of "
                         f"{len(c.body) - _ENCAPSULATION} bytes")
    return rows

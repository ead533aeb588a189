"""A node's memory kept to what it holds: `release_free_heap`, `AckedPublisher`.

The freed C heap given back to the operating system, a reliable publisher's unacknowledged
messages bounded.

A catalog node allocates and frees a batch's arrays (and DDS its messages) many times a
second. glibc's malloc keeps the pages of freed blocks inside its heap resident until the
top of the heap is free, so a long-running process's resident set stays at the high-water
mark of its batches. ``malloc_trim(0)`` returns every whole free page of the heap (and of
the threads' arenas) to the system: the memory stays usable, only the pages are dropped.

Elsewhere than glibc (musl, macOS) there is no ``malloc_trim``: `release_free_heap` does
nothing there and says so (False).

A reliable publisher's history keeps each message it sent until every reader acknowledged it,
and Fast DDS (as rmw_fastrtps configures it: preallocated history memory, reallocated to the
largest message) never frees a history slot once made: a node that publishes a burst of large
messages faster than its readers acknowledge them keeps, for the rest of its life, as many
slots of the largest message's size as it ever had unacknowledged messages, and that count
only grows as bursts do. `AckedPublisher` bounds it: it waits for the readers'
acknowledgements once `max_unacked_rows` rows are out. The graphs ssa_fusion starts give
their nodes Fast DDS's dynamic history memory instead (`ros.discovery.ENDPOINT_PROFILES`):
a slot's buffer is freed once its message is acknowledged, so the history holds only what
is unacknowledged at the time, and the bound matters for nodes started without that profile.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import time
from collections.abc import Callable
from functools import cache
from typing import Generic, Protocol, TypeVar, cast

from rclpy.duration import Duration

MsgT = TypeVar("MsgT")
MsgT_contra = TypeVar("MsgT_contra", contravariant=True)


@cache
def _malloc_trim() -> Callable[[int], int] | None:
    """Return glibc's ``malloc_trim`` (ctypes function), or None without glibc."""
    name = ctypes.util.find_library("c")
    if not name:
        return None
    try:
        libc = ctypes.CDLL(name)
    except OSError:
        return None
    trim = getattr(libc, "malloc_trim", None)
    if trim is None:
        return None
    trim.argtypes, trim.restype = [ctypes.c_size_t], ctypes.c_int
    return cast(Callable[[int], int], trim)


def release_free_heap() -> bool:
    """Return the C heap's free pages to the system (``malloc_trim(0)``).

    Returns True when there is a ``malloc_trim`` (glibc) and it was called, else False.
    A pass over the heap: microseconds when little is free, tens of ms when hundreds of MB
    are (madvise per page); call it about once a second, not per message.
    """
    trim = _malloc_trim()
    if trim is None:
        return False
    trim(0)
    return True


class ReliablePublisher(Protocol[MsgT_contra]):
    """What `AckedPublisher` uses of an rclpy Publisher."""

    def publish(self, msg: MsgT_contra) -> None:
        """Publish `msg`."""

    def wait_for_all_acked(self, timeout: Duration) -> bool:
        """Wait until every matched reader acknowledged what was sent; False on timeout."""


class AckedPublisher(Generic[MsgT]):
    """Publishes batches of rows on a reliable publisher, at most `max_unacked_rows` unacknowledged.

    Before a message whose rows would take the rows published since the last wait beyond
    `max_unacked_rows`, it waits (at most `timeout_s` wall s) until every matched reader has
    acknowledged everything the publisher sent (``wait_for_all_acked``): the history then
    holds about `max_unacked_rows` rows of messages at most (module docstring), not a whole
    burst. Acknowledgement is receipt by the reader's DDS, not its callback's work: a reader
    that falls behind in handling what it received does not hold the publisher back. A wait
    that times out (a reader that does not answer) is counted (`timeouts`) and the message
    goes out anyway.

    Parameters
    ----------
    pub : ReliablePublisher
        An rclpy Publisher, reliable (a best-effort one never waits).
    max_unacked_rows : float
        Rows published between two waits (one message of more goes out alone; inf: never
        wait).
    timeout_s : float
        Longest wait, wall s.
    """

    def __init__(self, pub: ReliablePublisher[MsgT], max_unacked_rows: float,
                 timeout_s: float = 1.0) -> None:
        self.pub = pub
        self.max_unacked_rows = max_unacked_rows
        self.timeout = Duration(nanoseconds=int(timeout_s * 1e9))
        self.unacked_rows = 0
        """Rows published since the last wait."""
        self.waits = 0
        """Waits for acknowledgements."""
        self.timeouts = 0
        """Waits that ended by the timeout, not by every reader's acknowledgement."""
        self.waited_s = 0.0
        """Wall s spent waiting."""

    def publish(self, msg: MsgT, rows: int) -> None:
        """Publish `msg` of `rows` rows, first waiting for acknowledgements if due."""
        if self.unacked_rows and self.unacked_rows + rows > self.max_unacked_rows:
            self.waits += 1
            start = time.monotonic()
            if not self.pub.wait_for_all_acked(self.timeout):
                self.timeouts += 1
            self.waited_s += time.monotonic() - start
            self.unacked_rows = 0
        self.pub.publish(msg)
        self.unacked_rows += rows

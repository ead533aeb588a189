"""release_free_heap: the pages of freed heap blocks go back to the system (glibc).

AckedPublisher: at most its bound of rows unacknowledged before it waits for the readers."""

import ctypes.util
import math
from pathlib import Path

import numpy as np
import pytest
from rclpy.duration import Duration

from ssa_fusion.nodes.kit.memory import AckedPublisher, release_free_heap


def _rss_kib() -> int:
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1])
    raise AssertionError("no VmRSS")


@pytest.mark.skipif(not Path("/proc/self/status").exists()
                    or "libc.so" not in (ctypes.util.find_library("c") or ""),
                    reason="glibc and /proc only")
def test_freed_heap_returned():
    # 100 MB of 800-byte blocks on the heap (below the mmap threshold), all freed but the
    # last: the heap's top stays in use, so free() alone keeps the pages resident
    blocks = [np.ones(100) for _ in range(125_000)]
    del blocks[:-1]
    before = _rss_kib()
    assert release_free_heap()
    after = _rss_kib()
    assert before - after > 50_000, (before, after)  # KiB
    assert blocks[0].sum() == 100.0  # what is still held is intact


class _Publisher:
    """Stands for a reliable rclpy publisher: records what it is asked to do, in order.

    Its readers acknowledge a wait's messages unless `answers` is False.
    """

    def __init__(self, answers: bool = True) -> None:
        self.calls: list[tuple[str, object]] = []
        self.answers = answers

    def publish(self, msg: object) -> None:
        self.calls.append(("publish", msg))

    def wait_for_all_acked(self, timeout: object) -> bool:
        self.calls.append(("wait", timeout))
        return self.answers


def test_acked_publisher_waits_before_a_message_that_would_pass_the_bound():
    pub = _Publisher()
    acked = AckedPublisher(pub, max_unacked_rows=10_000, timeout_s=0.5)
    for k, rows in enumerate([5_000, 5_000, 5_000, 3_000, 2_000, 5_000, 12_000, 1]):
        acked.publish(k, rows)
    # unacknowledged rows before each publication: 0, 5k, 10k -> wait, 5k, 8k, 10k -> wait,
    # 5k (12k pass it: wait; a message of more than the bound goes out alone), 12k -> wait
    assert [c[0] for c in pub.calls] == [
        "publish", "publish", "wait", "publish", "publish", "publish", "wait", "publish",
        "wait", "publish", "wait", "publish"]
    assert [c[1] for c in pub.calls if c[0] == "publish"] == list(range(8))
    waits = [c[1] for c in pub.calls if c[0] == "wait"]
    assert all(w == Duration(nanoseconds=500_000_000) for w in waits)
    assert (acked.waits, acked.timeouts, acked.unacked_rows) == (4, 0, 1)


def test_acked_publisher_counts_a_wait_no_reader_answers_and_publishes_anyway():
    pub = _Publisher(answers=False)
    acked = AckedPublisher(pub, max_unacked_rows=1)
    for k in range(3):
        acked.publish(k, 1)
    assert [c[1] for c in pub.calls if c[0] == "publish"] == [0, 1, 2]
    assert (acked.waits, acked.timeouts) == (2, 2)


def test_acked_publisher_without_a_bound_never_waits():
    pub = _Publisher()
    acked = AckedPublisher(pub, max_unacked_rows=math.inf)
    for k in range(100):
        acked.publish(k, 5_000)
    assert [c[0] for c in pub.calls] == ["publish"] * 100 and acked.waits == 0

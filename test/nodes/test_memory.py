"""release_free_heap: the pages of freed heap blocks go back to the system (glibc)."""

import ctypes.util
from pathlib import Path

import numpy as np
import pytest

from ssa_fusion.nodes.memory import release_free_heap


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

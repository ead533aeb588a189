"""Giving a node's freed C heap back to the operating system: `release_free_heap`.

A catalog node allocates and frees a batch's arrays (and DDS its messages) many times a
second. glibc's malloc keeps the pages of freed blocks inside its heap resident until the
top of the heap is free, so a long-running process's resident set stays at the high-water
mark of its batches. ``malloc_trim(0)`` returns every whole free page of the heap (and of
the threads' arenas) to the system: the memory stays usable, only the pages are dropped.

Elsewhere than glibc (musl, macOS) there is no ``malloc_trim``: `release_free_heap` does
nothing there and says so (False).
"""

from __future__ import annotations

import ctypes
import ctypes.util
from collections.abc import Callable
from functools import cache
from typing import cast


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

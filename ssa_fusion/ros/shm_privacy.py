"""Fast DDS's shared-memory files, private to the user who runs the graph.

On this host's loopback the nodes' middleware (rmw_fastrtps, ``ROS_AUTOMATIC_DISCOVERY_RANGE``
LOCALHOST) adds Fast DDS's shared-memory transport whatever the XML profile says, and Fast DDS
creates its segments (``/dev/shm/fastdds_*``: every message sent to a process on this host
passes through them) readable by every local user, whatever the umask (measured:
docs/SECURITY.md). `make_private` takes the read and write bits of the group and of others
from every such file this process has mapped or open and owns; the processes of one user
still share them. Each node and each probe calls it once its participant exists and then
every `PERIOD_S` (segments of participants that join later), so a segment is open to others
for at most that long after it appears.
"""

from __future__ import annotations

import contextlib
import os
import re
from pathlib import Path

SHM = Path("/dev/shm")
PREFIXES = ("fastdds_", "sem.fastdds_")
"""Fast DDS's segments, port segments, their lock files and named semaphores."""
PERIOD_S = 1.0
"""Wall s between two looks for new segments."""
_PATH = re.compile(r"(/dev/shm/\S+)")


def _used() -> set[Path]:
    """Return the /dev/shm files this process has mapped or open."""
    out: set[Path] = set()
    with contextlib.suppress(OSError):
        for line in Path("/proc/self/maps").read_text().splitlines():
            m = _PATH.search(line)
            if m:
                out.add(Path(m.group(1)))
    with contextlib.suppress(OSError):
        for fd in Path("/proc/self/fd").iterdir():
            with contextlib.suppress(OSError):
                target = os.readlink(fd)
                if target.startswith("/dev/shm/"):
                    out.add(Path(target.split(" (deleted)")[0]))
    return out


def make_private() -> list[Path]:
    """Make Fast DDS's /dev/shm files this process uses and owns private; return those changed.

    A file another user owns is left alone (it is theirs to protect); one that disappeared
    meanwhile is skipped.
    """
    changed = []
    uid = os.getuid()
    for path in _used():
        if not path.name.startswith(PREFIXES):
            continue
        with contextlib.suppress(OSError):
            st = path.stat()
            if st.st_uid == uid and st.st_mode & 0o077:
                path.chmod(st.st_mode & 0o700)
                changed.append(path)
    return changed

"""Whether a node that reports lockstep progress is still there.

Lockstep waits for a consumer as long as it lives, however long that is (a stopped process,
a swap storm, a closed laptop lid): sim time must not go on without it. It gives up only
when the consumer is gone. Each consumer's progress report carries its process (`PID`,
`START`: its start time in clock ticks since boot) and where it runs (`HOST`: the boot id and
the PID namespace). The simulator asks `alive`:

* a consumer on its host and in its PID namespace is alive while its process exists, is
  the one that reported (same start time) and is no zombie: a stopped process (SIGSTOP) is
  alive, an ended one is gone at once;
* any other (a shard on another host) is alive while the ROS graph lists its node (DDS drops a
  participant after its lease expires: 20 s without a word from it by Fast DDS's default,
  as across hosts, 600 s in the profile a graph on one host runs with
  (`ros.discovery.PARTICIPANT_LEASE_S`): a consumer stopped that long counts as gone).
"""

from __future__ import annotations

import contextlib
import os
from collections.abc import Mapping
from pathlib import Path

PID = "pid"
"""Progress key: the reporting process's id."""
START = "start"
"""Progress key: the reporting process's start time (clock ticks since boot, /proc)."""
HOST = "host"
"""Progress key: the boot id and PID namespace the process runs in."""


def _stat(pid: int) -> list[str] | None:
    """Return the fields of /proc/`pid`/stat after the command name, or None."""
    try:
        text = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return None
    return text[text.rfind(")") + 2:].split()


def host_key() -> str:
    """Return where this process runs: its boot id and PID namespace ('' if unknown)."""
    boot = ""
    with contextlib.suppress(OSError):
        boot = Path("/proc/sys/kernel/random/boot_id").read_text().strip()
    ns = ""
    with contextlib.suppress(OSError):
        ns = os.readlink("/proc/self/ns/pid")
    return f"{boot}/{ns}" if boot and ns else ""


def process_keys() -> dict[str, str]:
    """Return this process's `PID`, `START` and `HOST`, as a progress report carries them."""
    fields = _stat(os.getpid())
    return {PID: str(os.getpid()), START: fields[19] if fields else "", HOST: host_key()}


def process_alive(report: Mapping[str, str]) -> bool | None:
    """Return whether the process of `report` lives, or None where this cannot be told.

    None when the report names no process, or one on another host or PID namespace.
    """
    pid, start, host = report.get(PID, ""), report.get(START, ""), report.get(HOST, "")
    if not pid.isdigit() or not host or host != host_key():
        return None
    fields = _stat(int(pid))
    if fields is None:
        return False
    return fields[0] != "Z" and (not start or fields[19] == start)


def alive(report: Mapping[str, str] | None, in_graph: bool) -> bool:
    """Return whether a consumer lives: its process when it can be seen, else the graph.

    `in_graph`: the ROS graph lists the consumer's node.
    """
    seen = process_alive(report) if report is not None else None
    return in_graph if seen is None else seen

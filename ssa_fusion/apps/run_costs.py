"""What a run's node processes cost, and when its phases began: CPU time, memory, stamps.

`cpu_s` reads a running process's CPU time (user + system) from ``/proc`` (Linux; 0 when
unknown); the simulator, which has ended by the time a run sums up, says its own in its
last line (`sensor_costs`, from its log: ``schedule done: ...; CPU S s, peak RSS M MiB``);
`first_measurement` is the wall time its first measurements went out. `phases` turns them
into the run's start-up (command start to the first measurement), running (first
measurement to the last estimate) and summary (the run's end to its summary printed).
"""

from __future__ import annotations

import os
import re
from pathlib import Path

_TICKS = os.sysconf("SC_CLK_TCK") if hasattr(os, "sysconf") else 100
_STAMP = re.compile(r"\[(\d+(?:\.\d+)?)\]")
_SENSOR = re.compile(r"schedule done: .*; CPU ([0-9.]+) s, peak RSS ([0-9.]+) MiB")
FIRST_LINE = "first measurements published"
"""What the simulator logs when its first measurements go out."""


def cpu_s(pid: int) -> float:
    """Return the CPU time (user + system, s) process `pid` has used; 0 when unknown."""
    try:
        fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
        return (int(fields[11]) + int(fields[12])) / _TICKS
    except (OSError, IndexError, ValueError):
        return 0.0


def _lines(log: Path) -> list[str]:
    try:
        return log.read_text(errors="replace").splitlines()
    except OSError:
        return []


def sensor_costs(log: Path) -> tuple[float, float] | None:
    """Return (CPU s, peak RSS MiB) the simulator said at its end (its stderr `log`), or None."""
    for line in reversed(_lines(log)):
        m = _SENSOR.search(line)
        if m:
            return float(m.group(1)), float(m.group(2))
    return None


def first_measurement(log: Path) -> float | None:
    """Return the wall time (Unix s) of the simulator's first measurements (its `log`)."""
    for line in _lines(log):
        if FIRST_LINE in line and (m := _STAMP.search(line)):
            return float(m.group(1))
    return None


def phases(command_start: float, first: float | None,
           ran: tuple[float, float] | None) -> dict[str, float | None]:
    """Return the run's start-up and running wall s (Unix stamps; None: unknown).

    `command_start`: when the command started; `first`: its first measurement out; `ran`:
    (first measurement, last estimate).
    """
    return {"startup_s": None if first is None else first - command_start,
            "running_s": None if ran is None else ran[1] - ran[0]}

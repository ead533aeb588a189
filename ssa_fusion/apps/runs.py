"""Run directories of `ssa-fusion live`: one per run, named like rosbag2's bags, and the logs.

`default_out` names a new directory (`out/live/<scenario>_<date-time>`), `link_latest`
points `out/live/latest` at it, `run_dirs` makes it and picks the bag inside,
`sensor_wall_times` reads from sensor_sim's log when the simulation started and ended,
`ended_badly` says which node processes of a run did not end well, `run_graph` gives a run
its identity and its ROS domain (`ros.run_identity`, `ros.domains`), and `replay_graph`
opens a replay's (`run_graph`) beside the bag it records.
"""

from __future__ import annotations

import argparse
import os
import re
import sys
import time
from pathlib import Path
from typing import TYPE_CHECKING

from ssa_fusion.apps.args import discovery

if TYPE_CHECKING:
    from ssa_fusion.ros.processes import Graph

LIVE_ROOT = Path("out/live")
"""Where runs go by default, one directory each."""


def default_out(scenario: str, root: Path = LIVE_ROOT) -> Path:
    """Return a new run directory named like rosbag2's default bags, never an existing one."""
    stamp = time.strftime("%Y_%m_%d-%H_%M_%S")
    out = root / f"{scenario}_{stamp}"
    n = 1
    while out.exists():
        n += 1
        out = root / f"{scenario}_{stamp}_{n}"
    return out


def link_latest(out: Path, root: Path = LIVE_ROOT) -> None:
    """Point root/latest at `out` (replacing an older link, never a real directory)."""
    latest = root / "latest"
    if latest.exists() and not latest.is_symlink():
        return
    tmp = root / f".latest_{os.getpid()}"
    tmp.unlink(missing_ok=True)
    tmp.symlink_to(os.path.relpath(out.resolve(), root.resolve()), target_is_directory=True)
    os.replace(tmp, latest)


def ended_badly(problems: list[str]) -> bool:
    """Say on stderr how node processes ended badly (`Graph.close`'s problems); True if any."""
    if problems:
        print("error: node process(es) ended badly:\n" + "\n\n".join(problems), file=sys.stderr)
    return bool(problems)


def run_graph(args: argparse.Namespace, logs: Path, command: str) -> Graph | None:
    """Return the graph of a new run in its ROS domain, or None after a one-line error.

    A new run id (its nodes' namespace); ``--domain-id`` (or $ROS_DOMAIN_ID) if no one else
    is in it (``--share-domain``: whoever is), else a free domain (`ros.domains.open_graph`).
    `command` prefixes what it says of domains passed over.
    """
    from ssa_fusion.ros.domains import DomainInUseError, open_graph
    from ssa_fusion.ros.run_identity import new_run_id

    try:
        return open_graph(logs, args.domain_id, new_run_id(), discovery(args),
                          share=bool(getattr(args, "share_domain", False)),
                          say=lambda text: print(f"{command}: {text}", flush=True))
    except DomainInUseError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return None


_LOG_STAMP = re.compile(r"\[(\d+(?:\.\d+)?)\]")


def sensor_wall_times(log: Path) -> tuple[float, float] | None:
    """Return (start, end) of the simulation in wall time (Unix s) from sensor_sim's log.

    The log is its stderr, in rcutils' default format: the lines "starting" and "schedule
    done"; None when either is missing or unreadable.
    """
    try:
        lines = log.read_text(errors="replace").splitlines()
    except OSError:
        return None
    start = end = None
    for line in lines:
        stamp = _LOG_STAMP.search(line)
        if stamp is None:
            continue
        if start is None and ("]: subscribers matched; starting" in line
                              or "]: starting (" in line):
            start = float(stamp.group(1))
        elif "]: schedule done" in line:
            end = float(stamp.group(1))
    return (start, end) if start is not None and end is not None and end >= start else None


def run_dirs(args: argparse.Namespace, name: str) -> tuple[Path, Path] | None:
    """Create and return the run directory and the bag path in it.

    The directory is `--out`, else a new one named after `name`, linked as latest; the bag
    is `--bag`, else OUT/bag. None after a one-line error when the bag exists or the
    directory cannot be made.
    """
    out: Path = args.out or default_out(name)
    bag: Path = args.bag or out / "bag"
    if bag.exists():
        print(f"error: bag {bag} exists already; choose another --bag or --out",
              file=sys.stderr)
        return None
    try:
        out.mkdir(parents=True, exist_ok=True)
        if args.out is None:
            link_latest(out)
    except OSError as exc:
        print(f"error: cannot use {out}: {exc}", file=sys.stderr)
        return None
    return out, bag


def replay_graph(args: argparse.Namespace, record: Path) -> tuple[Graph, Path] | None:
    """Return the graph of a replay recording to `record` (`run_graph`), and its logs directory.

    The logs go beside the bag (its name + ``_logs``); None when that directory cannot be
    used or no ROS domain can be had (said on stderr).
    """
    logs = record.with_name(record.name + "_logs")
    try:
        graph = run_graph(args, logs, "replay")
    except OSError as exc:
        print(f"error: cannot use {record}: {exc}", file=sys.stderr)
        return None
    return None if graph is None else (graph, logs)

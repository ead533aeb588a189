"""`ssa-fusion bag repair BAG`: make a bag whose recorder was killed readable by any reader.

A recorder killed with SIGKILL (or a power loss) leaves a bag without ``metadata.yaml``
and an ``.mcap`` without summary or footer: `ssa-fusion report`/`replay` read it
(`bagio.read_bag` recovers every complete chunk), plain ``rosbags`` and ``ros2 bag`` do
not. `repair` writes those chunks' messages to a new, closed bag (`ros.bagrepair`).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from ssa_fusion.ros import bagrepair
from ssa_fusion.ros.bagio import BagError


def add_arguments(p: argparse.ArgumentParser) -> None:
    """Add the `bag` subcommands (`repair`) to `p`."""
    sub = p.add_subparsers(dest="bag_command", required=True, metavar="{repair}")
    r = sub.add_parser(
        "repair", help="rewrite an unclosed bag (recorder killed) as a complete one",
        description="Rewrite the complete chunks of a bag whose recorder was killed (no "
                    "metadata.yaml, no MCAP summary) as a new, closed rosbag2 v9 MCAP bag "
                    "that plain rosbags and MCAP readers open: same topics, types, "
                    "definitions, bytes and timestamps; at most the last, incomplete chunk "
                    "is lost.")
    r.add_argument("bag", type=Path, help="the bag directory (or bare .mcap file) to repair")
    r.add_argument("--out", type=Path, default=None,
                   help="where to write the repaired bag; must not exist (default: "
                        "BAG_repaired next to BAG)")
    r.set_defaults(_bag_run=run_repair)


def run(args: argparse.Namespace) -> int:
    """Run the chosen `bag` subcommand; return its exit code."""
    return int(args._bag_run(args))


def run_repair(args: argparse.Namespace) -> int:
    """Exit 0 with one line of per-topic counts; 2 with one `error:` line."""
    try:
        result = bagrepair.repair(args.bag, args.out)
    except BagError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    print(result.line(args.bag))
    return 0

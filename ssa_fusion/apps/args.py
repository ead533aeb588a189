"""Argument types and options shared by the `ssa-fusion` subcommands."""

from __future__ import annotations

import argparse
import math
import os
from pathlib import Path


def positive_float(text: str) -> float:
    """Parse a finite float > 0 (an argparse type)."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number") from None
    if not value > 0 or value == float("inf"):
        raise argparse.ArgumentTypeError(f"must be a finite number > 0, got {text}")
    return value


def time_scale(text: str) -> float:
    """Parse a time scale: a finite float > 0, or ``max`` (inf: as fast as the graph goes)."""
    return math.inf if text == "max" else positive_float(text)


MAX_DOMAIN_ID = 232
"""The largest ROS domain id (DDS ports: 7400 + 250 x id must stay below 65536)."""


def domain_id(text: str) -> int:
    """Parse `--domain-id` (an argparse type): an integer in 0..`MAX_DOMAIN_ID`."""
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not an integer") from None
    if not 0 <= value <= MAX_DOMAIN_ID:
        raise argparse.ArgumentTypeError(
            f"{value} is outside 0..{MAX_DOMAIN_ID} (ROS domain ids; 0..101 avoid the "
            "ephemeral ports on Linux)")
    return value


def add_domain_id(p: argparse.ArgumentParser) -> None:
    """Add `--domain-id` to `p`.

    It defaults to $ROS_DOMAIN_ID when that is set (so that ROS tools in the same shell see
    the run), else to a free-looking id chosen by `graph.Graph`.
    """
    env = os.environ.get("ROS_DOMAIN_ID", "").strip()
    p.add_argument("--domain-id", type=domain_id, default=int(env) if env.isdigit() else None,
                   help="ROS domain id (default: $ROS_DOMAIN_ID if set, else a free-looking "
                        "one in 1..100)")


def add_sites(p: argparse.ArgumentParser, what: str) -> None:
    """Add ``--sites FILE`` (a sites file, `core.site_file`; `what` it gives) to `p`."""
    p.add_argument("--sites", type=Path, default=None, metavar="SITES.yaml",
                   help=f"sites file (YAML, docs/SITES.md): {what}")


def add_settings(p: argparse.ArgumentParser, verb: str, default: str) -> None:
    """Add ``--scenario`` and ``--params-file``: the estimator settings to `verb` with.

    `default`: what is used without either.
    """
    p.add_argument("--scenario", default="",
                   help=f"{verb} with this paper scenario's estimator settings (default: "
                        f"{default})")
    p.add_argument("--params-file", type=Path, default=None,
                   help=f"{verb} with the filter/surrogate settings of this ROS params YAML")

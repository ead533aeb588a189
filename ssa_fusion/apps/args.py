"""Argument types and options shared by the `ssa-fusion` subcommands."""

from __future__ import annotations

import argparse
import math
import os
from pathlib import Path

from ssa_fusion.ros.discovery import Discovery, DiscoveryRange, peer_problem


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
    """Add `--domain-id` and `--share-domain` to `p`.

    It defaults to $ROS_DOMAIN_ID when that is set (so that ROS tools in the same shell see
    the run), else to a free domain (`ros.domains`: one without other participants). A
    domain named that others use is refused unless `--share-domain`.
    """
    env = os.environ.get("ROS_DOMAIN_ID", "").strip()
    p.add_argument("--domain-id", type=domain_id, default=int(env) if env.isdigit() else None,
                   help="ROS domain id (default: $ROS_DOMAIN_ID if set, else a free one in "
                        "1..101, looked for); refused when other nodes are in it")
    p.add_argument("--share-domain", action="store_true",
                   help="run in --domain-id even if other nodes are in it (the run keeps to "
                        "its own traffic, docs/SECURITY.md)")


def static_peers(text: str) -> tuple[str, ...]:
    """Parse `--static-peers` (an argparse type): comma-separated IP addresses or host names."""
    peers = tuple(x.strip() for x in text.split(",") if x.strip())
    for peer in peers:
        problem = peer_problem(peer)
        if problem:
            raise argparse.ArgumentTypeError(problem)
    return peers


def discovery_range(text: str) -> DiscoveryRange:
    """Parse `--discovery-range` (an argparse type): a `DiscoveryRange`, any case."""
    try:
        return DiscoveryRange(text.strip().upper())
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"{text!r} is not one of {', '.join(DiscoveryRange)}") from None


def add_discovery(p: argparse.ArgumentParser) -> None:
    """Add `--discovery-range` and `--static-peers` to `p` (read back by `discovery`).

    Without them every node discovers only nodes of this host (docs/MULTIHOST.md), whatever
    the shell's ``ROS_AUTOMATIC_DISCOVERY_RANGE``/``ROS_STATIC_PEERS`` say.
    """
    p.add_argument("--discovery-range", type=discovery_range, default=DiscoveryRange.LOCALHOST,
                   metavar="{" + ",".join(DiscoveryRange) + "}",
                   help="ROS_AUTOMATIC_DISCOVERY_RANGE of every node: LOCALHOST (default: this "
                        "host only) or SUBNET (multicast on this host's networks: nodes on other "
                        "hosts, docs/MULTIHOST.md)")
    p.add_argument("--static-peers", type=static_peers, default=(), metavar="ADDR[,ADDR...]",
                   help="ROS_STATIC_PEERS of every node: other hosts' addresses to announce to "
                        "by unicast (for networks without multicast; docs/MULTIHOST.md)")


def discovery(args: argparse.Namespace) -> Discovery:
    """Return the discovery settings of `add_discovery`'s options in `args` (default: loopback)."""
    return Discovery(getattr(args, "discovery_range", DiscoveryRange.LOCALHOST),
                     getattr(args, "static_peers", ()))


def add_sites(p: argparse.ArgumentParser, what: str) -> None:
    """Add ``--sites FILE`` (a sites file, `formats.sites`; `what` it gives) to `p`."""
    p.add_argument("--sites", type=Path, default=None, metavar="SITES.yaml",
                   help=f"sites file (YAML, docs/SITES.md): {what}")


def add_settings(p: argparse.ArgumentParser, verb: str, default: str) -> None:
    """Add ``--scenario``, ``--params-file``, ``--filter``: the estimator settings to `verb` with.

    `default`: what is used without either.
    """
    p.add_argument("--scenario", default="",
                   help=f"{verb} with this paper scenario's estimator settings (default: "
                        f"{default})")
    p.add_argument("--params-file", type=Path, default=None,
                   help=f"{verb} with the filter/surrogate settings of this ROS params YAML")
    from ssa_fusion.apps.filter_setup import FilterSetup

    p.add_argument("--filter", type=FilterSetup, choices=list(FilterSetup), default=None,
                   metavar="{" + ",".join(FilterSetup) + "}", dest="setup",
                   help=f"{verb} with this filter set-up for the bag's own measurements: "
                        "radar (range/az/el), optical (ra/dec), network (both), position "
                        "(default for a bag without recorded settings: the one its "
                        "measurements call for)")

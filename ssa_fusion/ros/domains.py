"""A ROS domain for a run: a free one, or the one asked for if no one else is in it.

ROS domains keep graphs apart only when each picks its own, and a default computed from the
process id picks the same one in every container (each has its own PID 1). So before a run
starts any node, its probe joins the domain and looks for participants (`LOOK_S`: discovery
on this host takes 0.1-3.6 s): with ``--domain-id`` (or ``$ROS_DOMAIN_ID``) a domain in use
is refused, unless the run is told to share it (it then keeps to its own traffic:
`ros.run_identity`); without, random domains of `processes.auto_domains` (1..101 unless
``$SSA_FUSION_DOMAINS`` narrows them) are tried until one is free.

Two runs that start at once see each other's probe: the older (`run_identity.older`: run ids
begin with their start time) keeps the domain and the younger yields, so exactly one of them
moves on (or refuses). Nodes named ``_...`` (the ``ros2`` command's daemon) do not count.
"""

from __future__ import annotations

import random
from collections.abc import Callable
from pathlib import Path

from ssa_fusion.ros.discovery import LOOPBACK, Discovery
from ssa_fusion.ros.processes import Graph, auto_domains
from ssa_fusion.ros.run_identity import older, run_of

LOOK_S = 2.0
"""Wall s a run's probe looks for other participants in a domain before it takes it."""
AUTO_TRIES = 20
"""Domains tried before a run without ``--domain-id`` gives up."""


class DomainInUseError(RuntimeError):
    """The domain asked for is in use (or no free one was found); one line says by whom."""


def blocking(others: list[str], run: str) -> list[str]:
    """Return the nodes of `others` (full names) a run `run` must not share a domain with.

    Every node but those of younger runs (which yield to this one).
    """
    out = []
    for name in others:
        theirs = run_of(name.rsplit("/", 1)[0])
        if theirs is None or not older(run, theirs):
            out.append(name)
    return out


def _describe(nodes: list[str]) -> str:
    shown = ", ".join(nodes[:3])
    return shown + (f" and {len(nodes) - 3} more" if len(nodes) > 3 else "")


def open_graph(workdir: Path, domain_id: int | None, run: str,
               discovery: Discovery = LOOPBACK, share: bool = False,
               look_s: float = LOOK_S, say: Callable[[str], None] = lambda _t: None,
               rng: random.Random | None = None) -> Graph:
    """Return the graph of run `run` in a domain of its own (see the module docstring).

    `domain_id`: the domain asked for (None: a free one). `share`: take the domain asked for
    even if others are in it. `say`: told of each domain passed over. `DomainInUseError` when the
    domain asked for is in use, or no free one was found in `AUTO_TRIES`.
    """
    if domain_id is not None:
        graph = Graph(workdir, domain_id, discovery, run)
        if share:
            return graph
        them = blocking(graph.others(look_s), run)
        if not them:
            return graph
        graph.close()
        raise DomainInUseError(f"ROS domain {domain_id} is in use ({_describe(them)}); choose "
                          "another --domain-id, leave it out for a free one, or "
                          "--share-domain to run beside them")
    rng = rng or random.Random()
    domains = auto_domains()
    tries = min(AUTO_TRIES, len(domains))
    for domain in rng.sample(domains, tries):
        graph = Graph(workdir, domain, discovery, run)
        them = blocking(graph.others(look_s), run)
        if not them:
            return graph
        graph.close()
        say(f"ROS domain {domain} is in use ({_describe(them)}); trying another")
    raise DomainInUseError(f"no free ROS domain found in {tries} tries of "
                      f"{domains.start}..{domains.stop - 1}; "
                      "name one with --domain-id (and --share-domain to share it)")

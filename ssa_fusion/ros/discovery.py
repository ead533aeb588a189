"""How far a graph's DDS discovery reaches: this host only (the default), or other hosts.

The nodes' middleware (rmw_fastrtps_cpp, Fast DDS) reads two environment variables when a
process creates its ROS context: ``ROS_AUTOMATIC_DISCOVERY_RANGE`` (`DiscoveryRange`) and
``ROS_STATIC_PEERS`` (addresses to announce to by unicast, ';'-separated). `Discovery`
holds both for the processes ssa_fusion starts (`ros.processes.Graph`). Neither binds a
socket to an address: they decide whom a participant announces itself to (measured, and the
consequences, in docs/MULTIHOST.md).
"""

from __future__ import annotations

import ipaddress
import re
from collections.abc import MutableMapping
from dataclasses import dataclass
from enum import StrEnum

RANGE_VAR = "ROS_AUTOMATIC_DISCOVERY_RANGE"
"""The environment variable of the automatic discovery range."""
PEERS_VAR = "ROS_STATIC_PEERS"
"""The environment variable of the static peers (';'-separated addresses)."""
_HOSTNAME = re.compile(r"^(?=.{1,253}$)[A-Za-z0-9]([A-Za-z0-9-]*[A-Za-z0-9])?"
                       r"(\.[A-Za-z0-9]([A-Za-z0-9-]*[A-Za-z0-9])?)*$")


class DiscoveryRange(StrEnum):
    """Values of ``ROS_AUTOMATIC_DISCOVERY_RANGE`` a graph runs with."""

    LOCALHOST = "LOCALHOST"
    """Announce to participants of this host only (no multicast): the default."""
    SUBNET = "SUBNET"
    """Announce by multicast on the host's networks: nodes on other hosts of the subnet."""


@dataclass(frozen=True)
class Discovery:
    """The discovery settings of every process of a graph."""

    range: DiscoveryRange = DiscoveryRange.LOCALHOST
    static_peers: tuple[str, ...] = ()
    """Addresses (IP or host name) of other hosts to announce to by unicast."""

    @property
    def reaches_other_hosts(self) -> bool:
        """Return True when nodes on other hosts can discover this graph's."""
        return self.range is DiscoveryRange.SUBNET or bool(self.static_peers)

    def apply(self, env: MutableMapping[str, str]) -> None:
        """Set these settings in `env` (an environment), removing an inherited peer list."""
        env[RANGE_VAR] = self.range.value
        if self.static_peers:
            env[PEERS_VAR] = ";".join(self.static_peers)
        else:
            env.pop(PEERS_VAR, None)

    def exports(self) -> list[str]:
        """Return the ``NAME=value`` assignments of `apply` (for a shell command line)."""
        env: dict[str, str] = {}
        self.apply(env)
        return [f"{k}={v}" for k, v in env.items()]


def peer_problem(peer: str) -> str | None:
    """Return why `peer` is not an IP address or a host name, or None."""
    try:
        ipaddress.ip_address(peer)
        return None
    except ValueError:
        pass
    if _HOSTNAME.match(peer):
        return None
    return f"{peer!r} is not an IP address or a host name"


LOOPBACK = Discovery()
"""The default: automatic discovery on this host only, no static peers."""

"""How far a graph's DDS discovery reaches: this host only (the default), or other hosts.

The nodes' middleware (rmw_fastrtps_cpp, Fast DDS) reads two environment variables when a
process creates its ROS context: ``ROS_AUTOMATIC_DISCOVERY_RANGE`` (`DiscoveryRange`) and
``ROS_STATIC_PEERS`` (addresses to announce to by unicast, ';'-separated). `Discovery`
holds both for the processes ssa_fusion starts (`ros.processes.Graph`). Neither binds a
socket to an address: they decide whom a participant announces itself to, and Fast DDS
listens on every address of the host (measured in docs/MULTIHOST.md). So a graph that stays
on this host also gets a Fast DDS profile (`LOOPBACK_PROFILE`, `Discovery.bind`) that
listens on loopback only: a participant elsewhere that knows this host's address cannot
reach it either.

The same profile gives every reader and writer of the graph's processes Fast DDS's dynamic
history memory (`ENDPOINT_PROFILES`): a message's buffer is allocated when the message
enters a history and freed when it leaves. rmw_fastrtps otherwise configures
``PREALLOCATED_WITH_REALLOC`` memory, whose buffers are never freed: a catalog node's
estimate writer (and its measurement readers) keep, for the rest of their life, as many
buffers of the largest message's size as their history ever held at once (a burst that
readers acknowledged late), tens of MiB a process. rmw_fastrtps applies an XML profile's
history memory only with ``RMW_FASTRTPS_USE_QOS_FROM_XML=1`` (`QOS_FROM_XML_VAR`), and
then takes the publication mode and data sharing from the profile too: it sets them as
rmw_fastrtps does by default (synchronous publication, no data sharing). Those three are
all the variable changes (rmw_fastrtps 9, Kilted: its create_publisher and
create_subscription): the ROS QoS given in code (history, depth, reliability, durability
...) are applied on top of the profile either way.

It also gives every participant a lease of `PARTICIPANT_LEASE_S` (Fast DDS's default: 20 s).
A participant that says nothing for its lease is dropped by the others, and a volatile
writer that meets it again sends it nothing written before: a node stopped longer than the
lease (SIGSTOP, a debugger, a swap storm) lost for good what was sent to it meanwhile, and
in lockstep the simulator waited forever for rows that could no longer come (a recorder
stopped 30 s in a catalog run). Lockstep tells a local consumer that ended from one that is
silent by its process (`nodes.kit.liveness`), not by DDS, so the long lease costs it
nothing; a crashed process stays matched (its writers' unacknowledged samples kept) until
the lease runs out.
"""

from __future__ import annotations

import ipaddress
import re
from collections.abc import MutableMapping
from dataclasses import dataclass
from enum import StrEnum
from pathlib import Path

RANGE_VAR = "ROS_AUTOMATIC_DISCOVERY_RANGE"
"""The environment variable of the automatic discovery range."""
PEERS_VAR = "ROS_STATIC_PEERS"
"""The environment variable of the static peers (';'-separated addresses)."""
PROFILE_VAR = "FASTDDS_DEFAULT_PROFILES_FILE"
"""The environment variable naming the Fast DDS XML profiles file a process loads."""
QOS_FROM_XML_VAR = "RMW_FASTRTPS_USE_QOS_FROM_XML"
"""The environment variable that makes rmw_fastrtps take the history memory policy,
publication mode and data sharing from the XML profiles (``1``) rather than its own."""
PROFILE_NAME = "fastdds_loopback.xml"
"""The file name `Discovery.bind` writes `LOOPBACK_PROFILE` to."""
PARTICIPANT_LEASE_S = 600.0
"""Wall s a participant of a graph on this host may stay silent before the others drop it
(and, volatile, what was sent to it meanwhile): a node stopped that long (SIGSTOP, a
debugger) loses nothing (module docstring). Announced every `ANNOUNCE_PERIOD_S`."""
ANNOUNCE_PERIOD_S = 3.0
"""Wall s between two announcements of a participant that its lease holds (Fast DDS's
default)."""
ENDPOINT_PROFILES = """\
    <data_writer profile_name="ssa_fusion_writer" is_default_profile="true">
      <qos>
        <publishMode><kind>SYNCHRONOUS</kind></publishMode>
        <data_sharing><kind>OFF</kind></data_sharing>
      </qos>
      <historyMemoryPolicy>DYNAMIC</historyMemoryPolicy>
    </data_writer>
    <data_reader profile_name="ssa_fusion_reader" is_default_profile="true">
      <qos>
        <data_sharing><kind>OFF</kind></data_sharing>
      </qos>
      <historyMemoryPolicy>DYNAMIC</historyMemoryPolicy>
    </data_reader>
"""
"""Every writer's and reader's defaults: dynamic history memory (``DYNAMIC``, Fast DDS's
``DYNAMIC_RESERVE_MEMORY_MODE``: buffers freed with their messages; module docstring), and
what rmw_fastrtps sets by default otherwise (synchronous publication, data sharing off)."""


def _duration(tag: str, seconds: float) -> str:
    """Return a Fast DDS XML duration element `tag` of `seconds` (s, whole ns)."""
    sec, nanosec = divmod(round(seconds * 1e9), 1_000_000_000)
    return f"<{tag}><sec>{sec}</sec><nanosec>{nanosec}</nanosec></{tag}>"


def loopback_profile(lease_s: float = PARTICIPANT_LEASE_S,
                     announce_s: float = ANNOUNCE_PERIOD_S) -> str:
    """Return the Fast DDS profiles of a graph on this host (`LOOPBACK_PROFILE`).

    Every participant listens on loopback only, with a lease of `lease_s` wall s announced
    every `announce_s` (module docstring), and `ENDPOINT_PROFILES`.
    """
    return f"""\
<?xml version="1.0" encoding="UTF-8"?>
<!-- ssa_fusion: every participant listens on loopback only (UDPv4 on lo, and shared memory) -->
<dds xmlns="http://www.eprosima.com">
  <profiles>
    <transport_descriptors>
      <transport_descriptor>
        <transport_id>ssa_fusion_shm</transport_id>
        <type>SHM</type>
      </transport_descriptor>
      <transport_descriptor>
        <transport_id>ssa_fusion_loopback_udp</transport_id>
        <type>UDPv4</type>
        <interfaces>
          <allowlist>
            <interface name="lo"/>
          </allowlist>
        </interfaces>
      </transport_descriptor>
    </transport_descriptors>
    <participant profile_name="ssa_fusion_loopback" is_default_profile="true">
      <rtps>
        <userTransports>
          <transport_id>ssa_fusion_shm</transport_id>
          <transport_id>ssa_fusion_loopback_udp</transport_id>
        </userTransports>
        <useBuiltinTransports>false</useBuiltinTransports>
        <builtin>
          <discovery_config>
            {_duration("leaseDuration", lease_s)}
            {_duration("leaseAnnouncement", announce_s)}
          </discovery_config>
        </builtin>
      </rtps>
    </participant>
{ENDPOINT_PROFILES}  </profiles>
</dds>
"""


LOOPBACK_PROFILE = loopback_profile()
"""Fast DDS's default transports (shared memory, UDPv4) with UDP on the loopback interface,
a participant lease of `PARTICIPANT_LEASE_S`, and `ENDPOINT_PROFILES`."""
_HOSTNAME = re.compile(r"^(?=.{1,253}$)[A-Za-z0-9]([A-Za-z0-9-]*[A-Za-z0-9])?"
                       r"(\.[A-Za-z0-9]([A-Za-z0-9-]*[A-Za-z0-9])?)*$")


class DiscoveryRange(StrEnum):
    """Values of ``ROS_AUTOMATIC_DISCOVERY_RANGE`` a graph runs with."""

    LOCALHOST = "LOCALHOST"
    """Announce to participants of this host only (no multicast): the default."""
    SUBNET = "SUBNET"
    """Announce by multicast on the host's networks: nodes on other hosts of the subnet."""
    OFF = "OFF"
    """Announce to no other participant: a process on its own (one that must not take part
    in a graph's discovery, e.g. one started only to check its parameters)."""


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

    def bind(self, env: MutableMapping[str, str], directory: Path) -> None:
        """Make the processes of `env` listen on loopback only, unless they reach other hosts.

        Writes `LOOPBACK_PROFILE` to `directory` and names it in `env` (`PROFILE_VAR`), with
        `QOS_FROM_XML_VAR` set to ``1`` (its history memory applies: module docstring); a
        profiles file the user named there already is kept (theirs decides, and so does
        their `QOS_FROM_XML_VAR`). Reaching other hosts, any loopback profile of an earlier
        graph is taken out of `env`, with the `QOS_FROM_XML_VAR` it came with.
        """
        current = env.get(PROFILE_VAR, "")
        ours = Path(current).name == PROFILE_NAME
        if self.reaches_other_hosts:
            if ours:
                del env[PROFILE_VAR]
                env.pop(QOS_FROM_XML_VAR, None)
            return
        if current and not ours:
            return
        path = Path(directory) / PROFILE_NAME
        path.write_text(LOOPBACK_PROFILE)
        env[PROFILE_VAR] = str(path)
        env[QOS_FROM_XML_VAR] = "1"

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

"""A run's identity: its ROS namespace, and which publishers of a topic belong to it.

A run (one ``ssa-fusion live`` or ``replay``) starts every node it runs in a ROS namespace of
its own, ``/ssa_run_<id>`` (`run_namespace`, the id from `new_run_id`). Topics stay
absolute (``/ssa/measurement``, ``/clock``): bags, ``ros2 topic`` and Foxglove see the usual
names, and no message type changes. Every message DDS delivers carries its writer's GID
(rclpy's ``MessageInfo['publisher_gid']``), and the ROS graph names the node and namespace of
each writer: a node takes a message only from a writer of its own namespace
(`RunMembers.judge`), and `RunGate` holds, in order, what comes from a writer the graph has
not named yet (discovery names a writer's node a moment after it matches), for at most
`UNNAMED_WAIT_S`. `/clock` is one of those topics: a stranger's clock is refused like its
measurements. A node in the root namespace (``ros2 run`` without ``__ns``) has no run: it
takes every writer's traffic, as any ROS node does.

The id starts with the UTC time the run started (`new_run_id`), so the ids of two runs sort
by their start (`older`): two ``live`` commands that meet in one ROS domain agree which was
first. Nothing here is security: a participant can name itself into any namespace
(docs/SECURITY.md).
"""

from __future__ import annotations

import enum
import re
import secrets
import time
from collections import deque
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from rclpy.node import Node

RUN_PREFIX = "ssa_run_"
"""The namespace token of a run: ``/ssa_run_<id>``."""
ROOT = "/"
"""The root namespace: a node without a run."""
UNNAMED_WAIT_S = 5.0
"""Wall s a message of a writer the ROS graph has not named is held before it is refused."""
_UNKNOWN = "_NODE_NAMESPACE_UNKNOWN_"
"""What the graph says of a writer whose node it has not heard of yet (rmw)."""
_RUN_ID = re.compile(r"^[0-9]{8}_[0-9]{6}_[0-9]{3}_[0-9a-f]{4}$")


def new_run_id(now: float | None = None) -> str:
    """Return a new run id: its UTC start time to the millisecond and 16 random bits.

    E.g. ``20251207_040102_123_a3f2``; ids sort by start time (`older`).
    """
    t = time.time() if now is None else now
    ms = int(t * 1000.0) % 1000
    return f"{time.strftime('%Y%m%d_%H%M%S', time.gmtime(t))}_{ms:03d}_{secrets.token_hex(2)}"


def run_namespace(run_id: str) -> str:
    """Return the ROS namespace of run `run_id` (``/ssa_run_<id>``)."""
    if not _RUN_ID.match(run_id):
        raise ValueError(f"{run_id!r} is not a run id (YYYYMMDD_HHMMSS_mmm_xxxx)")
    return f"/{RUN_PREFIX}{run_id}"


def run_of(namespace: str) -> str | None:
    """Return the run id of a run's namespace, or None for any other namespace."""
    token = namespace.strip("/")
    if "/" in token or not token.startswith(RUN_PREFIX):
        return None
    rid = token[len(RUN_PREFIX):]
    return rid if _RUN_ID.match(rid) else None


def older(a: str, b: str) -> bool:
    """Return True when run `a` started before run `b` (ties: by the random part)."""
    return a < b


class Member(enum.Enum):
    """Whose a writer is, for a node of a run."""

    OWN = "own"
    FOREIGN = "foreign"
    UNKNOWN = "unknown"
    """The graph has not named the writer's node yet."""


def publisher_gid(info: object) -> bytes | None:
    """Return the writer GID of rclpy's MessageInfo `info` (None where the rmw gives none)."""
    gid = info.get("publisher_gid") if isinstance(info, dict) else None
    data = gid.get("data") if isinstance(gid, dict) else None
    return bytes(data) if data else None


class RunMembers:
    """Which writers of a topic are of `node`'s run (its namespace), cached by GID."""

    def __init__(self, node: Node) -> None:
        self.node = node
        self.namespace = node.get_namespace() or ROOT
        self._known: dict[bytes, bool] = {}

    @property
    def has_run(self) -> bool:
        """Return True when the node is in a namespace (a node in the root takes all)."""
        return self.namespace != ROOT

    def judge(self, topic: str, gid: bytes | None) -> Member:
        """Return whose the writer `gid` of `topic` is (OWN for a node without a run)."""
        if not self.has_run or gid is None:
            return Member.OWN
        own = self._known.get(gid)
        if own is None:
            self._learn(topic)
            own = self._known.get(gid)
        if own is None:
            return Member.UNKNOWN
        return Member.OWN if own else Member.FOREIGN

    def namespace_of(self, topic: str, gid: bytes) -> str:
        """Return the namespace the graph gives writer `gid` of `topic` ('' if none)."""
        for info in self.node.get_publishers_info_by_topic(topic):
            if bytes(info.endpoint_gid) == gid:
                return str(info.node_namespace)
        return ""

    def _learn(self, topic: str) -> None:
        """Note every writer of `topic` the graph names, by GID."""
        for info in self.node.get_publishers_info_by_topic(topic):
            ns = str(info.node_namespace)
            if ns and ns != _UNKNOWN:
                self._known[bytes(info.endpoint_gid)] = ns == self.namespace


Foreign = Callable[[str], None]
"""Told why a message was refused (one line naming its writer's namespace)."""


class RunGate:
    """Hand a subscription's messages of the run to `take`, in order; refuse the others.

    A message of a writer the graph names in another namespace goes to `foreign` (a reason);
    one of a writer not named yet waits, and every later message with it, until the graph
    names it or `wait_s` wall s passed (then it is foreign: a writer that never says whose
    it is). `release` hands on what may go; call it now and then (a node's wall timer).
    """

    def __init__(self, members: RunMembers, topic: str, take: Callable[[Any], None],
                 foreign: Foreign, wait_s: float = UNNAMED_WAIT_S) -> None:
        self.members = members
        self.topic = topic
        self.take = take
        self.foreign = foreign
        self.wait_s = wait_s
        self.held: deque[tuple[object, bytes | None, float]] = deque()

    def __call__(self, msg: object, info: object) -> None:
        """Take, refuse or hold one message (`info`: its rclpy MessageInfo)."""
        gid = publisher_gid(info)
        if self.held:
            self.held.append((msg, gid, time.monotonic()))
            self.release()
            return
        self._judge(msg, gid, time.monotonic())

    def _judge(self, msg: object, gid: bytes | None, since: float) -> bool:
        """Handle one message; False when it must wait (the caller holds it)."""
        verdict = self.members.judge(self.topic, gid)
        if verdict is Member.OWN:
            self.take(msg)
        elif verdict is Member.FOREIGN:
            assert gid is not None
            ns = self.members.namespace_of(self.topic, gid) or "?"
            self.foreign(f"{self.topic} from a publisher in namespace {ns}, not this run's "
                         f"{self.members.namespace}")
        elif time.monotonic() - since >= self.wait_s:
            self.foreign(f"{self.topic} from a publisher the ROS graph has not named in "
                         f"{self.wait_s:g} s (gid {gid.hex() if gid else '?'})")
        else:
            if not self.held or self.held[0][0] is not msg:
                self.held.append((msg, gid, since))
            return False
        return True

    def release(self) -> None:
        """Hand on the held messages that may go now, oldest first."""
        while self.held:
            msg, gid, since = self.held[0]
            if not self._judge(msg, gid, since):
                return
            self.held.popleft()

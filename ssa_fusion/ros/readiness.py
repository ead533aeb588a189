"""Waiting until subscribers are really ready to receive.

A DDS match has two sides, made in two processes at their own pace: the writer's (its
matched-subscription count) and the reader's (its matched-publisher count). What a writer
sends before both exist is lost to a volatile reader. ssa_fusion nodes report each input
subscription's matched-publisher count and each output publisher's matched-subscription
count on /diagnostics (`nodes.kit.diagnostics.Diagnostics.subscribe` and `.advertise`);
`ReadyNodes` reads those reports so that a sender (the sensor simulator, replay's player)
starts only when each named node has matched a publisher on each named topic
('node:/topic'), or as many publishers as it names ('node:/topic=count': a recorder that
must hear every shard from its first message), and each named node's output has matched as
many readers as it names ('node:>/topic=count': a shard's estimates reach the recorder from
its first batch).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING

from ssa_fusion.ros.topics import (
    TOPIC_CLOCK,
    TOPIC_DIAGNOSTICS,
    TOPIC_ESTIMATE,
    TOPIC_FORECAST,
    TOPIC_MEASUREMENT,
    TOPIC_TRUTH,
    TOPIC_WITHHELD,
)

if TYPE_CHECKING:  # rclpy when a node reads the reports: graphs.py imports this module's names
    from rclpy.node import Node

    from ssa_fusion.ros.interfaces import Message

MATCHED_KEY = "matched_publishers "
"""Diagnostics key prefix; the rest of the key is the subscribed topic."""
MATCHED_READERS_KEY = "matched_subscribers "
"""Diagnostics key prefix; the rest of the key is the published topic."""
OUTPUT = ">"
"""Marks a need on a node's output: 'node:>/topic' (its publisher's matched readers)."""

READERS = [f"{node}:{topic}" for node, topics in (
    ("surrogate", (TOPIC_MEASUREMENT,)),
    ("filter", (TOPIC_MEASUREMENT, TOPIC_FORECAST)),
    ("recorder", (TOPIC_MEASUREMENT, TOPIC_TRUTH, TOPIC_WITHHELD, TOPIC_FORECAST,
                  TOPIC_ESTIMATE, TOPIC_CLOCK)),
) for topic in topics] + [
    f"filter:{OUTPUT}{TOPIC_ESTIMATE}",  # the recorder
    f"surrogate:{OUTPUT}{TOPIC_FORECAST}=2",  # the filter and the recorder
]
"""What the ssa_fusion graph's nodes must have matched (their side) before measurements flow."""
LOCKSTEP_READERS = ["surrogate:/lockstep/forecasts", "filter:/lockstep/decisions"]
"""In lockstep, also: the releases (`nodes.kit.progress`) reach the surrogate and the filter."""


def readers_of(topics: set[str] | tuple[str, ...]) -> list[str]:
    """Return the `READERS` entries whose topic is in `topics`.

    Those with a publisher in a graph that lacks some topics (e.g. a bag without
    /ssa/withheld).
    """
    return [r for r in READERS if split_need(r)[1].removeprefix(OUTPUT) in topics]


class ReadyNodes:
    """The latest matched-publisher counts each node reported on /diagnostics.

    By node name and topic (`reports`). `subscribe` (``subscribe(type, topic, callback,
    qos)``), when given, subscribes in its place: of the run only (an ssa_fusion node's, a
    run graph's: other runs' nodes of the same names report too, in a shared domain).
    """

    def __init__(self, node: Node, subscribe: Callable[..., object] | None = None) -> None:
        self.reports: dict[str, dict[str, int]] = {}
        from rclpy.qos import QoSProfile

        from ssa_fusion.ros.interfaces import DiagnosticArray

        diag = getattr(node, "diag", None)
        subscribe = subscribe or (diag.subscribe if diag is not None
                                  else node.create_subscription)
        self._sub = subscribe(DiagnosticArray, TOPIC_DIAGNOSTICS, self._on,
                              QoSProfile(depth=100))

    def _on(self, msg: Message) -> None:
        """Take one /diagnostics report."""
        for st in msg.status:
            counts = {kv.key[len(MATCHED_KEY):]: int(kv.value)
                      for kv in st.values if kv.key.startswith(MATCHED_KEY)}
            counts.update({OUTPUT + kv.key[len(MATCHED_READERS_KEY):]: int(kv.value)
                           for kv in st.values if kv.key.startswith(MATCHED_READERS_KEY)})
            if counts:
                self.reports[st.name] = counts

    def unmatched(self, needs: list[str]) -> list[str]:
        """Return the entries of `needs` ('node:[>]/topic[=count]') not matched yet.

        Those whose node has not reported `count` (default 1) matched publishers on that
        input topic ('node:/topic'), or matched subscribers on that output topic
        ('node:>/topic'), yet.
        """
        missing = []
        for need in needs:
            name, topic, count = split_need(need)
            if self.reports.get(name, {}).get(topic, 0) < count:
                missing.append(need)
        return missing

    def ready(self, needs: list[str]) -> bool:
        """Return True once every entry of `needs` ('node:/topic') is matched."""
        return not self.unmatched(needs)


def split_need(need: str) -> tuple[str, str, int]:
    """Return the node, topic and count (default 1) of 'node:[>]/topic[=count]'.

    The topic keeps its `OUTPUT` mark ('>/topic'). A malformed count reads as 1
    (`params.checks.check_needs` says why it is malformed).
    """
    name, _, rest = need.partition(":")
    topic, _, count = rest.partition("=")
    return name, topic, int(count) if count.isdigit() else 1

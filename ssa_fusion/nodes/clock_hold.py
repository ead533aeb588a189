"""Messages that arrive before a node's sim-time clock has started wait until it has."""

from __future__ import annotations

import math
import time
from collections import deque
from collections.abc import Callable

from rclpy.node import Node

from ssa_fusion.core.types import Cause
from ssa_fusion.nodes.diagnostics import Diagnostics
from ssa_fusion.ros.topics import DATA_DEPTH


class ClockHold:
    """Hold what arrives before the node's clock has started; hand it back once it has.

    Under sim time the clock reads 0 until the first /clock: a stamp cannot be judged
    against it (`validation.ahead_of_clock`), and one stamped a year ahead would go in first
    and make every later measurement stale. So the handling of each such message (a
    callable that handles it again) is kept, in arrival order (counted as
    `held_until_clock`), and handed back by `release` once the clock runs. A graph with no
    /clock at all (sim time never starts) is not stalled: after `wait_s` wall s without one,
    the held messages are released and later ones pass unheld, unjudged as before. Beyond
    `limit` the oldest is dropped (`dropped_before_clock`). With wall time the clock always
    runs.
    """

    def __init__(self, node: Node, diag: Diagnostics, limit: int = DATA_DEPTH,
                 wait_s: float = 3.0) -> None:
        self.node = node
        self.diag = diag
        self.limit = limit
        self.wait_s = wait_s
        self.held: deque[Callable[[], None]] = deque()
        self.since = math.inf  # monotonic time the first message was held
        self.clockless = False  # gave up waiting: this graph has no /clock

    def _running(self) -> bool:
        return self.node.get_clock().now().nanoseconds > 0

    def hold(self, again: Callable[[], None]) -> bool:
        """Keep `again` and return True when a message must wait for the clock; else False.

        It must wait while the clock has not started, or while messages held before it
        started have not been released yet (they go first).
        """
        if not self.held and (self.clockless or self._running()):
            return False
        if len(self.held) >= self.limit:
            self.held.popleft()
            self.diag.count(Cause.DROPPED_BEFORE_CLOCK,
                            f"more than {self.limit} messages before the first /clock")
        if not self.held:
            self.since = time.monotonic()
        self.held.append(again)
        self.diag.count(Cause.HELD_UNTIL_CLOCK, "measurements arrive before the first /clock: "
                        "held until sim time starts")
        return True

    def release(self) -> list[Callable[[], None]]:
        """Return the held handlers, oldest first, once they may run (and forget them).

        They may once the clock runs, or once `wait_s` passed without it.
        """
        if not self.held:
            return []
        if not self._running():
            if time.monotonic() - self.since < self.wait_s:
                return []
            self.clockless = True
            self.node.get_logger().info(f"no /clock after {self.wait_s:g} s: measurements "
                                        "are taken without a clock to judge their stamps")
        items = list(self.held)
        self.held.clear()
        return items

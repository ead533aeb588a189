"""Messages that wait for a node's sim-time clock.

Those that arrive before it has started wait until it has; those stamped ahead of a running
clock wait (a few wall seconds) for it to catch up.
"""

from __future__ import annotations

import math
import time
from collections import deque
from collections.abc import Callable

from rclpy.node import Node

from ssa_fusion.core.base.types import Cause
from ssa_fusion.nodes.kit.diagnostics import Diagnostics
from ssa_fusion.ros.topics import DATA_DEPTH

_Ahead = tuple[float, float, float, Callable[[], None]]
"""A message held ahead of the clock: stamp (s), its lead (s), monotonic time held, handler."""


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

    Once the clock runs, a message stamped more than the node's ``max_clock_lead`` ahead of
    it (`ahead`) waits up to `ahead_wait_s` wall s for the clock to catch up (counted as
    `held_ahead_of_clock`): after a stall (a paused simulator or node, a loaded machine) the
    measurements of a burst can reach a node before the /clock messages that cover them, and
    they are valid. One the clock does not reach in that time (a sensor stamping wall time
    into a sim-time graph) is handed back all the same, to be refused by the lead check.
    Messages not ahead are not held behind them: their stamps are earlier anyway.
    """

    def __init__(self, node: Node, diag: Diagnostics, limit: int = DATA_DEPTH,
                 wait_s: float = 3.0, ahead_wait_s: float = 3.0) -> None:
        self.node = node
        self.diag = diag
        self.limit = limit
        self.wait_s = wait_s
        self.ahead_wait_s = ahead_wait_s
        self.held: deque[Callable[[], None]] = deque()
        self.since = math.inf  # monotonic time the first message was held
        self.clockless = False  # gave up waiting: this graph has no /clock
        self.ahead: deque[_Ahead] = deque()
        self.passing = False  # handing back: nothing is held again

    @property
    def holding(self) -> bool:
        """Return True while messages wait here (for the first clock, or ahead of it)."""
        return bool(self.held or self.ahead)

    def hold_ahead(self, again: Callable[[], None], t: float, lead_s: float) -> bool:
        """Keep `again` and return True when stamp `t` (s) is too far ahead of the clock.

        Too far: more than `lead_s` ahead of the running clock. Else (and always while
        handing back, or without a clock) return False.
        """
        now = self._now_s()
        if self.passing or now <= 0.0 or not t > now + lead_s:
            return False
        if len(self.ahead) >= self.limit:  # the oldest is judged now (refused if still ahead)
            oldest = self.ahead.popleft()[3]
            self.passing = True
            try:
                oldest()
            finally:
                self.passing = False
        self.ahead.append((t, lead_s, time.monotonic(), again))
        self.diag.count(Cause.HELD_AHEAD_OF_CLOCK,
                        f"t={t} is more than {lead_s:g} s ahead of the clock ({now}): held up "
                        f"to {self.ahead_wait_s:g} wall s for the clock to catch up")
        return True

    def _now_s(self) -> float:
        """Return the node's clock, s (0 before the first /clock under sim time)."""
        return self.node.get_clock().now().nanoseconds * 1e-9

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

        Those held before the clock: once it runs, or once `wait_s` passed without it. Those
        ahead of it: once the clock is within their lead, or `ahead_wait_s` passed. Call
        them with `passing` set (`SsaNode.replay_held`).
        """
        return self._release_early() + self._release_ahead()

    def _release_ahead(self) -> list[Callable[[], None]]:
        if not self.ahead:
            return []
        now = self._now_s()
        wall = time.monotonic()
        out: list[Callable[[], None]] = []
        keep: deque[_Ahead] = deque()
        for item in self.ahead:
            t, lead, since, again = item
            if t <= now + lead or wall - since >= self.ahead_wait_s:
                out.append(again)
            else:
                keep.append(item)
        self.ahead = keep
        return out

    def _release_early(self) -> list[Callable[[], None]]:
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

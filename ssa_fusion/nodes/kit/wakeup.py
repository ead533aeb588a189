"""Periodic work that runs only while there is some: `Wakeup`.

A node's periodic work (fusing what arrived, stepping its fits, reporting its lockstep
progress) runs on a wall timer while it has work. Its callback says whether it did any; after
`IDLE_RUNS` runs in a row without, the timer is cancelled, and the events that bring work
arm it again (`SsaNode.wakeup`: every input message, every change of the node's clock, and
work done by another of the node's wakeups). An idle node then wakes up for nothing but
its once-a-second /diagnostics, instead of polling at 20-200 Hz.
"""

from __future__ import annotations

from collections.abc import Callable

from rclpy.node import Node

from ssa_fusion.nodes.kit.diagnostics import wall_timer

IDLE_RUNS = 3
"""Runs in a row without work after which a wakeup's timer is cancelled until armed."""


class Wakeup:
    """A wall timer of period `period_s` calling `work` while it returns True (module docstring).

    `work` returns whether it did something (None counts as nothing); `after` is called
    once it did (the node arms its other wakeups).
    """

    def __init__(self, node: Node, period_s: float, work: Callable[[], bool | None],
                 after: Callable[[], None] | None = None) -> None:
        self.work = work
        self.after = after
        self.idle = 0
        self.runs = 0
        """Calls of `work` so far (what the node paid for)."""
        self.timer = wall_timer(node, period_s, self._run)

    @property
    def armed(self) -> bool:
        """Return True while the timer runs."""
        return not self.timer.is_canceled()

    def arm(self) -> None:
        """Run the work within a period from now (again), if it is not running already."""
        self.idle = 0
        if self.timer.is_canceled():
            self.timer.reset()

    def _run(self) -> None:
        self.runs += 1
        if self.work():
            self.idle = 0
            if self.after is not None:
                self.after()
            return
        self.idle += 1
        if self.idle >= IDLE_RUNS:
            self.timer.cancel()

"""A node's sim time from its run's ``/clock`` only.

rclpy's time source (``use_sim_time``) takes every ``/clock`` in the ROS domain: a
stranger's (another run's simulator, a bag played by hand) would move the node's sim time,
and with it every stamp check, prediction and forecast. `RunClock` replaces that
subscription with one of the node's checked inputs (`Diagnostics.subscribe`): a ``/clock``
whose writer is not of the node's run is refused and counted (`foreign_clock`), one rclpy
cannot take (a negative time) is refused and counted (`rejected_clock`); the others set the
node's clock as rclpy's would. Its QoS is reliable (the run's simulator publishes so; a
best-effort writer does not match it), so that in lockstep no clock of a step is lost.
`listen` hands each clock taken to the node too (the recorder writes it into the bag).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING

from rclpy.serialization import deserialize_message
from rclpy.time import Time as RclTime

from ssa_fusion.core.base.types import Cause
from ssa_fusion.ros.interfaces import Clock
from ssa_fusion.ros.qos import reliable_stream
from ssa_fusion.ros.topics import TOPIC_CLOCK

if TYPE_CHECKING:
    from ssa_fusion.nodes.kit.base import SsaNode

CLOCK_QOS = reliable_stream(100)
"""The run's /clock: reliable (every step's clock arrives), a short queue."""

ClockListener = Callable[[bytes, int], None]
"""Told of each /clock taken: its CDR bytes and its time, ns."""


class RunClock:
    """The node's /clock subscription, of its run only (see the module docstring).

    Nothing is done for a node on wall time (``use_sim_time`` false).
    """

    def __init__(self, node: SsaNode) -> None:
        self.node = node
        self.listeners: list[ClockListener] = []
        source = node._time_source  # rclpy's: it keeps the clocks; its subscription goes
        self.active = source.ros_time_is_active
        if not self.active:
            return
        if source._clock_sub is not None:
            node.destroy_subscription(source._clock_sub)
        source._clock_sub = node.diag.subscribe(Clock, TOPIC_CLOCK, self._on_clock, CLOCK_QOS,
                                                raw=True)

    def listen(self, listener: ClockListener) -> None:
        """Hand every /clock taken from now on to `listener` too (after the clock is set)."""
        self.listeners.append(listener)

    def _on_clock(self, data: bytes) -> None:
        """Set the node's sim time from one of its run's /clock messages."""
        msg = deserialize_message(data, Clock)
        try:
            t = RclTime.from_msg(msg.clock)
        except ValueError as exc:  # rclpy cannot represent it (a negative time)
            self.node.diag.count(Cause.REJECTED_CLOCK,
                                 f"a /clock message rclpy cannot take ({exc}); ignored")
            return
        self.node._time_source.clock_callback(msg)
        for listener in self.listeners:
            listener(data, int(t.nanoseconds))

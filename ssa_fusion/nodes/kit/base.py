"""`SsaNode`: the base class of every ssa_fusion node.

It owns what every node does alike, so that a node only translates messages to and from
core types, holds its parameters and timers, and calls the core:

* its parameters, declared from the node's table (`PARAMETERS`, `params.rows`),
  checked at start-up and on every run-time set, their values in `params`;
* its ``/diagnostics`` (`diag`: counts by cause, logged once, matched inputs);
* input subscriptions whose callbacks cannot kill the node (`subscribe`), and wall timers
  (`wall_timer`);
* its shared-memory segments, private to the user (`ros.shm_privacy`);
* its run: only its run's messages reach its callbacks, its sim time follows only its run's
  ``/clock`` (`nodes.kit.run_clock`), and a stranger's are counted (`ros.run_identity`);
* the clock hold: measurements that come before the first /clock wait for it
  (`measurement_in`, `replay_held`), and a backwards jump of sim time resets what the node
  learnt (`reset_on_backward_jump`);
* the settings in effect, published latched on ``/ssa/config`` (`publish_settings`);
* its process: `main` runs it until SIGINT/SIGTERM or `finish`, exit 0, or 2 with a message
  for an invalid parameter (`nodes.kit.process`).

As rclpy's demos, a node subclasses it and sets its publishers, subscriptions and timers up
in ``__init__``::

    class Echo(SsaNode):
        PARAMETERS = ParameterTable("echo", (Param("period", 1.0, "wall s", "s", POSITIVE),))

        def __init__(self) -> None:
            super().__init__()
            self.wall_timer(self.params.number("period"), self.tick)
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Callable
from typing import ClassVar

from rclpy.clock import JumpThreshold, TimeJump
from rclpy.duration import Duration
from rclpy.node import Node
from rclpy.publisher import Publisher
from rclpy.qos import QoSProfile
from rclpy.subscription import Subscription
from rclpy.subscription_content_filter_options import ContentFilterOptions
from rclpy.timer import Timer

from ssa_fusion.core.base.types import Cause, Measurement
from ssa_fusion.core.measure.validation import ahead_of_clock
from ssa_fusion.nodes import start_process
from ssa_fusion.nodes.kit.clock_hold import ClockHold
from ssa_fusion.nodes.kit.diagnostics import Diagnostics, wall_timer
from ssa_fusion.nodes.kit.node_parameters import NodeParameters
from ssa_fusion.nodes.kit.process import constructing, run, start_watchdog
from ssa_fusion.nodes.kit.run_clock import RunClock
from ssa_fusion.nodes.kit.wakeup import Wakeup
from ssa_fusion.params.checks import ParamValue
from ssa_fusion.params.rows import ParameterTable
from ssa_fusion.ros import messages, shm_privacy
from ssa_fusion.ros.interfaces import Message, String, Time
from ssa_fusion.ros.qos import CONFIG_QOS
from ssa_fusion.ros.topics import TOPIC_CONFIG, TOPIC_MEASUREMENT


class SsaNode(Node):
    """An rclpy node with the parameters, diagnostics, clock hold and process of them all.

    Attributes
    ----------
    PARAMETERS : ParameterTable
        The node's name and parameters (class attribute, one per node class; ``-r
        __node:=...`` renames a node, as any rclpy node).
    params : NodeParameters
        Their values in effect.
    diag : Diagnostics
        Its /diagnostics counters and status.
    """

    PARAMETERS: ClassVar[ParameterTable]

    def __init__(self) -> None:
        with start_watchdog():  # DDS can deadlock here: exit rather than hang (process.py)
            super().__init__(self.PARAMETERS.node)
            constructing(self)  # destroyed in order by `run` if a parameter is refused below
            self.params = NodeParameters(self, self.PARAMETERS, self.on_parameters_set)
            self.params.reject_unknown()
            self.diag = Diagnostics(self, stamp=self.diagnostics_stamp)
            self.run_clock = RunClock(self)
        self.private_segments()
        self.wall_timer(shm_privacy.PERIOD_S, self.private_segments)
        self.clock_hold = ClockHold(self, self.diag)
        self.handled: Counter[str] = Counter()
        """Measurement messages handled for good (used or refused, not held), by topic."""
        self._jump_handles: list[object] = []
        self._settings_pub: Publisher[String] | None = None
        self._wakeups: list[Wakeup] = []

    def private_segments(self) -> None:
        """Make the shared-memory segments of this process the user's only (`ros.shm_privacy`)."""
        shm_privacy.make_private()

    # parameters ------------------------------------------------------------------------
    def on_parameters_set(self, changed: dict[str, ParamValue]) -> None:
        """Put run-time parameters that changed into effect (their values are in `params`).

        Called once per accepted ``ros2 param set`` of parameters marked run time. A node
        whose run-time parameters are read where they are used needs nothing here.
        """

    # time --------------------------------------------------------------------------------
    def diagnostics_stamp(self) -> Time:
        """Return the time of a /diagnostics report: the node's clock (sim time or 0)."""
        return self.get_clock().now().to_msg()

    def now_s(self) -> float:
        """Return the node's clock in s (sim time under use_sim_time; 0 before /clock)."""
        return self.get_clock().now().nanoseconds * 1e-9

    def wall_timer(self, period_s: float, callback: Callable[[], None]) -> Timer:
        """Create a guarded timer on the steady (wall) clock (sim time may stand still)."""
        return wall_timer(self, period_s, self.diag.guard(callback))

    def wakeup(self, period_s: float, work: Callable[[], bool | None]) -> Wakeup:
        """Run `work` every `period_s` wall s while it has work (`nodes.kit.wakeup`).

        `work` returns whether it did something (an exception is counted, as `wall_timer`'s,
        and counts as nothing); it runs on while messages wait for the clock (`clock_hold`:
        they are handed back, or refused, after a wall-time wait). Once idle, it runs again
        after an input message, a change of the node's clock, or work done by another of the
        node's wakeups.
        """
        if not self._wakeups:
            self.diag.on_input.append(self.arm_wakeups)
            self._jump_handles.append(self.get_clock().create_jump_callback(
                JumpThreshold(min_forward=Duration(nanoseconds=1),
                              min_backward=Duration(nanoseconds=-1), on_clock_change=True),
                post_callback=lambda _jump: self.arm_wakeups()))
        guarded = self.diag.guard(work)
        w = Wakeup(self, period_s, lambda: bool(guarded()) or self.clock_hold.holding,
                   after=self.arm_wakeups)
        self._wakeups.append(w)
        return w

    def arm_wakeups(self) -> None:
        """Arm every wakeup of the node (`wakeup`): something happened that may give work."""
        for w in self._wakeups:
            w.arm()

    def reset_on_backward_jump(self, reset: Callable[[], None], what: str) -> None:
        """Call `reset` when sim time jumps backwards (a bag loops), and count it.

        `what` says what was forgotten (``reset_clock_jump`` on /diagnostics).
        """
        def on_jump(_jump: TimeJump) -> None:
            reset()
            self.diag.count(Cause.RESET_CLOCK_JUMP, f"sim time jumped backwards: {what}")

        self._jump_handles.append(self.get_clock().create_jump_callback(
            JumpThreshold(min_forward=None, min_backward=Duration(nanoseconds=-1),
                          on_clock_change=False),
            post_callback=on_jump))

    # input -------------------------------------------------------------------------------
    def subscribe(self, msg_type: type[Message], topic: str,
                  callback: Callable[[Message], None], qos: QoSProfile, raw: bool = False,
                  content_filter: ContentFilterOptions | None = None) -> Subscription[Message]:
        """Subscribe to an input: see `Diagnostics.subscribe`."""
        return self.diag.subscribe(msg_type, topic, callback, qos, raw, content_filter)

    def advertise(self, msg_type: type[Message], topic: str,
                  qos: QoSProfile) -> Publisher[Message]:
        """Create an output publisher, its matches reported: see `Diagnostics.advertise`."""
        return self.diag.advertise(msg_type, topic, qos)

    def measurement_in(self, msg: Message, again: Callable[[], None],
                       object_id: str, topic: str = TOPIC_MEASUREMENT) -> Measurement | None:
        """Return the core measurement of Measurement message `msg` of `topic`, or None.

        None when it must wait for the first /clock (`again` handles it once the clock
        runs: `replay_held`), or when it is refused (counted by cause): of another object
        than `object_id` (unless ''), of no kind the core knows, or stamped more than
        ``max_clock_lead`` ahead of the clock. Unless held, it counts as `handled`.
        """
        if self.clock_hold.hold(again):
            return None
        m = None
        if object_id and msg.object_id != object_id:
            self.diag.count(Cause.IGNORED_OTHER_OBJECT, f"object_id {msg.object_id!r}")
        else:
            m = self.measurement_of(msg)
            if m is not None and self.clock_hold.hold_ahead(again, m.t, self.max_clock_lead()):
                return None
        self.handled[topic] += 1
        return None if m is None or self.ahead_of_clock(m.t) else m

    def max_clock_lead(self) -> float:
        """Return ``max_clock_lead``: how far (s) a stamp may be ahead of the clock."""
        return self.params.number("max_clock_lead")

    def measurement_of(self, msg: Message) -> Measurement | None:
        """Return the core measurement of `msg`, or None (counted) for a kind it lacks."""
        try:
            return messages.measurement_from_msg(msg)
        except ValueError as exc:
            self.diag.count(Cause.REJECTED_KIND, str(exc))
            return None

    def ahead_of_clock(self, t: float) -> bool:
        """Return True, counted, when epoch `t` is beyond ``max_clock_lead`` of the clock."""
        cause, reason = ahead_of_clock(t, self.now_s(), self.max_clock_lead())
        if cause:
            self.diag.count(cause, reason)
        return bool(cause)

    def replay_held(self) -> None:
        """Handle the messages held for the clock, once they may go (in order)."""
        released = self.clock_hold.release()
        if not released:
            return
        self.clock_hold.passing = True
        try:
            for again in released:
                again()
        finally:
            self.clock_hold.passing = False

    # output ------------------------------------------------------------------------------
    def publish_settings(self, text: str) -> None:
        """Publish the settings in effect on /ssa/config, latched (every bag records them).

        `text` is `params.settings.config_message`'s; the publisher is created at the first.
        """
        if self._settings_pub is None:
            self._settings_pub = self.create_publisher(String, TOPIC_CONFIG, CONFIG_QOS)
        self._settings_pub.publish(String(data=text))

    # process -----------------------------------------------------------------------------
    def close(self) -> None:
        """Release what the node holds outside rclpy (a bag, a server) before it ends."""

    @classmethod
    def main(cls, args: list[str] | None = None) -> int:
        """Run this node in this process until it is stopped; return the exit code."""
        start_process()
        return run(cls, args)

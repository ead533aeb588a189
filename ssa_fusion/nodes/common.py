"""Pieces every ssa_fusion node shares: running with clean shutdown, diagnostics counters,
validated parameters."""

from __future__ import annotations

import inspect
import math
import signal
import sys
import time
import traceback
from collections import Counter, deque
from collections.abc import Callable
from typing import Any

import rclpy
from builtin_interfaces.msg import Time as TimeMsg
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from rcl_interfaces.msg import ParameterDescriptor, SetParametersResult
from rclpy._rclpy_pybind11 import RCLError
from rclpy.clock import Clock, ClockType
from rclpy.event_handler import SubscriptionEventCallbacks
from rclpy.exceptions import ParameterException
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import QoSProfile
from rclpy.serialization import deserialize_message
from rclpy.signals import SignalHandlerOptions

from ssa_fusion.core.frames import Frame
from ssa_fusion.core.stations import network_stations
from ssa_fusion.core.types import KIND_NAMES, Cause, Kind
from ssa_fusion.nodes import STOP
from ssa_fusion.ros.executors import make_executor
from ssa_fusion.ros.readiness import MATCHED_KEY
from ssa_fusion.ros.topics import DATA_DEPTH, TOPIC_DIAGNOSTICS


class ParameterError(ValueError):
    """A parameter value is invalid; the message names the parameter and the rule."""


class Diagnostics:
    """Counts events by cause, logs each cause once, publishes them on /diagnostics.

    Each report is published every `period_s` wall seconds (sim time may stand still) and
    stamped in the graph's time base: `stamp()` when given, else the node's clock (sim time
    under use_sim_time, 0 before the first /clock). The node that drives sim time
    (sensor_sim) gives the sim time it last published.
    """

    def __init__(self, node: Node, period_s: float = 1.0,
                 stamp: Callable[[], TimeMsg] | None = None) -> None:
        self.node = node
        self._stamp = stamp or (lambda: node.get_clock().now().to_msg())
        self.counts: Counter[str] = Counter()
        self.status: dict[str, str] = {}
        self._logged: set[str] = set()
        self._watched: list[Any] = []
        self._pub = node.create_publisher(DiagnosticArray, TOPIC_DIAGNOSTICS, QoSProfile(depth=10))
        wall_timer(node, period_s, self.publish)  # sim time may stand still (no /clock)

    def count(self, cause: str, detail: str = "", warn: bool = True) -> None:
        """Count one `cause`; the first occurrence of each cause is logged (with detail)."""
        self.counts[cause] += 1
        if cause not in self._logged:
            self._logged.add(cause)
            text = f"{cause}: {detail} (logged once; counted on {TOPIC_DIAGNOSTICS})"
            if warn:
                self.node.get_logger().warning(text)
            else:
                self.node.get_logger().info(text)

    def subscribe(self, msg_type: Any, topic: str, callback: Callable[[Any], None],
                  qos: QoSProfile, raw: bool = False, content_filter: Any = None) -> Any:
        """`create_subscription` whose matched-publisher count is reported on /diagnostics
        (key `MATCHED_KEY + topic`), at once when it changes. A sender can then wait until this
        reader has matched it, not only until its writer has matched the reader: DDS drops
        what a writer sends before the reader's side of the match exists. `content_filter`
        (rclpy `ContentFilterOptions`): DDS delivers only the samples it accepts."""
        if not raw:  # take the bytes and decode them here: a payload that does not decode
            callback = self._decoding(msg_type, topic, callback)  # is counted, not lost
        sub = self.node.create_subscription(
            msg_type, topic, callback, qos, raw=True,
            event_callbacks=SubscriptionEventCallbacks(matched=lambda _info: self.publish()),
            content_filter_options=content_filter,
        )
        self._watched.append(sub)
        return sub

    def _decoding(self, msg_type: Any, topic: str,
                  callback: Callable[[Any], None]) -> Callable[[bytes], None]:
        """Wrap `callback` to take serialized bytes: decoded as `msg_type`, or counted as
        `rejected_malformed` (logged once) when they do not decode."""
        name = f"{msg_type.__module__.split('.')[0]}/{msg_type.__name__}"

        def decode(data: bytes) -> None:
            try:
                msg = deserialize_message(data, msg_type)
            except Exception as exc:  # rclpy raises several types for bad CDR
                self.count(Cause.REJECTED_MALFORMED,
                           f"{len(data)} bytes on {topic} do not decode as {name}: {exc}")
                return
            callback(msg)

        return decode

    def guard(self, callback: Callable[..., None]) -> Callable[..., None]:
        """Wrap a subscription/timer callback: an unexpected exception is counted as
        'internal_error' (traceback logged once) instead of killing the node."""

        n_args = len(inspect.signature(callback).parameters)

        def guarded(*args: Any) -> None:  # executors may pass extra info (TimerInfo)
            try:
                callback(*args[:n_args])
            except Exception as exc:
                self.count(
                    Cause.INTERNAL_ERROR, f"{type(exc).__name__}: {exc}\n" + traceback.format_exc()
                )

        return guarded

    def publish(self) -> None:
        """Publish the counts, status and matched-publisher counts now."""
        msg = DiagnosticArray()
        msg.header.stamp = self._stamp()
        st = DiagnosticStatus()
        st.name = f"{self.node.get_name()}"
        st.hardware_id = "ssa_fusion"
        rejected = sum(v for k, v in self.counts.items() if k.startswith("rejected"))
        st.level = DiagnosticStatus.WARN if rejected else DiagnosticStatus.OK
        st.message = "; ".join(f"{k}={v}" for k, v in self.status.items()) or "ok"
        st.values = [KeyValue(key=k, value=str(v)) for k, v in sorted(self.counts.items())]
        st.values += [KeyValue(key=k, value=v) for k, v in sorted(self.status.items())]
        st.values += [KeyValue(key=MATCHED_KEY + sub.topic_name,
                               value=str(sub.get_publisher_count())) for sub in self._watched]
        msg.status = [st]
        self._pub.publish(msg)


class ClockHold:
    """Messages that arrive before the node's clock has started wait here until it has.

    Under sim time the clock reads 0 until the first /clock: a stamp cannot be judged
    against it (`validation.ahead_of_clock`), and one stamped a year ahead would go in first
    and make every later measurement stale. So they are kept, in arrival order (counted as
    `held_until_clock`), and handed back by `release` once the clock runs. A graph with no
    /clock at all (sim time never starts) is not stalled: after `wait_s` wall s without one,
    the held messages are released and later ones pass unheld, unjudged as before. Beyond
    `limit` the oldest is dropped (`dropped_before_clock`). With wall time the clock always
    runs.
    """

    def __init__(self, node: Node, limit: int = DATA_DEPTH, wait_s: float = 3.0) -> None:
        self.node = node
        self.limit = limit
        self.wait_s = wait_s
        self.held: deque[tuple[Any, ...]] = deque()
        self.since = math.inf  # monotonic time the first message was held
        self.clockless = False  # gave up waiting: this graph has no /clock

    def _running(self) -> bool:
        return bool(self.node.get_clock().now().nanoseconds > 0)

    def hold(self, *item: Any) -> bool:
        """Keep `item` and return True if the clock has not started, or if messages held
        before it started have not been released yet (they go first); else return False."""
        if not self.held and (self.clockless or self._running()):
            return False
        diag = self.node.diag
        if len(self.held) >= self.limit:
            self.held.popleft()
            diag.count(Cause.DROPPED_BEFORE_CLOCK,
                       f"more than {self.limit} messages before the first /clock")
        if not self.held:
            self.since = time.monotonic()
        self.held.append(item)
        diag.count(Cause.HELD_UNTIL_CLOCK, "measurements arrive before the first /clock: "
                   "held until sim time starts", warn=False)
        return True

    def release(self) -> list[tuple[Any, ...]]:
        """The held items, oldest first, once the clock runs or `wait_s` passed without it
        (and forget them)."""
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


def wall_timer(node: Node, period_s: float, callback: Callable[[], None]) -> Any:
    """A timer on the steady (wall) clock. Sim-time timers fire once per elapsed period and
    so, at a high time scale, back to back; checks that read sim time inside the callback
    run on this instead."""
    return node.create_timer(period_s, callback, clock=Clock(clock_type=ClockType.STEADY_TIME))


def declare(
    node: Node,
    name: str,
    default: Any,
    description: str,
    check: Callable[[Any], str | None] | None = None,
    apply: Callable[[Any], None] | None = None,
) -> Any:
    """Declare a parameter with a description; validate it now and on every later set.

    `check(value)` returns None when valid, else the reason. An invalid start-up value
    raises ParameterError; a later invalid `ros2 param set` is refused (old value kept).
    `apply(value)` puts a value accepted at run time into effect; a parameter without it is
    read-only at run time (set at start-up; rclpy refuses later sets as read-only).
    """
    descriptor = ParameterDescriptor(description=description, read_only=apply is None)
    try:
        node.declare_parameter(name, default, descriptor)
    except ParameterException as exc:  # e.g. a string given for a number
        raise ParameterError(f"parameter '{name}': {exc}") from exc
    value = node.get_parameter(name).value
    hooks = node.__dict__.setdefault("_ssa_param_hooks", {})
    if not hooks:
        node.add_on_set_parameters_callback(lambda ps: _validate(node, ps))
        node.add_post_set_parameters_callback(lambda ps: _apply(node, ps))
    hooks[name] = (check, apply)
    if check is not None:
        reason = check(value)
        if reason:
            raise ParameterError(f"parameter '{name}' = {value!r}: {reason}")
    return value


def cross_check(node: Node, names: tuple[str, ...],
                rule: Callable[[dict[str, Any]], str | None]) -> None:
    """Enforce a rule over several parameters of `node` (declared with `declare`) at start
    and on every later set.

    `rule(values)` gets the value of each of `names` and returns None when they go together,
    else the reason. It is checked now (an invalid start-up combination raises ParameterError
    naming ``names[0]``) and then on every run-time set of any of `names`, with the values
    the set would leave: its own over the current ones, so an atomic set of several is judged
    as a whole. A set that breaks the rule is refused with the reason (old values kept).
    """
    values = {name: node.get_parameter(name).value for name in names}
    reason = rule(values)
    if reason:
        raise ParameterError(f"parameter '{names[0]}' = {values[names[0]]!r}: {reason}")
    node.__dict__.setdefault("_ssa_cross_checks", []).append((names, rule))


def _validate(node: Node, params: list[Parameter]) -> SetParametersResult:
    hooks = node.__dict__.get("_ssa_param_hooks", {})
    for p in params:
        check = hooks.get(p.name, (None, None))[0]
        reason = check(p.value) if check else None
        if reason:
            node.get_logger().warning(f"refused parameter '{p.name}' = {p.value!r}: {reason}")
            return SetParametersResult(successful=False, reason=f"{p.name}: {reason}")
    new = {p.name: p.value for p in params}
    for names, rule in node.__dict__.get("_ssa_cross_checks", []):
        changed = [name for name in names if name in new]
        if not changed:
            continue
        reason = rule({name: new[name] if name in new else node.get_parameter(name).value
                       for name in names})
        if reason:
            text = ", ".join(f"'{name}' = {new[name]!r}" for name in changed)
            node.get_logger().warning(f"refused parameter {text}: {reason}")
            return SetParametersResult(successful=False,
                                       reason=f"{', '.join(changed)}: {reason}")
    return SetParametersResult(successful=True)


def _apply(node: Node, params: list[Parameter]) -> None:
    hooks = node.__dict__.get("_ssa_param_hooks", {})
    for p in params:
        apply = hooks.get(p.name, (None, None))[1]
        if apply is not None:
            apply(p.value)
            node.get_logger().info(f"parameter '{p.name}' = {p.value!r} in effect")


def _finite(value: Any) -> bool:
    return isinstance(value, int) or (isinstance(value, float) and math.isfinite(value))


def positive(value: Any) -> str | None:
    return None if _finite(value) and value > 0 else "must be a finite number > 0"


def non_negative(value: Any) -> str | None:
    return None if _finite(value) and value >= 0 else "must be a finite number >= 0"


def at_least(low: int) -> Callable[[Any], str | None]:
    """A parameter check: an integer >= `low`."""
    def check(v: Any) -> str | None:
        return None if isinstance(v, int) and v >= low else f"must be an integer >= {low}"
    return check


def all_non_negative(values: Any) -> bool:
    """Every element is a finite number >= 0 (``min(values) >= 0`` lets NaN through)."""
    return all(non_negative(v) is None for v in values)


KINDS = {name: kind for kind, name in KIND_NAMES.items()}
"""The `kind` parameter's values: measurement kind by name."""


def measurement_stream(node: Node, defaults: Any) -> tuple[int, str]:
    """Declare `kind` and `station` on `node` (defaults: `defaults.kind`, `defaults.station`):
    the measurement kind it takes and the frame_id those measurements come in (the station
    for range/az/el and ra/dec, "gcrf" for position)."""
    kind = declare(
        node, "kind", defaults.kind, "measurement kind: position | range_az_el | ra_dec",
        one_of(*KINDS)
    )
    station = declare(
        node,
        "station",
        defaults.station,
        "station id of range/az/el or ra/dec measurements (their frame_id), or a station "
        "network (a network id, or station ids separated by commas: the filter fuses them all)",
        _station_check,
    )
    return KINDS[kind], station if KINDS[kind] != Kind.POSITION else Frame.GCRF


def _station_check(value: str) -> str | None:
    try:
        network_stations(value)
    except ValueError as exc:
        return str(exc)
    return None


def clock_lead(node: Node, default: float) -> float:
    """Declare `max_clock_lead` (s) on `node`: a measurement stamped further ahead of the
    node's clock is refused as `rejected_future` (see `validation.ahead_of_clock`)."""

    def apply(value: Any) -> None:
        node.max_lead = float(value)

    return float(declare(node, "max_clock_lead", default,
                         "s a measurement's stamp may be ahead of this node's clock; further "
                         "is refused (a wall-time stamp in a sim-time graph)", positive,
                         apply=apply))


def one_of(*choices: str) -> Callable[[Any], str | None]:
    def check(value: Any) -> str | None:
        return None if value in choices else f"must be one of {', '.join(choices)}"

    return check


def run(make_node: Callable[[], Node], args: list[str] | None = None) -> int:
    """rclpy main loop of one node with the behaviour users rely on.

    SIGINT/SIGTERM (also twice, also during shutdown) end the loop; pending callbacks are
    drained for a moment (so a recorder writes what already reached it), the node's
    ``close()`` runs, and the process exits 0. An invalid parameter at start-up exits 2 with
    a message naming the parameter. A callback may call `finish()` to end with exit 0.
    """
    stop = STOP  # set by the handlers `start_process` installed (the node's main calls it)
    try:
        rclpy.init(args=args, signal_handler_options=SignalHandlerOptions.NO)
    except RCLError as exc:  # rcl could not parse the arguments: a -p rule, a params file
        print(f"error: cannot start: {_first_line(str(exc))} (check the --ros-args: "
              "-p name:=value rules need a value, lists one type; params files valid YAML)",
              file=sys.stderr)
        return 2
    node = None
    code = 0
    executor = make_executor()
    try:
        if stop.is_set():  # interrupted while starting: nothing to do
            return code
        node = make_node()
        reject_unknown_parameters(node)
        executor.add_node(node)
        while not stop.is_set():
            try:
                executor.spin_once(timeout_sec=0.1)
            except Exception as exc:  # raised outside the node's guarded callbacks
                escaped(node, exc)
        _drain(executor, node)
    except ParameterError as exc:
        print(f"error: {exc}", file=sys.stderr)
        code = 2
    finally:
        if node is not None:
            close = getattr(node, "close", None)
            if close is not None:
                close()
            node.destroy_node()
        executor.shutdown()
        rclpy.try_shutdown()
        # Python's finalization resets handlers it installed to SIG_DFL, so a late second
        # interrupt would kill the exiting process (-15/-2); ignored signals stay ignored.
        signal.signal(signal.SIGINT, signal.SIG_IGN)
        signal.signal(signal.SIGTERM, signal.SIG_IGN)
    return code


def _first_line(text: str) -> str:
    """The message of an rcl error without its source locations (", at file.c:N")."""
    return text.strip().splitlines()[0].split(", at /")[0] if text.strip() else "unknown error"


def reject_unknown_parameters(node: Node) -> None:
    """Raise ParameterError naming every parameter given to `node` (``-p``, a params file)
    that it does not declare, with the list of those it does: a misspelt name would
    otherwise be ignored silently (rclpy's default)."""
    declared = set(node._parameters)  # rclpy keeps no public list of either
    given = set(getattr(node, "_parameter_overrides", {}))
    unknown = sorted(p for p in given - declared if not p.startswith("qos_overrides."))
    if unknown:
        names = ", ".join(f"parameter '{p}'" for p in unknown)
        raise ParameterError(f"unknown {names}; {node.get_name()} takes: "
                             f"{', '.join(sorted(declared))}")


def escaped(node: Node, exc: Exception) -> None:
    """Count an exception that escaped the node's own (guarded) callbacks instead of dying
    of it: rclpy's handling of a /clock message it cannot take (a negative time) raises in
    the executor. Counted as `rejected_clock` when it came from rclpy's time source, else
    `internal_error`, on the node's /diagnostics (logged once)."""
    frames = traceback.extract_tb(exc.__traceback__)
    from_clock = any(f.filename.endswith(("time_source.py", "clock.py", "time.py"))
                     for f in frames)
    cause = Cause.REJECTED_CLOCK if from_clock else Cause.INTERNAL_ERROR
    detail = (f"a /clock message rclpy cannot take ({type(exc).__name__}: {exc}); ignored"
              if from_clock else f"{type(exc).__name__}: {exc}\n" + traceback.format_exc())
    diag = getattr(node, "diag", None)
    if diag is not None:
        diag.count(cause, detail)
    else:
        node.get_logger().error(f"{cause}: {detail}")


def _drain(
    executor: SingleThreadedExecutor, node: Node, quiet_s: float = 0.2, limit_s: float = 3.0
) -> None:
    """Run callbacks already pending until `node.activity` stays still for `quiet_s`."""
    if not hasattr(node, "activity"):
        return
    deadline = time.monotonic() + limit_s
    last, last_change = node.activity, time.monotonic()
    while time.monotonic() < deadline and time.monotonic() - last_change < quiet_s:
        try:
            executor.spin_once(timeout_sec=0.02)
        except Exception as exc:
            escaped(node, exc)
        if node.activity != last:
            last, last_change = node.activity, time.monotonic()


def finish() -> None:
    """End the node's loop from a callback (the node's job is done): `run` leaves its loop
    after this callback returns, closes the node and exits 0. (Not an exception: rclpy's
    executor logs an exception escaping a callback as FATAL with a traceback.)"""
    STOP.set()

"""A node's process: its rclpy main loop, clean shutdown and exit codes.

SIGINT/SIGTERM (also twice, also during shutdown) end the loop and the process exits 0; an
invalid parameter at start-up exits 2 with one line naming it (`ParameterError`).
"""

from __future__ import annotations

import contextlib
import faulthandler
import math
import os
import signal
import sys
import time
import traceback
from collections.abc import Callable, Iterator
from typing import TYPE_CHECKING

import rclpy
from rclpy.executors import Executor
from rclpy.impl.implementation_singleton import rclpy_implementation as _rclpy
from rclpy.node import Node
from rclpy.signals import SignalHandlerOptions

from ssa_fusion.core.base.types import Cause
from ssa_fusion.nodes import STOP
from ssa_fusion.params.rows import ParameterError
from ssa_fusion.ros.executors import make_executor

if TYPE_CHECKING:
    from ssa_fusion.nodes.kit.base import SsaNode

EXIT_OK = 0
"""The node ended: its job was done, or SIGINT/SIGTERM stopped it."""
EXIT_FAILED = 1
"""The node could not go on doing its job (a recorder whose disk is full; stderr says why)."""
EXIT_BAD_PARAMETERS = 2
"""The node could not start: a parameter or a ROS argument is invalid (stderr says which)."""

SLOW_STOP_S = 7.0
"""Wall s after a stop began when a node still stopping dumps its threads' stacks to stderr
(it drains for at most 3 s; a supervisor such as the test graphs' kills it at 10 s)."""

START_TIMEOUT_S = 120.0
"""Wall s the DDS part of a node's start (rclpy's context, the node's participant, its
parameter services and /diagnostics) may take before the process writes "Timeout" and every
thread's stack to stderr and exits 1 (`start_watchdog`). A participant made while others
leave can deadlock inside Fast DDS (eProsima/Fast-DDS#6502), and a process stuck there
ignores SIGINT and SIGTERM; exiting lets its supervisor (``ros2 launch``'s respawn,
``ssa-fusion live``) see it. That part takes about a second; a node's own work at start (the
simulator's schedule) is not counted. `START_TIMEOUT_ENV` sets it (0: none)."""

START_TIMEOUT_ENV = "SSA_FUSION_START_TIMEOUT_S"
"""Environment variable that sets `START_TIMEOUT_S` (wall s; 0 turns the watchdog off)."""

_finish_code = [EXIT_OK]
"""The exit code a callback asked for with `finish` (one process runs one node)."""

_constructed: list[Node] = []
"""The node this process is building or runs, from the start of its ``__init__``
(`constructing`): a node whose ``__init__`` refuses a parameter is destroyed by `run`, its
publishers first, rather than left to the garbage collector with DDS still running."""


def start_timeout_s() -> float:
    """Return the start watchdog's timeout, wall s (`START_TIMEOUT_ENV`, else the default).

    ValueError naming the variable when it is not a finite number >= 0.
    """
    text = os.environ.get(START_TIMEOUT_ENV, "")
    if not text:
        return START_TIMEOUT_S
    try:
        value = float(text)
    except ValueError:
        value = math.nan
    if not (math.isfinite(value) and value >= 0.0):
        raise ValueError(f"{START_TIMEOUT_ENV} must be a number of seconds >= 0 (0: no "
                         f"watchdog), got {text!r}")
    return value


@contextlib.contextmanager
def start_watchdog() -> Iterator[None]:
    """Exit the process (1, every thread's stack on stderr) if the block outlasts the timeout.

    `start_timeout_s`; faulthandler's own thread does it, so it works while the main thread
    is blocked inside DDS holding the GIL, where no Python signal handler or thread can run.
    """
    timeout = start_timeout_s()
    if timeout > 0.0:
        faulthandler.dump_traceback_later(timeout, exit=True, file=sys.stderr)
    try:
        yield
    finally:
        if timeout > 0.0:
            faulthandler.cancel_dump_traceback_later()


def constructing(node: Node) -> None:
    """Record `node`, whose ``__init__`` has just made its rclpy node (`SsaNode` calls it)."""
    _constructed[:] = [node]


def run(make_node: Callable[[], SsaNode], args: list[str] | None = None) -> int:
    """Run one node in this process with the behaviour users rely on; return the exit code.

    SIGINT/SIGTERM (also twice, also during shutdown) end the loop; pending callbacks are
    drained for a moment (so a recorder writes what already reached it), the node's
    ``close()`` runs, and the process exits 0. An invalid parameter at start-up exits 2 with
    a message naming the parameter. A callback may call `finish()` to end with exit 0.
    """
    stop = STOP  # set by the handlers `start_process` installed (the node's main calls it)
    problem = params_file_problem(sys.argv[1:] if args is None else args)
    if problem:
        print(f"error: cannot start: {problem}", file=sys.stderr)
        return EXIT_BAD_PARAMETERS
    try:
        start_timeout_s()
    except ValueError as exc:
        print(f"error: cannot start: {exc}", file=sys.stderr)
        return EXIT_BAD_PARAMETERS
    try:
        with start_watchdog():
            rclpy.init(args=args, signal_handler_options=SignalHandlerOptions.NO)
    except _rclpy.RCLError as exc:  # rcl could not parse the arguments: a -p rule, a params file
        print(f"error: cannot start: {_first_line(str(exc))} (check the --ros-args: "
              "-p name:=value rules need a value, lists one type; params files valid YAML)",
              file=sys.stderr)
        return EXIT_BAD_PARAMETERS
    node: SsaNode | None = None
    code = EXIT_OK
    executor: Executor | None = None
    try:
        if stop.is_set():  # interrupted while starting: nothing to do
            return code
        node = make_node()
        # a node of a run reads each message's writer (its MessageInfo), which rclpy's
        # EventsExecutor cannot hand over
        executor = make_executor(message_info=node.diag.members.has_run)
        executor.add_node(node)
        while not stop.is_set():
            try:
                executor.spin_once(timeout_sec=0.1)
            except Exception as exc:  # raised outside the node's guarded callbacks
                escaped(node, exc)
        # a stop that takes longer than it should says where it is stuck (every thread's
        # stack on stderr), so that a node killed for it leaves the reason behind
        faulthandler.dump_traceback_later(SLOW_STOP_S, exit=False, file=sys.stderr)
        _drain(executor, node)
    except ParameterError as exc:
        print(f"error: {exc}", file=sys.stderr)
        code = EXIT_BAD_PARAMETERS
    except _rclpy.RCLError as exc:  # rcl could not make the node: e.g. DDS Security asked of
        # a middleware built without it (docs/SECURITY.md)
        print(f"error: cannot start: {_first_line(str(exc))}", file=sys.stderr)
        code = EXIT_FAILED
    finally:
        if node is not None:
            with contextlib.suppress(Exception):  # a context already shut down: no last word
                node.diag.publish_last()
            node.close()
            node.destroy_node()
        elif _constructed:  # refused while starting: destroyed in order, as rclpy does
            _constructed.pop().destroy_node()
        if executor is not None:
            executor.shutdown()
        rclpy.try_shutdown()
        # Python's finalization resets handlers it installed to SIG_DFL, so a late second
        # interrupt would kill the exiting process (-15/-2); ignored signals stay ignored.
        signal.signal(signal.SIGINT, signal.SIG_IGN)
        signal.signal(signal.SIGTERM, signal.SIG_IGN)
        faulthandler.cancel_dump_traceback_later()
    return max(code, _finish_code[0])


PARAMS_FILE_MAX_LINES = 20_000
"""Most lines of a params file a node starts with. rcl's YAML parser takes time quadratic in
the number of keys (0.24 s for 10,000, 2.2 s for 40,000; a million would take most of an
hour and ignore SIGTERM meanwhile); a node's settings are a few dozen lines."""


def params_file_problem(args: list[str]) -> str | None:
    """Return why a ``--params-file`` among the ROS arguments `args` is refused, or None.

    Checked before rcl reads it: a file larger than `params_file.PARAMS_FILE_MAX_BYTES` or with
    more than `PARAMS_FILE_MAX_LINES` lines. (A file that cannot be read is left to rcl,
    whose error names it.)
    """
    from ssa_fusion.params.params_file import PARAMS_FILE_MAX_BYTES

    ros = False
    for k, arg in enumerate(args):
        if arg == "--ros-args":
            ros = True
        elif arg == "--":
            ros = False
        elif ros and arg == "--params-file" and k + 1 < len(args):
            path = args[k + 1]
            try:
                with open(path, "rb") as f:
                    head = f.read(PARAMS_FILE_MAX_BYTES + 1)
            except OSError:
                continue
            if len(head) > PARAMS_FILE_MAX_BYTES:
                return (f"params file {path} is larger than {PARAMS_FILE_MAX_BYTES} bytes; "
                        "a node's settings are a few dozen lines")
            if head.count(b"\n") > PARAMS_FILE_MAX_LINES:
                return (f"params file {path} has more than {PARAMS_FILE_MAX_LINES} lines; "
                        "a node's settings are a few dozen lines")
    return None


def finish(code: int = EXIT_OK) -> None:
    """End the node's loop from a callback: the node's job is done, or cannot go on.

    `run` leaves its loop after this callback returns, closes the node and exits with
    `code` (0: done; `EXIT_FAILED`: it cannot go on, having said why). (Not an exception:
    rclpy's executor logs an exception escaping a callback as FATAL with a traceback.)
    """
    _finish_code[0] = max(_finish_code[0], code)
    STOP.set()


def _first_line(text: str) -> str:
    """Return the message of an rcl error without its source locations (", at file.c:N")."""
    return text.strip().splitlines()[0].split(", at /")[0] if text.strip() else "unknown error"


def escaped(node: SsaNode, exc: Exception) -> None:
    """Count an exception that escaped the node's own (guarded) callbacks instead of dying.

    rclpy's handling of a /clock message it cannot take (a negative time) raises in the
    executor. Counted as `rejected_clock` when it came from rclpy's time source, else
    `internal_error`, on the node's /diagnostics (logged once).
    """
    frames = traceback.extract_tb(exc.__traceback__)
    from_clock = any(f.filename.endswith(("time_source.py", "clock.py", "time.py"))
                     for f in frames)
    cause = Cause.REJECTED_CLOCK if from_clock else Cause.INTERNAL_ERROR
    detail = (f"a /clock message rclpy cannot take ({type(exc).__name__}: {exc}); ignored"
              if from_clock else f"{type(exc).__name__}: {exc}\n" + traceback.format_exc())
    node.diag.count(cause, detail)


def _drain(executor: Executor, node: SsaNode, quiet_s: float = 0.2,
           limit_s: float = 3.0) -> None:
    """Run the input callbacks already pending until no message came for `quiet_s`."""
    if not node.diag.has_inputs:
        return
    deadline = time.monotonic() + limit_s
    last, last_change = node.diag.activity, time.monotonic()
    while time.monotonic() < deadline and time.monotonic() - last_change < quiet_s:
        try:
            executor.spin_once(timeout_sec=0.02)
        except Exception as exc:
            escaped(node, exc)
        if node.diag.activity != last:
            last, last_change = node.diag.activity, time.monotonic()

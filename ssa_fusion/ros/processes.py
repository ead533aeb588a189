"""Run ssa_fusion node executables as separate processes over real DDS, loopback by default.

`Graph` starts executables (the files `ros2 run ssa_fusion <node>` runs) with
``ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST`` and Fast DDS listening on loopback only (or the
`ros.discovery.Discovery` it is given: nodes on other hosts) and a ROS domain id of its own,
gives the caller a probe node in that domain to wait for topic matches and to receive
messages (never a fixed sleep), and tears every process down with SIGTERM (SIGKILL after a
timeout), reporting exit codes and log tails. Used by `ssa-fusion live`/`replay` and by
the headless graph tests.

A graph of a run (`run`: `ros.run_identity.new_run_id`) starts every node in the run's
namespace and its probe there too; the probe's collections then take the run's messages
only (`collect`; the others are counted in `foreign`). Every process's ROS log files go to
the graph's log directory (``ROS_LOG_DIR``), never ``~/.ros/log``, and its shared-memory
segments are the user's only (`ros.shm_privacy`).
"""

from __future__ import annotations

import itertools
import json
import os
import signal
import subprocess
import sys
import time
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import rclpy
from rclpy.context import Context
from rclpy.node import Node
from rclpy.qos import QoSProfile

from ssa_fusion.ros import shm_privacy
from ssa_fusion.ros.discovery import LOOPBACK, Discovery
from ssa_fusion.ros.executors import make_executor
from ssa_fusion.ros.interfaces import Message
from ssa_fusion.ros.player import Player
from ssa_fusion.ros.qos import DATA_QOS
from ssa_fusion.ros.run_identity import ROOT, RunGate, RunMembers, run_namespace

NODE_BIN = Path(sys.prefix) / "lib" / "ssa_fusion"
"""Where the bootstrap places node executables (as `ros2 run ssa_fusion <node>` finds them)."""

_domain_counter = itertools.count()

DOMAINS_ENV = "SSA_FUSION_DOMAINS"
"""Environment variable: the ROS domain ids a graph or run without a domain of its own picks
from, ``first-last`` within 1..101 (default ``1-101``; their ports stay below Linux's ephemeral
range). Processes that run side by side on one loopback (the test suite's workers) give each
its own part, so that none picks a domain another one's graph is in."""


def auto_domains() -> range:
    """Return the domain ids `fresh_domain_id` and a run's free-domain search pick from.

    `DOMAINS_ENV` (default 1..101); ValueError, naming the variable, when it is malformed.
    """
    raw = os.environ.get(DOMAINS_ENV, "").strip() or "1-101"
    first, sep, last = raw.partition("-")
    try:
        lo, hi = int(first), int(last)
    except ValueError:
        lo = hi = 0
    if not sep or not 1 <= lo <= hi <= 101:
        raise ValueError(f"{DOMAINS_ENV}={raw!r}: give the ROS domain ids to pick from as "
                         "first-last within 1-101 (e.g. 1-50)")
    return range(lo, hi + 1)


def fresh_domain_id() -> int:
    """Return a ROS domain id of `auto_domains` unlikely to be shared with another graph or run."""
    domains = auto_domains()
    return domains[(os.getpid() * 7 + next(_domain_counter)) % len(domains)]


def node_command(executable: str) -> list[str]:
    """Return the command that runs node `executable`.

    The installed file, else the same entry point through the module
    (`ssa_fusion.nodes.entry`).
    """
    path = NODE_BIN / executable
    if path.exists():
        return [str(path)]
    return [sys.executable, "-m", "ssa_fusion.nodes.entry", executable]


@dataclass
class Proc:
    """A started executable and its log files."""

    name: str
    popen: subprocess.Popen[bytes]
    stdout_path: Path
    stderr_path: Path
    expect_returncode: int | None = 0

    @property
    def returncode(self) -> int | None:
        """Return the exit code, or None while it runs."""
        return self.popen.poll()

    def stdout(self) -> str:
        """Return what it printed on stdout so far."""
        return self.stdout_path.read_text(errors="replace")

    def stderr(self) -> str:
        """Return what it printed on stderr so far."""
        return self.stderr_path.read_text(errors="replace")

    def describe(self) -> str:
        """Return its name, pid, exit code and the end of its stderr."""
        tail = "\n".join(self.stderr().splitlines()[-30:])
        return f"process {self.name!r} (pid {self.popen.pid}) exit {self.returncode}:\n{tail}"


class Graph:
    """Processes plus an in-process probe node, all in one private ROS domain.

    Every wait below is a condition wait: it spins the probe until its condition holds and
    gives up only after its timeout, which is multiplied by `timeout_factor`.
    """

    timeout_factor: float = 1.0
    """Multiplies every timeout of this class's waits (`scaled`). 1 for `live`/`replay`; the
    test suite sets it from ``SSA_TEST_TIMEOUT_FACTOR`` (test/ros_graph.py) so that its waits
    hold on a loaded machine. A wait ends as soon as its condition holds, so a larger factor
    lets a slow run take longer and never slows a passing one."""

    def __init__(self, workdir: Path, domain_id: int | None = None,
                 discovery: Discovery = LOOPBACK, run: str | None = None) -> None:
        self.workdir = Path(workdir)
        self.workdir.mkdir(parents=True, exist_ok=True)
        self.domain_id = fresh_domain_id() if domain_id is None else domain_id
        self.discovery = discovery
        self.run = run
        self.namespace = ROOT if run is None else run_namespace(run)
        self.procs: list[Proc] = []
        self.foreign: Counter[str] = Counter()
        """Messages the probe's collections refused, by topic: not of the run."""
        discovery.apply(os.environ)  # the probe's too (read at rclpy.init)
        discovery.bind(os.environ, self.workdir)
        self.env = dict(os.environ)
        self.env.update(ROS_DOMAIN_ID=str(self.domain_id), PYTHONUNBUFFERED="1",
                        ROS_LOG_DIR=str(self.workdir / "ros"))
        os.environ.setdefault("ROS_LOG_DIR", self.env["ROS_LOG_DIR"])  # this process's too
        self.context = Context()
        rclpy.init(context=self.context, domain_id=self.domain_id)
        self.probe: Node = rclpy.create_node("ssa_fusion_probe", namespace=self.namespace,
                                             context=self.context)
        self.members = RunMembers(self.probe)
        self._gates: list[RunGate] = []
        self.executor = make_executor(self.context, message_info=run is not None)
        self.executor.add_node(self.probe)
        shm_privacy.make_private()
        self._private_at = time.monotonic()

    # processes ---------------------------------------------------------------------------
    def start(self, name: str, cmd: list[str], expect_returncode: int | None = 0,
              env: dict[str, str] | None = None) -> Proc:
        """Start `cmd` in this graph's domain; output goes to workdir/<name>.{out,err}.

        `env`: variables set for this process on top of the graph's.
        """
        out = self.workdir / f"{name}.out"
        if self.run is not None and "--ros-args" in cmd:  # a node: in the run's namespace
            cmd = [*cmd, "--ros-args", "-r", f"__ns:={self.namespace}"]
        err = self.workdir / f"{name}.err"
        popen = subprocess.Popen(cmd, env={**self.env, **(env or {})}, stdout=out.open("wb"),
                                 stderr=err.open("wb"), stdin=subprocess.DEVNULL,
                                 start_new_session=True)
        proc = Proc(name, popen, out, err, expect_returncode)
        self.procs.append(proc)
        return proc

    def start_node(self, executable: str, *ros_args: str, params: dict[str, Any] | None = None,
                   params_file: Path | None = None, name: str | None = None,
                   expect_returncode: int | None = 0, env: dict[str, str] | None = None) -> Proc:
        """Start an ssa_fusion node executable with parameters (`-p key:=value`).

        `env`: as `start`'s.
        """
        cmd = [*node_command(executable), *ros_arguments(params, params_file)]
        return self.start(name or executable, cmd + list(ros_args), expect_returncode, env)

    def start_python(self, script: Path | str, *args: str, name: str,
                     expect_returncode: int | None = 0) -> Proc:
        """Start a Python script with this interpreter."""
        return self.start(name, [sys.executable, str(script), *args], expect_returncode)

    def scaled(self, seconds: float) -> float:
        """Return a nominal timeout of `seconds` times `timeout_factor`."""
        return seconds * self.timeout_factor

    def wait_exit(self, proc: Proc, timeout: float) -> int:
        """Wait for `proc` to end by itself, spinning the probe meanwhile; return its code.

        `timeout` is scaled.
        """
        self.wait_for(lambda: proc.popen.poll() is not None, timeout, f"{proc.name} to exit")
        return proc.popen.returncode

    def wait_done_or_broken(self, proc: Proc, timeout: float) -> bool:
        """Wait until `proc` ends by itself or any other process of the graph ends.

        Return True when `proc` ended. Another process ending first means the graph cannot
        finish (a recorder that could not create its bag, a node that died): the caller
        stops at once rather than waiting out `timeout` (s, scaled; TimeoutError after it).
        """
        others = [p for p in self.procs if p is not proc]
        self.wait_for(lambda: proc.popen.poll() is not None
                      or any(p.popen.poll() is not None for p in others),
                      timeout, f"{proc.name} to exit")
        return proc.popen.poll() is not None

    def stop(self, proc: Proc, sig: int = signal.SIGTERM, timeout: float = 10.0) -> int:
        """Send `sig`; SIGKILL if still alive after `timeout` s (scaled); return the code."""
        if proc.popen.poll() is None:
            proc.popen.send_signal(sig)
            self._await(proc, timeout)
        return proc.popen.returncode

    def _await(self, proc: Proc, timeout: float) -> None:
        """Wait for `proc` to exit; SIGKILL if still alive after `timeout` s (scaled).

        The probe spins meanwhile: what the process says last (its final /diagnostics)
        reaches the probe's subscriptions.
        """
        deadline = time.monotonic() + self.scaled(timeout)
        while proc.popen.poll() is None and time.monotonic() < deadline:
            self.spin_once(0.05)
        if proc.popen.poll() is None:
            proc.popen.kill()
            proc.popen.wait(5)

    # probe -------------------------------------------------------------------------------
    def spin_once(self, timeout: float = 0.05) -> None:
        """Run the probe's callbacks that are ready (waiting up to `timeout` s)."""
        self.executor.spin_once(timeout_sec=timeout)
        for gate in self._gates:
            gate.release()
        if time.monotonic() - self._private_at >= shm_privacy.PERIOD_S:
            shm_privacy.make_private()
            self._private_at = time.monotonic()

    def wait_for(self, predicate: Callable[[], bool], timeout: float, what: str) -> None:
        """Spin the probe until `predicate()`; raise TimeoutError after `timeout` s (scaled).

        The error holds the processes' stderr.
        """
        limit = self.scaled(timeout)
        deadline = time.monotonic() + limit
        while not predicate():
            if time.monotonic() > deadline:
                scaling = (f" ({timeout:g} s x timeout factor {self.timeout_factor:g})"
                           if self.timeout_factor != 1.0 else "")
                raise TimeoutError(
                    f"timed out after {limit:g} s{scaling} waiting for {what}\n{self.report()}"
                )
            self.spin_once()

    def wait_for_publisher(self, topic: str, count: int = 1, timeout: float = 20.0) -> None:
        """Wait until `topic` has `count` publishers."""
        self.wait_for(lambda: self.probe.count_publishers(topic) >= count, timeout,
                      f"{count} publisher(s) on {topic}")

    def wait_for_subscriber(self, topic: str, count: int = 1, timeout: float = 20.0) -> None:
        """Wait until `topic` has `count` subscribers."""
        self.wait_for(lambda: self.probe.count_subscribers(topic) >= count, timeout,
                      f"{count} subscriber(s) on {topic}")

    def collect(self, msg_type: type[Message], topic: str,
                qos: QoSProfile = DATA_QOS) -> list[Message]:
        """Subscribe the probe to `topic`; the returned list fills as messages arrive.

        A graph of a run takes its run's messages only (the others count in `foreign`).
        """
        received: list[Message] = []
        self.subscribe(msg_type, topic, received.append, qos)
        return received

    def subscribe(self, msg_type: type[Message], topic: str,
                  callback: Callable[[Message], None], qos: QoSProfile = DATA_QOS) -> None:
        """Subscribe the probe to `topic`: `callback` gets the run's messages only."""
        if self.run is None:
            self.probe.create_subscription(msg_type, topic, callback, qos)
            return

        def refuse(_why: str) -> None:
            self.foreign[topic] += 1

        gate = RunGate(self.members, topic, callback, refuse)
        self._gates.append(gate)
        self.probe.create_subscription(msg_type, topic, gate, qos)

    def others(self, look_s: float) -> list[str]:
        """Return the nodes of other participants in the domain, after `look_s` wall s.

        Their full names (namespace/name), the probe's own left out; hidden nodes (named
        ``_...``: the ros2 command's daemon) too. Not scaled: how long discovery is given.
        """
        deadline = time.monotonic() + look_s
        while time.monotonic() < deadline:
            self.spin_once(0.05)
        own = (self.probe.get_name(), self.probe.get_namespace())
        return sorted(f"{ns.rstrip('/')}/{name}"
                      for name, ns in self.probe.get_node_names_and_namespaces()
                      if (name, ns) != own and not name.startswith("_"))

    def wait_quiet(self, counts: Callable[[], object], quiet_s: float, limit_s: float) -> None:
        """Spin until `counts()` has not changed for `quiet_s` s.

        At most `limit_s` (scaled; `quiet_s` is not: it is how long a run must stay still,
        not a timeout).
        """
        deadline = time.monotonic() + self.scaled(limit_s)
        last, since = counts(), time.monotonic()
        while time.monotonic() < deadline and time.monotonic() - since < quiet_s:
            self.spin_once()
            now = counts()
            if now != last:
                last, since = now, time.monotonic()

    def report(self) -> str:
        """Return every process's description (`Proc.describe`)."""
        return "\n".join(p.describe() for p in self.procs)

    def play(self, player: Player, readers_ready: Callable[[], bool], readers: str) -> None:
        """Play `player`'s messages to the end once its `readers` matched its publishers.

        Waits for `readers_ready()` first, and at the end for the messages to be
        acknowledged (as ``ros2 bag play --wait-for-all-acked``).
        """
        self.wait_for(readers_ready, 30.0, readers)
        player.start()
        self.wait_for(player.done, player.duration_s + 60.0, "playback to finish")
        player.finish(self.scaled(5.0))

    # teardown ----------------------------------------------------------------------------
    def close(self, together: bool = False) -> list[str]:
        """Stop every process still running (newest first); describe unexpected exits.

        `together`: signal them all at once, then wait for each (a test's teardown, after
        which nothing is asserted about what a recorder would still receive; ~0.5 s per
        process less). Otherwise each is stopped before the next is signalled, so the first
        started (a recorder) hears the others to the end.
        """
        problems = []
        running = [p for p in reversed(self.procs) if p.popen.poll() is None]
        if together:
            for p in running:
                p.popen.send_signal(signal.SIGTERM)
        for p in reversed(self.procs):
            if together:
                if p in running:
                    self._await(p, 10.0)
            else:
                self.stop(p)
            if p.expect_returncode is not None and p.returncode != p.expect_returncode:
                problems.append(p.describe())
        self.executor.shutdown()
        self.probe.destroy_node()
        self.context.try_shutdown()
        return problems


def ended_badly(problems: list[str]) -> bool:
    """Say on stderr which node processes ended badly (`Graph.close`'s `problems`); True if any."""
    if problems:
        print("error: node process(es) ended badly:\n" + "\n".join(problems), file=sys.stderr)
    return bool(problems)


def recorded_short(record: Path, heard: dict[str, int],
                   rows: Callable[[Message], int] = lambda _m: 1) -> bool:
    """Say on stderr which topics the bag at `record` holds fewer of than were heard; True if any.

    `heard`: per topic, what a probe of the run received (messages, or `rows` of each
    message, e.g. an EstimateBatch's rows). A recorder that missed what the graph published
    must not pass as a complete replay.
    """
    from ssa_fusion.ros import bagio

    have = dict.fromkeys(heard, 0)
    for m in bagio.read_bag(record, list(heard)):
        have[m.topic] += rows(m.msg)
    short = [f"{t}: {have[t]} recorded of {n} published" for t, n in heard.items()
             if have[t] < n]
    if short:
        print(f"error: {record} misses what the graph published: " + "; ".join(short),
              file=sys.stderr)
    return bool(short)


def ros_arguments(params: dict[str, Any] | None = None,
                  params_file: Path | None = None) -> list[str]:
    """Return ``--ros-args`` with `params_file` and `params` (``-p key:=value`` each)."""
    out = ["--ros-args"]
    if params_file is not None:
        out += ["--params-file", str(params_file)]
    for key, value in (params or {}).items():
        out += ["-p", f"{key}:={_ros_value(value)}"]
    return out


def _ros_value(value: object) -> str:
    """Return `value` as a ``-p name:=value`` rule writes it (rcl reads it as YAML).

    Strings are double-quoted (JSON is YAML): an empty one, or one YAML would read as
    another type (``'123'``, ``'true'``), stays a string.
    """
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, str):
        return json.dumps(value)
    if isinstance(value, (list, tuple)):
        return "[" + ",".join(_ros_value(v) for v in value) + "]"
    return str(value)

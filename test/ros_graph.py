"""Headless ROS 2 graph tests: real node processes over real DDS, loopback only.

`RosGraph` starts executables as separate processes with
`ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST` and a ROS domain id of their own, gives the test a
probe node in that same domain to wait for topic matches and to receive messages (never a
fixed sleep), and tears every process down with SIGTERM (SIGKILL after a timeout), reporting
exit codes and stderr of any process that ended badly.
"""

from __future__ import annotations

import itertools
import os
import signal
import subprocess
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import rclpy
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node

from ssa_fusion.qos import DATA_QOS

NODE_BIN = Path(sys.prefix) / "lib" / "ssa_fusion"
"""Where the bootstrap places node executables (as `ros2 run ssa_fusion <node>` finds them)."""

_domain_counter = itertools.count()


def fresh_domain_id() -> int:
    """A ROS domain id in 1..100 unlikely to be shared with another test or test run."""
    return 1 + (os.getpid() * 7 + next(_domain_counter)) % 100


@dataclass
class NodeProcess:
    """A started executable with its log files."""

    name: str
    popen: subprocess.Popen
    stdout_path: Path
    stderr_path: Path
    expect_returncode: int | None = 0
    returncode: int | None = field(default=None)

    def stdout(self) -> str:
        return self.stdout_path.read_text(errors="replace")

    def stderr(self) -> str:
        return self.stderr_path.read_text(errors="replace")

    def describe(self) -> str:
        tail = "\n".join(self.stderr().splitlines()[-30:])
        return f"process {self.name!r} (pid {self.popen.pid}) exit {self.returncode}:\n{tail}"


class RosGraph:
    """Processes plus an in-test probe node, all in one private ROS domain."""

    def __init__(self, workdir: Path, domain_id: int | None = None) -> None:
        self.workdir = workdir
        self.domain_id = fresh_domain_id() if domain_id is None else domain_id
        self.processes: list[NodeProcess] = []
        self.env = dict(os.environ)
        self.env.update(
            ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST",
            ROS_DOMAIN_ID=str(self.domain_id),
            PYTHONUNBUFFERED="1",
            RCUTILS_LOGGING_BUFFERED_STREAM="0",
        )
        self.env.pop("ROS_STATIC_PEERS", None)
        os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
        self.context = Context()
        rclpy.init(context=self.context, domain_id=self.domain_id)
        self.probe: Node = rclpy.create_node("graph_test_probe", context=self.context)
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.probe)

    # processes ---------------------------------------------------------------------------
    def start(
        self, name: str, cmd: list[str], expect_returncode: int | None = 0
    ) -> NodeProcess:
        """Start `cmd` in this graph's domain; logs go to workdir/<name>.{out,err}."""
        out = self.workdir / f"{name}.out"
        err = self.workdir / f"{name}.err"
        popen = subprocess.Popen(
            cmd,
            env=self.env,
            stdout=out.open("wb"),
            stderr=err.open("wb"),
            stdin=subprocess.DEVNULL,
            start_new_session=True,
        )
        proc = NodeProcess(name, popen, out, err, expect_returncode)
        self.processes.append(proc)
        return proc

    def start_node(
        self, executable: str, *args: str, name: str | None = None, **kw
    ) -> NodeProcess:
        """Start an ssa_fusion node executable (the file `ros2 run ssa_fusion` would run)."""
        path = NODE_BIN / executable
        if not path.exists():
            raise FileNotFoundError(f"{path} missing: run tools/bootstrap.sh")
        return self.start(name or executable, [str(path), *args], **kw)

    def start_python(self, script: Path | str, *args: str, name: str, **kw) -> NodeProcess:
        """Start a Python script with this interpreter."""
        return self.start(name, [sys.executable, str(script), *args], **kw)

    def wait_exit(self, proc: NodeProcess, timeout: float) -> int:
        """Wait for `proc` to end by itself; spins the probe meanwhile."""
        self.wait_for(lambda: proc.popen.poll() is not None, timeout, f"{proc.name} to exit")
        proc.returncode = proc.popen.returncode
        return proc.returncode

    def stop(self, proc: NodeProcess, sig: int = signal.SIGTERM, timeout: float = 10.0) -> int:
        """Send `sig`; SIGKILL if still alive after `timeout` s. Returns the exit code."""
        if proc.popen.poll() is None:
            proc.popen.send_signal(sig)
            try:
                proc.popen.wait(timeout)
            except subprocess.TimeoutExpired:
                proc.popen.kill()
                proc.popen.wait(5)
        proc.returncode = proc.popen.returncode
        return proc.returncode

    # probe -------------------------------------------------------------------------------
    def spin_once(self, timeout: float = 0.05) -> None:
        self.executor.spin_once(timeout_sec=timeout)

    def wait_for(self, predicate: Callable[[], bool], timeout: float, what: str) -> None:
        """Spin the probe until `predicate()`; on timeout fail with the processes' stderr."""
        deadline = time.monotonic() + timeout
        while not predicate():
            if time.monotonic() > deadline:
                raise TimeoutError(
                    f"timed out after {timeout} s waiting for {what}\n{self.report()}"
                )
            self.spin_once()

    def wait_for_publisher(self, topic: str, count: int = 1, timeout: float = 20.0) -> None:
        self.wait_for(lambda: self.probe.count_publishers(topic) >= count, timeout,
                      f"{count} publisher(s) on {topic}")

    def wait_for_subscriber(self, topic: str, count: int = 1, timeout: float = 20.0) -> None:
        self.wait_for(lambda: self.probe.count_subscribers(topic) >= count, timeout,
                      f"{count} subscriber(s) on {topic}")

    def collect(self, msg_type, topic: str, qos=DATA_QOS) -> list:
        """Subscribe the probe to `topic`; the returned list fills as messages arrive."""
        received: list = []
        self.probe.create_subscription(msg_type, topic, received.append, qos)
        return received

    def report(self) -> str:
        for p in self.processes:
            if p.returncode is None:
                p.returncode = p.popen.poll()
        return "\n".join(p.describe() for p in self.processes)

    # teardown ----------------------------------------------------------------------------
    def close(self) -> list[str]:
        """Stop every process still running; returns a description of each unexpected exit."""
        problems = []
        for p in self.processes:
            if p.popen.poll() is None:
                self.stop(p)
            p.returncode = p.popen.returncode
            if p.expect_returncode is not None and p.returncode != p.expect_returncode:
                problems.append(p.describe())
        self.executor.shutdown()
        self.probe.destroy_node()
        self.context.try_shutdown()
        return problems

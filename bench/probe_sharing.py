"""Hostile-conditions probe, classes 14-16: one run, one graph (`probe_hostile.py` runs them).

14. lockstep under load and pauses: ``make demo``'s run beside 3 CPU burners prints the idle
    run's table and records its bag; a 60 s recorder pause (SIGSTOP) loses nothing, in the
    one-object graph (the same bag) and in a catalog (``lost: 0``);
15. run identity and strangers: two ``live`` runs started at once with one ``--domain-id``
    (one refuses in one line, the other's bag is a lone run's), two in PID namespaces of
    their own without one (each a lone run's bag), 20 /clock dated 2037 and 100
    measurements stamped 1972 of an unknown station from another participant mid-run (the
    lone run's bag, counted, ``report`` and ``replay --offline`` of it clean), a bag of two
    runs' clocks refused by ``report`` in one line;
16. what a run leaves to other local users: its shared-memory segments (``/dev/shm/fastdds_*``
    mapped by its processes: the user's only), its ROS logs (under ``--out``, none in
    ``~/.ros/log``), its sockets (none bound beyond loopback on a port it announces).

A lone run of each kind is the reference, run once (idle) and kept for the probes after it.
"""

from __future__ import annotations

import atexit
import contextlib
import os
import re
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable, Iterator, Sequence
from pathlib import Path

from bench_lockstep import burners as cpu_burners
from probe_hostile import (
    CLI,
    NODE_DIR,
    ROOT,
    Probe,
    Result,
    accounted,
    domain_pids,
    live_catalog_probe,
    node_logs,
    run_cmd,
    shell,
    stall,
)

SKY = ["--scenario", "iss_network", "--duration", "12"]
"""A short real-sky run whose filter starts before the outage (seed 0's case: passes from
5.4 h; a single radar's case may see none in 12 h, or its first pass only in the outage):
the identity probes' run, lockstep at 1000x (under a minute)."""
TABLE = re.compile(r"^\| (placeholder|coast|j2_coast|batch_fit|dmd_ekf|hypothetical_ekf) \|.*$",
                   re.M)
CHOSEN = re.compile(r"ROS domain (\d+)")
_reference: dict[str, tuple[Path, str]] = {}
"""A lone idle run per kind ('demo', 'sky'): its bag and its output."""
_DOMAINS = iter(range(120, 150))


def _same_bag(a: Path, b: Path) -> bool:
    """Whether two bags hold the same /ssa/* messages (False when either is missing)."""
    if not (a.is_dir() and b.is_dir()):
        return False
    try:
        from ssa_fusion.ros.bag_runs import same_messages
    except ImportError:  # an earlier version: /ssa/run did not exist
        from bench_lockstep import same_bag as same_messages
    try:
        return same_messages(a, b)
    except Exception:  # an unreadable bag is no bag to compare
        return False


def _live(d: Path, name: str, extra: Sequence[str], during: Callable[[subprocess.Popen[bytes],
          Path], None] | None = None, timeout: float = 600.0,
          prefix: Sequence[str] = ()) -> tuple[Result, list[str], Path]:
    """Run ``live`` into `d`/`name` (its own out); `during(popen, out)` acts meanwhile."""
    out = d / name
    argv = [*prefix, *CLI, "live", *extra, "--out", str(out)]
    r = run_cmd(argv, d / f"{name}_cmd", timeout,
                during=(lambda p, _start: during(p, d / f"{name}_cmd")) if during else None)
    r.logs = node_logs(out)
    return r, argv, out


def reference(d: Path, kind: str) -> tuple[Path, str]:
    """Return the bag and output of a lone idle run of `kind` (run the first time asked)."""
    if kind not in _reference:
        keep = Path(tempfile.mkdtemp(prefix="probe_sharing_"))
        atexit.register(shutil.rmtree, keep, ignore_errors=True)
        r, _argv, out = _live(keep, kind, SKY if kind == "sky" else [])
        _reference[kind] = (out / "bag", r.out)
    return _reference[kind]


def _said(cmd_dir: Path, pattern: str, limit: float = 180.0) -> re.Match[str] | None:
    """Wait until the command's stdout (in `cmd_dir`) says `pattern`; the match."""
    deadline = time.monotonic() + limit
    while time.monotonic() < deadline:
        with contextlib.suppress(OSError):
            m = re.search(pattern, (cmd_dir / "stdout.txt").read_text(errors="replace"))
            if m:
                return m
        time.sleep(0.2)
    return None


def _judge_same(kind: str, d_of: Callable[[], Path]) -> Callable[[Result], tuple[str, str]]:
    """Judge: exit 0, the lone run's bag (and, for the demo, its table)."""

    def judge(r: Result) -> tuple[str, str]:
        if r.rc != 0:
            return "unclean", f"exit {r.rc}"
        bag, out = _reference[kind]
        if kind == "demo" and TABLE.findall(r.out) != TABLE.findall(out):
            return "silent", "another table than the idle run's"
        if not _same_bag(bag, d_of() / "bag"):
            return "silent", "another bag than the lone run's"
        return "clean", ""

    return judge


# ----------------------------------------------------------------------------- class 14


def lockstep_probes() -> Iterator[Probe]:
    """Class 14: the demo beside 3 CPU burners; 60 s recorder pauses."""
    where: dict[str, Path] = {}

    def loaded(d: Path) -> tuple[Result, str]:
        reference(d, "demo")
        with cpu_burners(3):
            r, argv, where["out"] = _live(d, "loaded", [])
        return r, shell(argv) + "  (beside 3 CPU burners)"

    yield Probe("14", "make demo beside 3 CPU burners: the idle table and bag", loaded,
                _judge_same("demo", lambda: where["out"]), graph=True)

    def paused(d: Path) -> tuple[Result, str]:
        reference(d, "demo")

        def pause(p: subprocess.Popen[bytes], cmd_dir: Path) -> None:
            m = _said(cmd_dir, r"ROS domain (\d+)")
            pid = _recorder(int(m.group(1))) if m else None
            if pid is None:
                return
            time.sleep(20.0)  # into the run
            os.kill(pid, signal.SIGSTOP)
            time.sleep(60.0)
            os.kill(pid, signal.SIGCONT)

        r, argv, where["out"] = _live(d, "paused", [], pause, timeout=900.0)
        return r, shell(argv) + "  (recorder stopped 60 s mid-run)"

    yield Probe("14", "live: the recorder paused 60 s (SIGSTOP): the lone run's bag", paused,
                _judge_same("demo", lambda: where["out"]), graph=True)
    yield live_catalog_probe("14", "live --catalog: the recorder paused 60 s: nothing lost",
                             ["--synthetic", "200", "--duration", "6", "--shards", "2"],
                             stall("recorder", 60.0), accounted(True), timeout=900.0)


def _recorder(domain: int, limit: float = 120.0) -> int | None:
    """The recorder's pid in `domain` (any run's), once it runs."""
    deadline = time.monotonic() + limit
    while time.monotonic() < deadline:
        for pid in domain_pids(domain):
            with contextlib.suppress(OSError):
                if b"/lib/ssa_fusion/recorder" in Path(f"/proc/{pid}/cmdline").read_bytes():
                    return pid
        time.sleep(0.2)
    return None


# ----------------------------------------------------------------------------- class 15

STRANGER = """
import sys, time, rclpy
from rclpy.duration import Duration
from rosgraph_msgs.msg import Clock
from builtin_interfaces.msg import Time
from ssa_fusion_msgs.msg import Measurement
rclpy.init(domain_id=int(sys.argv[1]))
node = rclpy.create_node('stranger')
clock = node.create_publisher(Clock, '/clock', 10)
meas = node.create_publisher(Measurement, '/ssa/measurement', 10000)
deadline = time.monotonic() + 60
while (clock.get_subscription_count() < 3 or meas.get_subscription_count() < 3) \\
        and time.monotonic() < deadline:
    rclpy.spin_once(node, timeout_sec=0.1)
time.sleep(float(sys.argv[2]))
for k in range(20):
    clock.publish(Clock(clock=Time(sec=2_130_000_000 + k)))
for k in range(100):
    m = Measurement(object_id='probe', kind=1, z=[7e6, 1.0, 0.5],
                    covariance=[1e6, 0, 0, 0, 1e-4, 0, 0, 0, 1e-4])
    m.header.stamp = Time(sec=70_000_000 + k)
    m.header.frame_id = 'nowhere' if k % 2 else ''
    meas.publish(m)
clock.wait_for_all_acked(Duration(seconds=10))
meas.wait_for_all_acked(Duration(seconds=10))
print('sent', clock.get_subscription_count(), meas.get_subscription_count(), flush=True)
"""
"""A participant outside the run: 20 /clock dated 2037, 100 measurements stamped 1972."""


def identity_probes() -> Iterator[Probe]:
    """Class 15: runs that cannot merge, strangers that cannot steer."""
    where: dict[str, Path] = {}

    def same_domain(d: Path) -> tuple[Result, str]:
        ref, _ = reference(d, "sky")
        domain = next(_DOMAINS)
        argv = [*CLI, "live", *SKY, "--domain-id", str(domain)]
        d.mkdir(parents=True, exist_ok=True)
        procs = [subprocess.Popen([*argv, "--out", str(d / n)], cwd=ROOT, start_new_session=True,
                                  stdout=(d / f"{n}.out").open("wb"),
                                  stderr=(d / f"{n}.err").open("wb")) for n in ("a", "b")]
        codes = [p.wait(600) for p in procs]
        err = "".join((d / f"{n}.err").read_text() for n in ("a", "b"))
        r = Result(0, "", err, 0.0)
        ran = [n for n, c in zip("ab", codes, strict=True) if c == 0]
        refused = [n for n, c in zip("ab", codes, strict=True) if c == 2]
        if len(ran) == 2 or not ran:
            r.rc = 1
            r.notes.append(f"exit codes {codes}: both ran (merged?) or none did")
        elif len(refused) != 1 or len(re.findall(r"^error:", err, re.M)) != 1:
            r.notes.append(f"exit codes {codes}: the second did not refuse in one line")
        elif not _same_bag(ref, d / ran[0] / "bag"):
            r.notes.append("the run that ran has another bag than a lone run's")
        return r, shell(argv) + "  (twice at once)"

    yield Probe("15", "two live runs at once in one --domain-id: one refuses, one is lone",
                same_domain, _noted, graph=True)

    def pid_namespaces(d: Path) -> tuple[Result, str]:
        ref, _ = reference(d, "sky")
        d.mkdir(parents=True, exist_ok=True)
        argv = ["unshare", "-p", "-f", "--mount-proc", *CLI, "live", *SKY]
        procs = [subprocess.Popen([*argv, "--out", str(d / n)], cwd=ROOT, start_new_session=True,
                                  stdout=(d / f"{n}.out").open("wb"),
                                  stderr=(d / f"{n}.err").open("wb")) for n in ("a", "b")]
        codes = [p.wait(600) for p in procs]
        r = Result(0 if codes == [0, 0] else 1, "", "", 0.0)
        domains = [CHOSEN.search((d / f"{n}.out").read_text()) for n in ("a", "b")]
        if codes != [0, 0]:
            r.notes.append(f"exit codes {codes}")
        elif not all(_same_bag(ref, d / n / "bag") for n in ("a", "b")):
            r.notes.append("a bag differs from a lone run's (merged runs?)")
        r.out = " ".join(m.group(0) for m in domains if m)
        return r, shell(argv) + "  (twice at once, each in a PID namespace)"

    yield Probe("15", "two live runs in PID namespaces of their own: two lone runs' bags",
                pid_namespaces, _noted, graph=True)

    def strangers(d: Path) -> tuple[Result, str]:
        reference(d, "sky")
        domain = next(_DOMAINS)

        def stranger(p: subprocess.Popen[bytes], cmd_dir: Path) -> None:
            if _said(cmd_dir, r"ROS domain \d+") is None:
                return
            subprocess.run([sys.executable, "-c", STRANGER, str(domain), "3"], cwd=ROOT,
                           capture_output=True, timeout=120, check=False,
                           env={**os.environ, "ROS_DOMAIN_ID": str(domain)})

        r, argv, where["out"] = _live(d, "strangers", [*SKY, "--domain-id", str(domain)],
                                      stranger)
        if r.rc == 0:
            for extra in (["report", str(where["out"] / "bag"), "--out", str(d / "rep")],
                          ["replay", str(where["out"] / "bag"), "--offline", "--out",
                           str(d / "off")]):
                done = run_cmd([*CLI, *extra], d / extra[0], 300.0)
                if done.rc != 0:
                    r.notes.append(f"{extra[0]} of the bag: exit {done.rc}")
                r.err += done.err
        if "foreign_clock" not in r.logs or "foreign_run" not in r.logs:
            r.notes.append("the strangers were not counted (foreign_clock, foreign_run)")
        return r, shell(argv) + "  (a stranger sends 20 /clock of 2037, 100 of 1972)"

    yield Probe("15", "a stranger's /clock (2037) and measurements (1972) mid-run: no change",
                strangers, _judge_same("sky", lambda: where["out"]), graph=True)

    def mixed(d: Path) -> tuple[Result, str]:
        bag, _ = reference(d, "sky")
        d.mkdir(parents=True, exist_ok=True)
        _merge(bag, d / "mixed")
        argv = [*CLI, "report", str(d / "mixed"), "--out", str(d / "rep")]
        return run_cmd(argv, d / "run", 300.0), shell(argv) + "  (two runs' clocks in it)"

    yield Probe("15", "report of a bag holding two runs (their clocks interleaved)", mixed,
                _refused_one_line, graph=True)


def _merge(bag: Path, out: Path) -> None:
    """Write a bag of `bag`'s messages twice, the second copy 7 s later (two runs' clocks)."""
    from rosbags.rosbag2 import Reader

    from ssa_fusion.ros import bagio

    w = bagio.BagWriter(out)
    with Reader(bag) as r:
        for c in r.connections:
            w.add_topic(c.topic, c.msgtype)
        for c, t, data in r.messages():
            for shift in (0, 7_000_000_000):
                w.write(c.topic, t + shift, data)
    w.close()


def _noted(r: Result) -> tuple[str, str]:
    """Silent (runs merged, a bag not a lone run's) when the probe noted anything."""
    return ("silent", "; ".join(r.notes)) if r.notes else ("clean", "")


def _refused_one_line_any(r: Result) -> tuple[str, str]:
    """Refused (exit 1 or 2) in one error line."""
    lines = [ln for ln in r.err.splitlines() if ln.startswith("error:")]
    if r.rc == 0:
        return "silent", "started (exit 0)"
    if r.rc not in (1, 2) or len(lines) != 1:
        return "unclean", f"exit {r.rc}, {len(lines)} error lines"
    return "clean", ""


def _refused_one_line(r: Result) -> tuple[str, str]:
    lines = [ln for ln in r.err.splitlines() if ln.startswith("error:")]
    if r.rc == 0:
        return "silent", "scored as one run (exit 0)"
    if r.rc != 2 or len(lines) != 1:
        return "unclean", f"exit {r.rc}, {len(lines)} error lines"
    return "clean", ""


# ----------------------------------------------------------------------------- class 16


def leftover_probes() -> Iterator[Probe]:
    """Class 16: shared memory, logs and sockets of a run."""
    ros_log = Path.home() / ".ros" / "log"

    def run(d: Path) -> tuple[Result, str]:
        before = set(ros_log.iterdir()) if ros_log.is_dir() else set()
        seen: dict[str, list[str]] = {"shm": [], "sockets": []}
        domain = next(_DOMAINS)

        def look(p: subprocess.Popen[bytes], cmd_dir: Path) -> None:
            if _said(cmd_dir, r"ROS domain \d+") is None or _recorder(domain) is None:
                return
            time.sleep(3.0)
            for pid in domain_pids(domain):
                seen["shm"] += _open_segments(pid)
                seen["sockets"] += _announced_sockets(pid)

        r, argv, out = _live(d, "run", [*SKY, "--domain-id", str(domain)], look)
        if seen["shm"]:
            r.notes.append(f"segments others may read: {sorted(set(seen['shm']))[:2]}")
        if seen["sockets"]:
            r.notes.append(f"sockets beyond loopback: {seen['sockets'][:2]}")
        new = (set(ros_log.iterdir()) if ros_log.is_dir() else set()) - before
        if new:
            r.notes.append(f"{len(new)} log file(s) in ~/.ros/log, e.g. {sorted(new)[0].name}")
        if not list((out / "logs").rglob("*.log")):
            r.notes.append(f"no ROS log under {out}/logs")
        return r, shell(argv) + "  (its segments, sockets and logs)"

    yield Probe("16", "live: shared memory, sockets, logs the user's and under --out only",
                run, lambda r: ("clean", "") if r.rc == 0 else ("unclean", f"exit {r.rc}"),
                graph=True)

    def secure(d: Path) -> tuple[Result, str]:
        (d / "keys" / "enclaves" / "ssa").mkdir(parents=True)
        argv = [str(NODE_DIR / "filter"), "--ros-args", "--enclave", "/ssa"]
        env = {"ROS_SECURITY_ENABLE": "true", "ROS_SECURITY_STRATEGY": "Enforce",
               "ROS_SECURITY_KEYSTORE": str(d / "keys"), "ROS_DOMAIN_ID": str(next(_DOMAINS))}
        return run_cmd(argv, d / "run", 60.0, env=env), shell(argv) + "  (ROS_SECURITY_*)"

    yield Probe("16", "ROS_SECURITY_ENABLE with wheels without DDS Security: one line", secure,
                _refused_one_line_any, graph=True)


def _open_segments(pid: int) -> list[str]:
    """The /dev/shm/fastdds_* files process `pid` maps that others may read or write."""
    out = []
    with contextlib.suppress(OSError):
        for line in Path(f"/proc/{pid}/maps").read_text().splitlines():
            path = line.split()[-1]
            if path.startswith("/dev/shm/fastdds_"):
                with contextlib.suppress(OSError):
                    if os.stat(path).st_mode & 0o077:
                        out.append(path)
    return out


def _announced_sockets(pid: int) -> list[str]:
    """Sockets of `pid` on an address beyond loopback and a port outside the ephemeral range."""
    from probe_hostile import _ephemeral, _wild_sockets

    out = []
    for kind in ("udp", "tcp", "udp6", "tcp6"):
        with contextlib.suppress(OSError):
            out += [w for w in _wild_sockets(pid, kind)
                    if not _ephemeral(int(w.rsplit(":", 1)[1], 16))]
    return out


def sharing_probes() -> list[Probe]:
    """Classes 14, 15 and 16."""
    return [*lockstep_probes(), *identity_probes(), *leftover_probes()]

"""Graph test of shards on two hosts: two network namespaces joined by a veth pair.

Host A runs ``ssa-fusion live --catalog ... --shards 2 --remote-shards 1 --discovery-range
SUBNET`` (sensor_sim, the recorder, shard 0); host B runs the command live prints for shard
1 (catalog_filter alone, ``ros2 run`` with its parameters). Each namespace has its own
loopback, so everything between the hosts crosses the veth, whose byte counters must cover
what crossed it. Every object is tracked by exactly the shard of its key, and every
measurement is accounted for (published = recorded = received = consumed). The namespaces
are the test's own (ssa_fusion_host{A,B}_<pid>), removed at the end whatever happens;
without the right to make them (not root, no iproute2) the test is skipped, saying why.
"""

from __future__ import annotations

import json
import os
import re
import shlex
import shutil
import signal
import subprocess
import sys
import time
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import pytest
from ros_graph import TIMEOUT_FACTOR

from ssa_fusion.nodes.kit.shards import shard_range
from ssa_fusion.ros import bagio, messages
from ssa_fusion.ros.discovery import PROFILE_VAR, Discovery
from ssa_fusion.ros.processes import fresh_domain_id, node_command
from ssa_fusion.ros.topics import TOPIC_ESTIMATE_BATCH, TOPIC_MEASUREMENT_BATCH

SAMPLE = Path(__file__).resolve().parents[2] / "config" / "catalogs" / "sample.tle"
OBJECTS = 12
REMOTE_LINE = re.compile(r"on shard (\d+)'s host: (.+)")


@dataclass(frozen=True)
class Host:
    """A network namespace standing for a host, and its end of the veth pair."""

    netns: str
    veth: str
    address: str

    def run(self, *cmd: str) -> str:
        """Run `cmd` in this host's namespace; return its stdout."""
        return _ip("netns", "exec", self.netns, *cmd)

    def counters(self) -> dict[str, int]:
        """Return the veth's rx_bytes and tx_bytes (B)."""
        return {k: int(self.run("cat", f"/sys/class/net/{self.veth}/statistics/{k}"))
                for k in ("rx_bytes", "tx_bytes")}


def _ip(*args: str) -> str:
    done = subprocess.run(["ip", *args], capture_output=True, text=True, timeout=20)
    if done.returncode:
        raise RuntimeError(f"ip {' '.join(args)}: {done.stderr.strip()}")
    return done.stdout


@pytest.fixture(scope="module")
def hosts() -> Iterator[tuple[Host, Host]]:
    """Hosts A and B (namespaces, veth pair 10.213.0.1/30 - 10.213.0.2/30), removed after."""
    if shutil.which("ip") is None:
        pytest.skip("no iproute2 (`ip`): cannot make network namespaces")
    pid = os.getpid()
    a = Host(f"ssa_fusion_hostA_{pid}", f"ssaA{pid}", "10.213.0.1")
    b = Host(f"ssa_fusion_hostB_{pid}", f"ssaB{pid}", "10.213.0.2")
    made: list[str] = []
    try:
        for h in (a, b):
            try:
                _ip("netns", "add", h.netns)
            except RuntimeError as exc:
                pytest.skip(f"cannot make a network namespace (root needed): {exc}")
            made.append(h.netns)
        _ip("link", "add", a.veth, "type", "veth", "peer", "name", b.veth)
        for h in (a, b):
            _ip("link", "set", h.veth, "netns", h.netns)
            _ip("-n", h.netns, "addr", "add", f"{h.address}/30", "dev", h.veth)
            _ip("-n", h.netns, "link", "set", "lo", "up")
            _ip("-n", h.netns, "link", "set", h.veth, "up")
        yield a, b
    finally:
        for ns in made:  # the veth pair goes with them
            subprocess.run(["ip", "netns", "del", ns], capture_output=True, timeout=20)


def _stop(popen: subprocess.Popen[bytes]) -> int:
    """SIGTERM `popen` (SIGKILL after 10 s x factor); return its exit code."""
    if popen.poll() is None:
        popen.send_signal(signal.SIGTERM)
        try:
            popen.wait(10 * TIMEOUT_FACTOR)
        except subprocess.TimeoutExpired:
            popen.kill()
            popen.wait(5)
    return popen.returncode


def _wait(predicate, timeout: float, what: str, logs: list[Path]) -> None:
    """Poll `predicate` every 0.1 s; fail after `timeout` s (x factor) with the `logs`."""
    deadline = time.monotonic() + timeout * TIMEOUT_FACTOR
    while not predicate():
        if time.monotonic() > deadline:
            tails = "\n".join(f"--- {p}:\n{p.read_text(errors='replace')[-3000:]}"
                              for p in logs if p.exists())
            pytest.fail(f"timed out waiting for {what}\n{tails}")
        time.sleep(0.1)


def _netns_of(pid: int) -> str:
    return os.readlink(f"/proc/{pid}/ns/net")


@pytest.fixture(scope="module")
def run(hosts, tmp_path_factory):
    """Live on A with shard 1 remote; shard 1 on B from the command live printed."""
    a, b = hosts
    out = tmp_path_factory.mktemp("multihost")
    live_out, live_err = out / "live.out", out / "live.err"
    # as on a host of its own: not the loopback-only profile of this process's earlier graphs
    env = {k: v for k, v in os.environ.items() if k != PROFILE_VAR}
    env["PYTHONUNBUFFERED"] = "1"
    live_cmd = ["ip", "netns", "exec", a.netns, sys.executable, "-m", "ssa_fusion.apps.cli",
                "live", "--catalog", str(SAMPLE),
                "--synthetic", str(OBJECTS), "--duration", "6", "--shards", "2",
                "--remote-shards", "1", "--no-surrogate", "--discovery-range", "SUBNET",
                "--scenario", "iss_network", "--time-scale", "max", "--seed", "4",
                "--domain-id", str(fresh_domain_id()), "--out", str(out / "run")]
    procs: list[subprocess.Popen[bytes]] = []
    try:
        live = subprocess.Popen(live_cmd, env=env, stdout=live_out.open("wb"),
                                stderr=live_err.open("wb"), stdin=subprocess.DEVNULL,
                                start_new_session=True)
        procs.append(live)
        logs = [live_out, live_err]

        def remote() -> list[tuple[int, str]]:
            return [(int(m[1]), m[2]) for m in REMOTE_LINE.finditer(live_out.read_text())]

        _wait(lambda: remote() or live.poll() is not None, 30, "live to print shard 1's "
              "command", logs)
        commands = remote()
        assert [k for k, _ in commands] == [1], live_out.read_text()
        words = shlex.split(commands[0][1])
        assignments = [w for w in words if re.fullmatch(r"[A-Z_]+=.*", w)]
        rest = words[len(assignments):]
        assert rest[:3] == ["ros2", "run", "ssa_fusion"]  # no ros2 CLI here: its executable
        shard_env = {**env, **dict(w.split("=", 1) for w in assignments)}
        shard_err = out / "shard_1.err"
        logs.append(shard_err)
        shard = subprocess.Popen(["ip", "netns", "exec", b.netns, *node_command(rest[3]),
                                  *rest[4:]], env=shard_env,
                                 stdout=(out / "shard_1.out").open("wb"),
                                 stderr=shard_err.open("wb"), stdin=subprocess.DEVNULL,
                                 start_new_session=True)
        procs.append(shard)
        namespaces = {"A": _netns_of(live.pid), "test": _netns_of(os.getpid())}
        _wait(lambda: live.poll() is not None, 120, "live to finish", logs)
        if shard.poll() is None:
            namespaces["B"] = _netns_of(shard.pid)
        shard_code = _stop(shard)  # the remote shard is stopped by hand, as its user would
        summary_path = out / "run" / "catalog.json"
        return {"rc": live.returncode, "shard_rc": shard_code, "out": out / "run",
                "summary": json.loads(summary_path.read_text()) if summary_path.exists()
                else None, "stdout": live_out.read_text(), "stderr": live_err.read_text(),
                "shard_stderr": shard_err.read_text(), "assignments": assignments,
                "namespaces": namespaces, "a": a.counters(), "b": b.counters()}
    finally:
        for p in reversed(procs):
            _stop(p)


def _payload(bag: Path, topic: str, object_ids: set[str]) -> int:
    """Bytes (CDR) of the recorded batches on `topic` whose rows are all of `object_ids`."""
    store = bagio.typestore()
    return sum(len(store.serialize_cdr(m.msg, m.msgtype))
               for m in bagio.read_bag(bag, topics=[topic])
               if set(m.msg.object_id) <= object_ids)


def test_the_run_across_two_hosts_ends_with_nothing_lost(run):
    assert run["rc"] == 0, run["stdout"] + run["stderr"]
    assert run["shard_rc"] == 0, run["shard_stderr"]
    s = run["summary"]
    assert s["published"] > 500
    assert s["lost_measurements"] == 0 and s["lost_estimates"] == 0
    assert s["published"] == s["recorded_measurements"] == s["received_by_shards"] \
        == s["consumed_by_banks"]
    assert s["objects_with_estimates"] == OBJECTS
    assert s["remote_nodes"] == ["catalog_filter_1"]
    assert "catalog_filter_1: " in run["stdout"] and "RSS on its own host" in run["stdout"]


def test_the_remote_shard_ran_on_the_other_host_with_subnet_discovery(run):
    ns = run["namespaces"]
    assert "B" in ns, "shard 1 ended before the run did:\n" + run["shard_stderr"]
    assert len({ns["A"], ns["B"], ns["test"]}) == 3  # no loopback in common: only the veth
    assert "ROS_AUTOMATIC_DISCOVERY_RANGE=SUBNET" in run["assignments"]


def test_every_object_is_tracked_by_exactly_the_shard_of_its_key(run):
    s, bag = run["summary"], run["out"] / "bag"
    shards = s["per_shard"]
    assert list(shards) == ["catalog_filter_0", "catalog_filter_1"]
    ids = [set(p["object_ids"]) for p in shards.values()]
    assert ids[0].isdisjoint(ids[1]) and len(ids[0] | ids[1]) == OBJECTS and all(ids)
    for k, p in enumerate(shards.values()):
        lo, hi = shard_range(k, 2)
        assert all(lo <= messages.shard_key(o) <= hi for o in p["object_ids"])
        assert p["received"] > 0 and p["ignored_other_shard"] == 0
    published = {}  # recorded estimates by object
    for m in bagio.read_bag(bag, topics=[TOPIC_ESTIMATE_BATCH]):
        for oid in m.msg.object_id:
            published[oid] = published.get(oid, 0) + 1
    for p, mine in zip(shards.values(), ids, strict=True):
        assert sum(published.get(o, 0) for o in mine) == p["estimates"] > 0


def test_the_shards_traffic_crossed_the_veth(run):
    """B's veth received at least shard 1's measurements and sent at least its estimates."""
    s, bag = run["summary"], run["out"] / "bag"
    remote = set(s["per_shard"]["catalog_filter_1"]["object_ids"])
    mine_in = _payload(bag, TOPIC_MEASUREMENT_BATCH, remote)
    mine_out = _payload(bag, TOPIC_ESTIMATE_BATCH, remote)
    everything = _payload(bag, TOPIC_MEASUREMENT_BATCH, set(s["per_shard"]["catalog_filter_0"]
                                                      ["object_ids"]) | remote)
    b = run["b"]
    print(f"veth of host B: rx {b['rx_bytes']} B, tx {b['tx_bytes']} B; shard 1's "
          f"measurements {mine_in} B, its estimates {mine_out} B; all measurements "
          f"{everything} B")
    assert b["rx_bytes"] >= mine_in > 0
    assert b["tx_bytes"] >= mine_out > 0
    assert run["a"]["tx_bytes"] >= mine_in and run["a"]["rx_bytes"] >= mine_out


def test_a_graph_on_one_host_listens_on_loopback_only(hosts, tmp_path):
    """What `ssa-fusion live` runs by default, seen from the other host.

    Host A runs a catalog_filter with a graph's default settings (LOCALHOST, loopback
    profile) and a control catalog_filter with LOCALHOST alone (Fast DDS listening on every
    address). A participant on host B that names A in ROS_STATIC_PEERS discovers the
    control, never the node bound to loopback; and that node's DDS ports are on 127.0.0.1.
    """
    a, b = hosts
    domain = str(fresh_domain_id())
    base = {k: v for k, v in os.environ.items() if k != PROFILE_VAR}
    base["ROS_DOMAIN_ID"] = domain
    bound = dict(base)
    Discovery().apply(bound)
    Discovery().bind(bound, tmp_path)
    control = dict(base)
    Discovery().apply(control)
    peer = {**base, "ROS_AUTOMATIC_DISCOVERY_RANGE": "SUBNET", "ROS_STATIC_PEERS": a.address}
    procs: list[subprocess.Popen[bytes]] = []

    def start(host: Host, env: dict[str, str], *cmd: str, name: str) -> subprocess.Popen[bytes]:
        p = subprocess.Popen(["ip", "netns", "exec", host.netns, *cmd], env=env,
                             stdout=(tmp_path / f"{name}.out").open("wb"),
                             stderr=(tmp_path / f"{name}.err").open("wb"),
                             stdin=subprocess.DEVNULL, start_new_session=True)
        procs.append(p)
        return p

    try:
        node = start(a, bound, *node_command("catalog_filter"), "--ros-args", "-r",
                     "__node:=loopback_only", name="loopback_only")
        logs = [tmp_path / "loopback_only.err"]
        ports = range(7400 + 250 * int(domain), 7400 + 250 * (int(domain) + 1))

        def dds_sockets() -> list[str]:  # local address:port of its sockets on DDS ports
            lines = a.run("ss", "-lunpH").splitlines()
            addrs = [ln.split()[3] for ln in lines if f"pid={node.pid}," in ln]
            return [x for x in addrs if int(x.rsplit(":", 1)[1]) in ports]

        _wait(lambda: len(dds_sockets()) >= 2, 30, "the node's DDS sockets", logs)
        assert all(x.startswith("127.0.0.1:") for x in dds_sockets()), dds_sockets()
        start(a, control, *node_command("catalog_filter"), "--ros-args", "-r",
              "__node:=listening_everywhere", name="control")
        watcher = start(b, peer, sys.executable, str(Path(__file__).with_name("watch_nodes.py")),
                        "listening_everywhere", "3", str(30 * TIMEOUT_FACTOR), name="watcher")
        _wait(lambda: watcher.poll() is not None, 40, "the watcher on host B",
              [*logs, tmp_path / "watcher.err", tmp_path / "control.err"])
        seen = json.loads((tmp_path / "watcher.out").read_text() or "[]")
        assert watcher.returncode == 0 and "listening_everywhere" in seen, seen
        assert "loopback_only" not in seen
    finally:
        for p in reversed(procs):
            _stop(p)

"""`ssa-fusion live` stopped by a signal: SIGTERM and SIGHUP, like
SIGINT, stop every node the CLI started, close the bag, and exit 128 + the signal number.
Before, SIGTERM ended the CLI with 143 and left all four nodes running, the bag unclosed."""

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from ros_graph import TIMEOUT_FACTOR

from ssa_fusion.ros import bagio
from ssa_fusion.ros.processes import fresh_domain_id


def processes_in_domain(domain: int) -> list[int]:
    """Process ids whose environment has ROS_DOMAIN_ID=domain (this test's run only)."""
    pids = []
    for d in Path("/proc").iterdir():
        if not d.name.isdigit() or int(d.name) == os.getpid():
            continue
        try:
            env = (d / "environ").read_bytes().split(b"\0")
        except OSError:
            continue
        if f"ROS_DOMAIN_ID={domain}".encode() in env:
            pids.append(int(d.name))
    return pids


def wait_for(cond, timeout: float, what: str) -> None:
    deadline = time.monotonic() + timeout * TIMEOUT_FACTOR
    while not cond():
        assert time.monotonic() < deadline, f"timed out waiting for {what}"
        time.sleep(0.2)


@pytest.mark.parametrize("sig", [signal.SIGTERM])  # SIGHUP, SIGINT: the same handler
def test_live_stops_every_node_and_closes_the_bag(sig, tmp_path):  # (test/apps/test_cli.py)
    domain = fresh_domain_id()
    out = tmp_path / "run"
    # time scale 1000: the bag holds measurements ~4 s sooner than at 200; the whole run
    # (63 sim ks, ~1 min) still lasts far beyond the signal
    cli = subprocess.Popen(
        [sys.executable, "-m", "ssa_fusion.apps.cli", "live", "--time-scale", "1000",
         "--out", str(out), "--domain-id", str(domain)],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
        env={**os.environ, "ROS_DOMAIN_ID": str(domain)})
    try:
        # running: the recorder has written measurements to the bag's MCAP file
        wait_for(lambda: any(f.stat().st_size > 20000 for f in (out / "bag").glob("*.mcap")),
                 60.0, "the recorder to write measurements")
        assert len(processes_in_domain(domain)) >= 5  # the CLI and its four nodes
        cli.send_signal(sig)
        _, err = cli.communicate(timeout=60 * TIMEOUT_FACTOR)
    finally:
        if cli.poll() is None:
            cli.kill()
    assert cli.returncode == 128 + sig, err
    assert f"stopped by {signal.Signals(sig).name}" in err
    assert processes_in_domain(domain) == []  # no node left behind
    counts = {}
    for m in bagio.read_bag(out / "bag"):
        counts[m.topic] = counts.get(m.topic, 0) + 1
    assert counts.get("/ssa/measurement", 0) > 0 and counts.get("/ssa/config", 0) == 2
    assert (out / "bag" / "metadata.yaml").exists()  # closed, not recovered


@pytest.mark.parametrize("catalog", [False, True])
def test_a_recorder_that_cannot_create_its_bag_ends_the_run_at_once(catalog, tmp_path):
    """`--bag` under a file: the recorder exits 2 at start with the reason, and `live`
    stops every node and says so (it once waited 4 minutes for the simulator, then raised
    a TimeoutError)."""
    domain = fresh_domain_id()
    extra = ["--catalog", "config/catalogs/sample.tle"] if catalog else []
    start = time.monotonic()
    done = subprocess.run(
        [sys.executable, "-m", "ssa_fusion.apps.cli", "live", "--bag", "/dev/null/bag",
         "--out", str(tmp_path / "run"), "--domain-id", str(domain), *extra],
        capture_output=True, text=True, timeout=120 * TIMEOUT_FACTOR,
        cwd=Path(__file__).resolve().parents[2],
        env={**os.environ, "ROS_DOMAIN_ID": str(domain)})
    took = time.monotonic() - start
    assert done.returncode == 1, done.stderr
    assert "process 'recorder'" in done.stderr
    assert "parameter 'bag' = '/dev/null/bag': cannot create the bag there" in done.stderr
    assert "Traceback" not in done.stderr
    assert took < 60 * TIMEOUT_FACTOR  # not the simulator's timeout (60 s + 3 x sim/scale)
    assert processes_in_domain(domain) == []

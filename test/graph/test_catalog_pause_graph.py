"""A catalog run in lockstep whose recorder is stopped (SIGSTOP) longer than its DDS
participant lease: the others drop it, and their volatile writers never send it again what
they wrote meanwhile. The simulator once waited forever for those rows (a recorder stopped
30 s with Fast DDS's 20 s lease); now it names the loss in one line and the run ends, the
loss counted in its summary. The lease is made short here (`loopback_profile`: 3 s) so that
a pause of seconds shows what a pause of minutes does with the graph's own lease
(`PARTICIPANT_LEASE_S`, 600 s)."""

import json
import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

from ros_graph import TIMEOUT_FACTOR

from ssa_fusion.ros.discovery import (
    PARTICIPANT_LEASE_S,
    PROFILE_VAR,
    QOS_FROM_XML_VAR,
    loopback_profile,
)
from ssa_fusion.ros.processes import fresh_domain_id

SAMPLE = Path(__file__).resolve().parents[2] / "config" / "catalogs" / "sample.tle"
LEASE_S = 3.0
PAUSE_S = 8.0
"""Beyond `LEASE_S`: the recorder's participant is dropped while it is stopped."""
DROPPED = re.compile(r"lockstep: recorder lost what was sent to it while DDS had dropped it "
                     r".*\(lockstep_dropped\)")
SHORT = re.compile(r"recorded (\d+) of (\d+) (measurements|estimates)")
"""What the dropped line names the recorder short of: measurements, estimates or both (what
it lacked at the moment DDS dropped it depends on where the run was)."""


def _recorder(domain: int) -> int | None:
    """The pid of the run's recorder (its environment names `domain`), or None."""
    for d in Path("/proc").iterdir():
        if not d.name.isdigit():
            continue
        try:
            env = (d / "environ").read_bytes().split(b"\0")
            argv = (d / "cmdline").read_bytes().split(b"\0")
        except OSError:
            continue
        if f"ROS_DOMAIN_ID={domain}".encode() in env and any(
                a.endswith(b"/recorder") for a in argv[:2]):
            return int(d.name)
    return None


def _wait_for(cond, timeout: float, what: str):
    deadline = time.monotonic() + timeout * TIMEOUT_FACTOR
    while not (got := cond()):
        assert time.monotonic() < deadline, f"timed out waiting for {what}"
        time.sleep(0.1)
    return got


def test_the_graphs_own_lease_outlasts_a_minutes_pause():
    assert PARTICIPANT_LEASE_S >= 300.0  # Fast DDS's default is 20 s
    assert f"<leaseDuration><sec>{PARTICIPANT_LEASE_S:.0f}</sec>" in loopback_profile()


def test_a_recorder_stopped_beyond_its_lease_ends_the_run_with_its_loss_named(tmp_path):
    profile = tmp_path / "short_lease.xml"  # a profile of the user's own: `live` keeps it
    profile.write_text(loopback_profile(lease_s=LEASE_S, announce_s=0.25))
    domain, out = fresh_domain_id(), tmp_path / "run"
    cli = subprocess.Popen(
        [sys.executable, "-m", "ssa_fusion.apps.cli", "live", "--catalog", str(SAMPLE),
         "--synthetic", "12", "--duration", "3", "--shards", "1", "--time-scale", "1000",
         "--out", str(out), "--domain-id", str(domain)],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
        env={**os.environ, "ROS_DOMAIN_ID": str(domain), PROFILE_VAR: str(profile),
             QOS_FROM_XML_VAR: "1"})
    try:
        _wait_for(lambda: any(f.stat().st_size > 20000 for f in (out / "bag").glob("*.mcap")),
                  60.0, "the recorder to write measurements")
        pid = _wait_for(lambda: _recorder(domain), 10.0, "the recorder's process")
        os.kill(pid, signal.SIGSTOP)
        try:
            time.sleep(PAUSE_S)  # the pause itself (its length is the test's, not a wait)
        finally:
            os.kill(pid, signal.SIGCONT)
        stdout, _ = cli.communicate(timeout=90 * TIMEOUT_FACTOR)
    finally:
        if cli.poll() is None:  # SIGTERM: `live` stops every node it started
            cli.terminate()
            try:
                cli.communicate(timeout=60)
            except subprocess.TimeoutExpired:
                cli.kill()
                cli.communicate()
    log = (out / "logs" / "sensor_sim.err").read_text()
    named = DROPPED.findall(log)
    assert len(named) == 1, log[-3000:]
    short = SHORT.findall(named[0])
    assert short, named[0]
    s = json.loads((out / "catalog.json").read_text())
    assert s["lost_measurements"] == s["published"] - s["recorded_measurements"] > 0
    for recorded, sent, kind in short:
        assert int(recorded) < int(sent)
        assert s[f"lost_{kind}"] >= int(sent) - int(recorded), (kind, s)
    assert f"lost: {s['lost_measurements']}" in stdout
    # the first line names the run (its ROS namespace), as the one-object run's does
    assert re.search(r"; ROS domain \d+, run \d{8}_\d{6}_\d{3}_[0-9a-f]{4}; logs in ",
                     stdout.splitlines()[0])
    assert cli.returncode == 1  # measurements lost

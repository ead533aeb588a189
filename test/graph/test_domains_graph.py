"""Two `ssa-fusion live` runs never merge (`ros.domains`): started at once with the same
`--domain-id`, the second (the younger run) refuses in one line and the first runs on; in
two PID namespaces (two containers on one host, each its own PID 1) without a domain id,
each picks a free domain of its own. The runs are stopped (SIGTERM) once that is shown."""

import os
import re
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from ros_graph import TIMEOUT_FACTOR

from ssa_fusion.ros.processes import fresh_domain_id

CLI = [sys.executable, "-m", "ssa_fusion.apps.cli", "live"]
CHOSEN = re.compile(r"ROS domain (\d+), run (\S+);")


class Live:
    """A `live` command started in the background, its output in files."""

    def __init__(self, tmp: Path, name: str, argv: list[str]) -> None:
        self.out, self.err = tmp / f"{name}.out", tmp / f"{name}.err"
        env = {**os.environ, "ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST"}
        env.pop("ROS_DOMAIN_ID", None)
        with self.out.open("wb") as o, self.err.open("wb") as e:
            self.p = subprocess.Popen(argv, stdout=o, stderr=e, stdin=subprocess.DEVNULL,
                                      env=env, start_new_session=True)

    def domain(self) -> int | None:
        """The domain it said it runs in, once it has."""
        m = CHOSEN.search(self.out.read_text(errors="replace"))
        return int(m.group(1)) if m else None

    def stop(self) -> int:
        """SIGTERM it (once running; under `unshare`, its child), wait for its exit code."""
        if self.p.poll() is None:
            children = Path(f"/proc/{self.p.pid}/task/{self.p.pid}/children")
            kids = children.read_text().split() if children.exists() else []
            if Path(self.p.args[0]).name == "unshare" and kids:  # unshare forwards nothing
                os.kill(int(kids[0]), signal.SIGTERM)
            else:
                self.p.send_signal(signal.SIGTERM)
        return self.p.wait(60 * TIMEOUT_FACTOR)


def wait_until(predicate, seconds: float, what: str) -> None:
    deadline = time.monotonic() + seconds * TIMEOUT_FACTOR
    while not predicate():
        assert time.monotonic() < deadline, f"timed out waiting for {what}"
        time.sleep(0.1)


def test_two_runs_started_at_once_in_one_domain_the_second_refuses(tmp_path):
    domain = fresh_domain_id()
    runs = [Live(tmp_path, name, [*CLI, "--domain-id", str(domain), "--out",
                                  str(tmp_path / name)]) for name in ("a", "b")]
    try:
        wait_until(lambda: any(r.p.poll() is not None for r in runs), 120.0, "one to refuse")
        refused = [r for r in runs if r.p.poll() is not None]
        assert len(refused) == 1, [r.err.read_text() for r in runs]
        lines = [ln for ln in refused[0].err.read_text().splitlines()
                 if not ln.startswith("isolated:")]
        assert refused[0].p.returncode == 2 and len(lines) == 1, lines
        assert lines[0].startswith(f"error: ROS domain {domain} is in use (")
        assert "--share-domain" in lines[0]
        other = next(r for r in runs if r is not refused[0])
        wait_until(lambda: other.domain() == domain, 60.0, "the first to run on")
    finally:
        codes = [r.stop() for r in runs]
    assert sorted(codes) == [2, 128 + signal.SIGTERM], codes


@pytest.mark.skipif(os.geteuid() != 0 or shutil.which("unshare") is None,
                    reason="PID namespaces need root and unshare")
def test_two_runs_in_pid_namespaces_each_pick_a_free_domain(tmp_path):
    """Each is PID 1 of its namespace: a domain computed from the process id was the same."""
    runs = [Live(tmp_path, name, ["unshare", "-p", "-f", "--mount-proc",
                                  *CLI, "--out", str(tmp_path / name)])
            for name in ("a", "b")]
    try:
        wait_until(lambda: all(r.domain() is not None or r.p.poll() is not None
                               for r in runs), 120.0, "both to choose a domain")
        domains = [r.domain() for r in runs]
        assert None not in domains, [r.err.read_text() for r in runs]
        assert domains[0] != domains[1]
    finally:
        codes = [r.stop() for r in runs]
    assert codes == [128 + signal.SIGTERM] * 2, codes  # each stopped as a run is

"""`tools/bootstrap.sh` on a fresh venv says something at least every tick while it works.

The script runs on a copy of the tree's skeleton with pip, Python and CMake replaced by
stand-ins that take seconds and print nothing for most of them (as pip's "Installing
collected packages" and a CMake build do); every line on stderr is timed as it arrives.
"""

from __future__ import annotations

import itertools
import os
import re
import shutil
import subprocess
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
TICK_S = 1
"""The tick the runs here ask for (BOOTSTRAP_TICK_S), s."""
SLACK_S = 1.5
"""What a busy machine may add to a tick before the next line, s."""

FAKE_PYTHON = r"""#!/bin/bash
# pip, the interpreter's one-liners and the scripts read from stdin, as bootstrap.sh calls them
if [[ "$1 $2" == "-m pip" ]]; then
  echo "Collecting numpy==2.2.6"
  echo "Collecting rclpy==9.1.0"
  [[ -n "$FAKE_PIP_FAIL" ]] && { echo "ERROR: No matching distribution found for rclpy"; exit 1; }
  [[ "$*" == *" -r "* ]] && sleep "$FAKE_PIP_S"
  echo "Installing collected packages: numpy, rclpy"
  echo "Successfully installed numpy rclpy"
  exit 0
fi
if [[ "$1" == "-" ]]; then
  cat >/dev/null
  [[ "$2" == "" ]] && printf 'share/ssa_fusion\tpackage.xml\n'
  exit 0
fi
if [[ "$1" == "-c" ]]; then
  echo /nowhere
  exit 0
fi
exit 0
"""
FAKE_CMAKE = """#!/bin/bash
[[ "$1" == "--build" ]] && { echo "[ 50%] Building C object"; sleep "$FAKE_CMAKE_S"; }
exit 0
"""


def skeleton(tmp: Path) -> Path:
    """Return a tree with bootstrap.sh and the inputs it fingerprints, and a fake venv."""
    root = tmp / "repo"
    (root / "tools").mkdir(parents=True)
    for name in ("bootstrap.sh", "long_step.sh"):
        shutil.copy(ROOT / "tools" / name, root / "tools" / name)
    (root / "requirements").mkdir()
    for name in ("ros.txt", "python.txt"):
        (root / "requirements" / name).write_text("numpy==2.2.6\n")
    (root / "msg_defs" / "msg").mkdir(parents=True)
    for name in ("package.xml", "CMakeLists.txt", "msg/A.msg"):
        (root / "msg_defs" / name).write_text("x\n")
    for name in ("setup.py", "setup.cfg", "package.xml"):
        (root / name).write_text("x\n")
    bin_ = root / ".venv" / "bin"
    bin_.mkdir(parents=True)
    (root / ".venv" / "share").mkdir()
    (bin_ / "python").write_text(FAKE_PYTHON)
    (bin_ / "python").chmod(0o755)
    tools = tmp / "fake_bin"
    tools.mkdir()
    (tools / "cmake").write_text(FAKE_CMAKE)
    (tools / "cmake").chmod(0o755)
    return root


def run_timed(root: Path, **env: str) -> tuple[int, list[tuple[float, str]]]:
    """Run bootstrap.sh of `root`; return its exit code and (s since start, line) of stderr."""
    environ = {**os.environ, "BOOTSTRAP_TICK_S": str(TICK_S), "FAKE_PIP_S": "3",
               "FAKE_CMAKE_S": "2.5",
               "PATH": f"{root.parent / 'fake_bin'}{os.pathsep}{os.environ['PATH']}", **env}
    t0 = time.monotonic()
    proc = subprocess.Popen(["bash", str(root / "tools" / "bootstrap.sh")], env=environ,
                            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    assert proc.stderr is not None
    lines = [(time.monotonic() - t0, line.rstrip("\n")) for line in proc.stderr]
    return proc.wait(timeout=60), lines


def test_a_line_at_least_every_tick_through_pip_and_the_build(tmp_path):
    code, lines = run_timed(skeleton(tmp_path))
    text = "\n".join(f"{t:5.1f} {line}" for t, line in lines)
    assert code == 0, text
    times = [0.0] + [t for t, _ in lines]
    gaps = [b - a for a, b in itertools.pairwise(times)]
    assert max(gaps) <= TICK_S + SLACK_S, text
    # the heartbeat quotes pip's and the build's latest progress
    assert any(re.search(r"bootstrap:   pip: \d+ s \.\.\. Collecting rclpy", line)
               for _, line in lines), text
    assert any("cmake build: " in line and "[ 50%] Building" in line for _, line in lines), text
    assert lines[-1][1] == "bootstrap: .venv ready", text


def test_a_failing_step_shows_its_output_and_its_name(tmp_path):
    code, lines = run_timed(skeleton(tmp_path), FAKE_PIP_FAIL="1")
    text = "\n".join(line for _, line in lines)
    assert code != 0
    assert "ERROR: No matching distribution found for rclpy" in text
    assert "bootstrap: FAILED at step: pip install requirements/ros.txt" in text


def test_the_default_tick_is_under_ten_seconds():
    found = re.search(r'BOOTSTRAP_TICK_S="\$\{BOOTSTRAP_TICK_S:-(\d+)\}"',
                      (ROOT / "tools" / "long_step.sh").read_text())
    assert found is not None and int(found.group(1)) < 10


"""Arguments rcl itself cannot parse: an empty `-p x:=`, a list of mixed
types, a corrupt params file. The node exits 2 with one `error:` line of ours, no traceback.
(rcl fails before any DDS participant exists; the environment is loopback-only anyway.)"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

FILTER = Path(sys.prefix) / "lib" / "ssa_fusion" / "filter"


@pytest.mark.parametrize("ros_args", [
    ["-p", "q:="],
    ["-p", "p0_sigma:=[1, 2.0, 3, 4, 5, 6]"],
    ["--params-file", "CORRUPT"],
])
def test_arguments_rcl_cannot_parse_exit_2_with_one_error_line(tmp_path, ros_args):
    corrupt = tmp_path / "corrupt.yaml"
    corrupt.write_text("filter:\n  ros__parameters: [\n")
    args = [str(corrupt) if a == "CORRUPT" else a for a in ros_args]
    env = {**os.environ, "ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST", "ROS_DOMAIN_ID": "99"}
    r = subprocess.run([str(FILTER), "--ros-args", *args], capture_output=True, text=True,
                       timeout=60, env=env)
    assert r.returncode == 2, r
    ours = [line for line in r.stderr.splitlines() if line.startswith("error:")]
    assert len(ours) == 1 and "cannot start" in ours[0], r.stderr
    assert "Traceback" not in r.stderr


@pytest.mark.parametrize("keys", [30_000, 1_000_000])
def test_a_params_file_with_a_million_keys_is_refused_before_rcl_reads_it(tmp_path, keys):
    """rcl's parser is quadratic in the keys (a million took most of an hour, deaf to
    SIGTERM): a file over 20,000 lines or 1 MB is refused at once, exit 2, one line."""
    big = tmp_path / "big.yaml"
    big.write_text("filter:\n  ros__parameters:\n"
                   + "".join(f"    k{i}: {i}\n" for i in range(keys)))
    env = {**os.environ, "ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST", "ROS_DOMAIN_ID": "99"}
    r = subprocess.run([str(FILTER), "--ros-args", "--params-file", str(big)],
                       capture_output=True, text=True, timeout=60, env=env)
    assert r.returncode == 2, r
    ours = [line for line in r.stderr.splitlines() if line.startswith("error:")]
    assert len(ours) == 1 and str(big) in ours[0] and len(ours[0]) < 400, r.stderr
    assert ("lines" if keys == 30_000 else "bytes") in ours[0]
    assert "Traceback" not in r.stderr

"""CLI input errors are one clear line and exit 2: a ROS domain id out
of range, and a file named .mcap that is not an MCAP file."""

from __future__ import annotations

import subprocess
import sys

import pytest

from ssa_fusion.apps.args import domain_id
from ssa_fusion.ros import bagio


def _cli(*args: str, cwd=None) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "ssa_fusion.apps.cli", *args], cwd=cwd,
                          capture_output=True, text=True, timeout=120)


def test_domain_id_out_of_range_is_refused_before_anything_starts(tmp_path):
    import argparse

    assert domain_id("0") == 0 and domain_id("232") == 232
    for bad in ("233", "999", "-1", "x"):
        with pytest.raises(argparse.ArgumentTypeError):
            domain_id(bad)
    out = tmp_path / "run"
    r = _cli("live", "--domain-id", "999", "--out", str(out))
    assert r.returncode == 2, r
    assert "--domain-id: 999 is outside 0..232" in r.stderr
    assert "Traceback" not in r.stderr and not out.exists()  # no empty run directory


@pytest.mark.parametrize("layout", ["bare", "in_dir"])
def test_a_text_file_named_mcap_is_not_an_mcap(tmp_path, layout):
    f = (tmp_path / "x.mcap") if layout == "bare" else (tmp_path / "bag" / "bag.mcap")
    f.parent.mkdir(exist_ok=True)
    f.write_text("hello, not a bag\n")
    target = f if layout == "bare" else f.parent
    with pytest.raises(bagio.BagError, match="not an MCAP file"):
        list(bagio.read_bag(target))
    r = _cli("report", str(target), "--out", str(tmp_path / "rep"))
    assert r.returncode == 2, r
    assert "not an MCAP file" in r.stderr and "withheld" not in r.stderr, r.stderr
    assert "Traceback" not in r.stderr


def test_surrogate_params_of_a_catalog_run_are_checked_before_anything_starts(tmp_path):
    import argparse

    from ssa_fusion.apps.live_catalog import catalog_surrogate_params

    ok = argparse.Namespace(surrogate_param=["min_span=21600", "fit_budget=0.25",
                                             "min_anchors=3"])
    assert catalog_surrogate_params(ok) == {"min_span": 21600.0, "fit_budget": 0.25,
                                    "min_anchors": 3}  # an integer for seconds: a double
    assert type(catalog_surrogate_params(ok)["min_span"]) is float
    out = tmp_path / "run"
    for bad, says in (("min_spam=1", "catalog_surrogate has no parameter 'min_spam'"),
                      ("shards=2", "shards come from --shards"),
                      ("min_span", "expected NAME=VALUE")):
        r = _cli("live", "--catalog", "config/catalogs/sample.tle", "--surrogate-param", bad,
                 "--out", str(out))
        assert r.returncode == 2, r
        assert says in r.stderr and "Traceback" not in r.stderr
        assert not out.exists()


def test_a_catalog_run_ending_after_2038_is_refused_before_anything_starts(tmp_path):
    """`live --catalog --start 2038-01-19T00:00:00Z --duration 6` ran into epochs a ROS 2
    stamp cannot hold; now one line names the run's end, exit 2, nothing made."""
    out = tmp_path / "run"
    r = _cli("live", "--catalog", "config/catalogs/sample.tle", "--start",
             "2038-01-19T00:00:00Z", "--duration", "6", "--out", str(out))
    assert r.returncode == 2, r
    assert "the run's end (start + duration) 2038-01-19T06:00:00.000Z is outside" in r.stderr
    assert "Traceback" not in r.stderr and not out.exists()

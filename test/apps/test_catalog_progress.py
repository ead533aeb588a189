"""The commands that read a catalog say how far the read has got (`progress_lines`), and a
catalog they cannot read is one error line before anything starts."""

from __future__ import annotations

import argparse
import io
import subprocess
import sys
from pathlib import Path

from sgp4.io import compute_checksum

from ssa_fusion.apps import ccsds, live_catalog
from ssa_fusion.apps.progress_lines import ProgressLines

ROOT = Path(__file__).resolve().parents[2]
L1 = "1 25544U 98067A   20001.82137887  .00016717  00000-0  10270-3 0  912"
L2 = "2 25544  51.6392  96.6358 0005156  88.7140 271.4601 15.49497216  606"


def catalog_text(n: int) -> str:
    """A 3LE of `n` objects (NORAD numbers 1..n)."""
    out = []
    for i in range(1, n + 1):
        a, b = (f"{line[:2]}{i:05d}{line[7:68]}" for line in (L1, L2))
        out += [f"OBJECT {i}", a + str(compute_checksum(a)), b + str(compute_checksum(b))]
    return "\n".join(out) + "\n"


def _cli(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "ssa_fusion.apps.cli", *args], cwd=ROOT,
                          capture_output=True, text=True, timeout=120)


def test_live_catalog_reads_its_catalog_once_saying_how_far_it_got(tmp_path):
    path = tmp_path / "c.tle"
    path.write_text(catalog_text(9000))
    lines = ProgressLines(f"live: catalog {path}", "objects", every_s=0.0, stream=io.StringIO())
    args = argparse.Namespace(catalog=path, synthetic=0, objects=100, seed=1)
    assert len(live_catalog.entries_of(args, lines.reading)) == 100
    said = lines.stream.getvalue().splitlines()
    size = path.stat().st_size / 1e6
    assert len(said) == 9000 // 4096 + 1  # every PROGRESS_EVERY objects, and at the end
    assert said[-1].startswith(f"live: catalog {path}: read {size:.1f} of {size:.1f} MB "
                               f"(100%), 9000 objects, ")
    assert said[-1].endswith(" s")
    quiet = ProgressLines("live", "objects", stream=io.StringIO())  # every 5 s: none so soon
    live_catalog.entries_of(args, quiet.reading)
    assert quiet.stream.getvalue() == ""


def test_the_import_keeps_its_progress_lines():
    progress = ccsds.ImportProgress(every_s=0.0, stream=io.StringIO())
    progress.reading(2_500_000, 10_000_000, 123)
    progress.total = 40
    progress.writing(10)
    assert progress.stream.getvalue().splitlines() == [
        "import tdm: read 2.5 of 10.0 MB (25%), 123 measurements, 0 s",
        "import tdm: wrote 10 of 40 measurements to the bag (25%), 0 s"]


def test_a_catalog_wrong_deep_inside_is_one_line_before_the_run_starts(tmp_path):
    text = catalog_text(3000)
    bad = text.splitlines()[3 * 2500 - 1]  # line 2 of object 2,500: line 7,500
    path = tmp_path / "c.tle"
    path.write_text(text.replace(bad, bad[:10] + "x" + bad[11:]))
    out = tmp_path / "run"
    for option in ("--catalog", "--elements"):
        # a catalog run keeps going past a bad set unless --strict (test_skipped_sets);
        # one object's element set is the run: it always refuses
        extra = ["--scenario", "iss_network"] if option == "--elements" else ["--strict"]
        r = _cli("live", option, str(path), *extra, "--out", str(out))
        assert r.returncode == 2, r
        assert r.stderr.strip() == (f"error: {path}:7500: TLE line 2, column 11: 'x' does not "
                                    f"fit the TLE layout ('N' there)"), r.stderr
        assert not out.exists()  # no empty run directory

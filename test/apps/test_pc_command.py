"""`ssa-fusion pc FILE...`: the table, ``--json``, and one line per bad file with exit 1."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
from cara_cases import cara_cdm_dir
from cdm_cases import own_conjunction

from ssa_fusion.apps import cli
from ssa_fusion.formats.ccsds.cdm_out import write_cdm


def test_json_one_object_per_message_and_bad_files_one_line_each(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    c = own_conjunction()
    good = [write_cdm(c, tmp_path / "a.cdm"), write_cdm(c, tmp_path / "b.xml", "xml")]
    bad = tmp_path / "bad.cdm"
    bad.write_text("CCSDS_CDM_VERS = 1.0\nTCA = soon\n")
    code = cli.main(["pc", "--json", str(good[0]), str(bad), str(good[1]),
                     str(tmp_path / "missing.cdm")])
    out, err = capsys.readouterr()
    assert code == 1
    rows = [json.loads(line) for line in out.splitlines()]
    assert [r["file"] for r in rows] == [str(p) for p in good]
    for r in rows:
        assert set(r) >= {"file", "message_id", "tca", "miss_m", "pc", "method", "message_pc"}
        assert r["pc"] == pytest.approx(c.result.pc, rel=1e-9)
        assert r["message_pc"] == pytest.approx(c.result.pc, rel=1e-6)
        assert r["miss_m"] == pytest.approx(c.result.miss_km * 1e3)
        assert r["method"] == "FOSTER-1992" and abs(r["rel_diff"]) < 1e-6
    lines = err.splitlines()
    assert len(lines) == 2 and str(bad) in lines[0] and "missing.cdm" in lines[1]


def test_table_and_hbr_override(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    c = own_conjunction()
    path = write_cdm(c, tmp_path / "a.cdm")
    assert cli.main(["pc", str(path)]) == 0
    table = capsys.readouterr().out.splitlines()
    assert table[0].split()[:3] == ["message", "TCA", "(UTC)"] and len(table) == 3
    assert f"{c.result.pc:.4e}" in table[2] and "+0.000%" in table[2]
    assert cli.main(["pc", "--json", "--hbr", "30", str(path)]) == 0
    doubled = json.loads(capsys.readouterr().out)
    assert 3.0 < doubled["pc"] / c.result.pc < 4.1  # ~ HBR² for a small circle


def test_monte_carlo_method(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    c = own_conjunction()
    path = write_cdm(c, tmp_path / "a.cdm")
    assert cli.main(["pc", "--json", "--method", "mc", "--samples", "20000", str(path)]) == 0
    row = json.loads(capsys.readouterr().out)
    assert row["method"] == "MONTE_CARLO-3D" and row["samples"] == 20000
    assert abs(row["pc"] - c.result.pc) < 4 * math.sqrt(c.result.pc / 20000)


@pytest.mark.skipif(cara_cdm_dir() is None, reason="shared CARA CDMs not present")
def test_cara_cdms_through_the_command(capsys: pytest.CaptureFixture[str]) -> None:
    d = cara_cdm_dir()
    assert d is not None
    files = sorted(str(p) for p in d.glob("*.cdm"))
    assert cli.main(["pc", "--json", *files]) == 0
    rows = [json.loads(line) for line in capsys.readouterr().out.splitlines()]
    assert len(rows) == len(files)
    logs = np.array([r["log10_pc"] for r in rows])
    theirs = np.log10([r["message_pc"] for r in rows])
    assert np.max(np.abs(logs - theirs)) < math.log10(1.01)

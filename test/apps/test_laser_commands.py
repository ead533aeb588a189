"""The commands on a real laser-ranging bag (LAGEOS-2, `import crd` of the shared files):
`replay --offline --smooth`, `report`, `export oem --predict-until`, each judged against
something it did not make: the filter's NIS against its chi-square band, the fit's residuals
and the orbit against the CPF in the report's JSON (the issue's bounds), the predicted OEM
against the CPF where they overlap; and their refusals in one line."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from realdata import CPF, CRD, ECCENTRICITIES, STATIONS, lageos, needs_lageos

from ssa_fusion.apps import cli
from ssa_fusion.core.motion.tabulated import TabulatedOrbit
from ssa_fusion.formats.ccsds.common import ndm
from ssa_fusion.formats.ccsds.oem import oem_states
from ssa_fusion.formats.reference_orbit import read_reference
from ssa_fusion.ros import bagio, messages
from ssa_fusion.ros.topics import TOPIC_ESTIMATE, TOPIC_SMOOTHED

pytestmark = needs_lageos


def _import(bag, reference: bool = True) -> None:
    ref = ["--reference", str(lageos(CPF))] if reference else []
    assert cli.main(["import", "crd", str(lageos(CRD)), "--stations", str(lageos(STATIONS)),
                     "--eccentricities", str(lageos(ECCENTRICITIES)), *ref,
                     "--bag", str(bag)]) == 0


@pytest.fixture(scope="module")
def replayed(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("laser")
    _import(tmp / "lageos2")
    assert cli.main(["replay", "--offline", "--smooth", str(tmp / "lageos2")]) == 0
    return tmp


def test_the_offline_replay_publishes_the_orbit_and_its_nis(replayed, capsys):
    got = list(bagio.read_bag(replayed / "lageos2_offline"))
    est = [messages.estimate_from_msg(m.msg) for m in got if m.topic == TOPIC_ESTIMATE]
    fused = [e for e in est if e.update_source == 1]
    assert len(fused) == 70 and len(est) > 700  # and predictions every 300 s between passes
    assert sum(m.topic == TOPIC_SMOOTHED for m in got) == 70
    assert all(np.all(np.linalg.eigvalsh(e.P) > 0) for e in fused)
    nis = np.array([e.nis for e in fused])
    assert np.mean((nis >= 0.00098) & (nis <= 5.024)) >= 0.9


def test_the_report_judges_the_orbit_without_truth(replayed, capsys):
    assert cli.main(["report", str(replayed / "lageos2_offline")]) == 0
    out = capsys.readouterr().out
    assert "| 7941 |" in out and "NIS (the bag's filter" in out
    rep = json.loads((replayed / "lageos2_offline_report" / "report.json").read_text())
    assert rep["ranges"] == 70 and rep["fit"]["status"] == "converged"
    assert rep["fit"]["residual_rms_cm"] <= 25.0  # the bound (measured 1.6)
    assert set(rep["fit"]["biases_cm"]) == {"7090", "7119", "7825", "7941"}
    assert sum(p["count"] for p in rep["passes"]) == 70 and len(rep["passes"]) == 7
    assert rep["against_reference"]["batch fit"]["rms_3d_m"] <= 0.5  # (measured 0.29)
    assert rep["against_reference"]["batch fit"]["count"] == 288
    assert rep["nis"]["inside"] >= 0.9


def test_the_predicted_oem_meets_the_cpf_where_they_overlap(replayed, capsys):
    oem = replayed / "pred.oem"
    assert cli.main(["export", "oem", str(replayed / "lageos2"), "--predict-until",
                     "2016-02-14T06:00:00", "--out", str(oem)]) == 0
    assert "the fit of 70 laser ranges (converged)" in capsys.readouterr().out
    states = oem_states(ndm()[0].from_path(oem))["22195"]
    t = np.array([s.t for s in states])
    assert t[0] == pytest.approx(1455406617.0067, abs=1e-3)  # the last range's epoch
    assert np.all(np.diff(t) > 0) and t[-1] == pytest.approx(1455429600.0)
    ref = read_reference(lageos(CPF))
    table = TabulatedOrbit(ref.t, ref.x[:, :3])
    both = table.covers(t)
    assert 15 <= both.sum() <= 20  # 23:37 .. 23:55, the CPF's last
    x = np.array([s.x[:3] for s in states])[both]
    d = np.linalg.norm(x - table.states(t[both])[:, :3], axis=1) * 1000
    assert d.max() < 0.5


def test_refusals_are_one_line(tmp_path, capsys):
    _import(tmp_path / "no_reference", reference=False)
    capsys.readouterr()
    assert cli.main(["replay", "--offline", str(tmp_path / "no_reference")]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("error: laser ranges alone give no initial orbit") and "\n" not in err
    sample = Path(__file__).resolve().parents[2] / "bags" / "sample_iss_j2_rae"
    assert cli.main(["export", "oem", str(sample), "--predict-until", "2030-01-01",
                     "--out", str(tmp_path / "x.oem")]) == 2
    err = capsys.readouterr().err.strip()
    assert "only laser ranges" in err and "\n" not in err
    assert not (tmp_path / "x.oem").exists()

"""`ssa-fusion import crd`: the real LAGEOS-2 normal points into a bag (LASER_RANGE
measurements, Meteo messages, the stations on /ssa/config, the CPF on /ssa/reference), read
back message by message against the files; its refusals are one line and leave no bag."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np
import pytest
from realdata import CPF, CRD, ECCENTRICITIES, STATIONS, lageos, needs_lageos

from ssa_fusion.apps import cli
from ssa_fusion.core.base import types
from ssa_fusion.core.base.constants import C_KM_S
from ssa_fusion.core.base.quoting import MAX_MESSAGE
from ssa_fusion.core.earth.frames import itrs_to_gcrs
from ssa_fusion.formats.ilrs.cpf import read_cpf
from ssa_fusion.ros import bagio, messages
from ssa_fusion.ros.laser_config import recorded_laser
from ssa_fusion.ros.topics import TOPIC_CONFIG, TOPIC_MEASUREMENT, TOPIC_METEO, TOPIC_REFERENCE

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "formats"))
from crd_samples import V1
from test_sinex_reader import GOOD as SINEX


def _read(bag):
    out: dict[str, list] = {}
    for m in bagio.read_bag(bag):
        out.setdefault(m.topic, []).append(m)
    return out


@needs_lageos
def test_the_real_data_into_a_bag(tmp_path, capsys):
    bag = tmp_path / "lageos"
    assert cli.main(["import", "crd", str(lageos(CRD)), "--stations", str(lageos(STATIONS)),
                     "--eccentricities", str(lageos(ECCENTRICITIES)), "--reference",
                     str(lageos(CPF)), "--bag", str(bag)]) == 0
    line = capsys.readouterr().out.strip()
    assert line.startswith("import crd: 70 laser ranges of 22195 (lageos2) from 4 station(s) "
                           "(7090 YARL 12, 7119 HA4T 27, 7825 STL3 17, 7941 MATM 14); 135 "
                           "meteorological records (0 point(s) without"), line
    got = _read(bag)
    assert {k: len(v) for k, v in got.items()} == {
        TOPIC_CONFIG: 1, TOPIC_MEASUREMENT: 70, TOPIC_METEO: 135, TOPIC_REFERENCE: 288}
    ms = [messages.measurement_from_msg(m.msg) for m in got[TOPIC_MEASUREMENT]]
    assert all(m.kind == types.Kind.LASER_RANGE and m.object_id == "22195" for m in ms)
    assert [m.t for m in ms] == sorted(m.t for m in ms)
    # Yarragadee's first: 11 49382.400562600000 0.039237325685 std 2 (transmit epoch)
    y = next(m for m in ms if m.frame_id == "7090")
    assert y.t == pytest.approx(1455321600 + 49382.4005626, abs=1e-6)
    assert y.z[0] == pytest.approx(0.5 * C_KM_S * 0.039237325685, abs=1e-12)
    assert got[TOPIC_MEASUREMENT][0].msg.z[1:].tolist() == [0.0, 0.0]  # one channel, in m:
    assert got[TOPIC_MEASUREMENT][0].msg.covariance[0] == pytest.approx(0.005**2)
    w = messages.meteo_from_msg(next(m.msg for m in got[TOPIC_METEO]
                                     if m.msg.header.frame_id == "7090"))
    assert (w.pressure_hpa, w.temperature_k, w.humidity_pct) == pytest.approx((983.7, 301.4, 24))
    # "20 49382.401 ...", written with the point at 49382.4005626: stamped 1 ms earlier, first
    assert w.t == pytest.approx(1455321600 + 49382.401 - 0.001, abs=1e-6) and w.t < y.t
    assert next(m.msg for m in got[TOPIC_METEO]).pressure == pytest.approx(92750.0)  # Pa
    config = recorded_laser([got[TOPIC_CONFIG][0].msg.data])
    st = config.stations["7090"]
    np.testing.assert_allclose(st.position_km * 1e3, [-2389007.53398029, 5043329.44749889,
                                                      -3078524.22322662], rtol=0, atol=1e-8)
    np.testing.assert_allclose(st.eccentricity_une_km * 1e3, [3.1827, -0.0064, 0.0194])
    assert st.wavelength_um == pytest.approx(0.532) and st.name == "YARL"
    assert config.stations["7825"].wavelength_um == pytest.approx(0.5321)
    assert config.com_km == {"22195": pytest.approx(0.251e-3)}
    assert config.bias_sigma_km["7941"] == pytest.approx(1e-3)
    raw = json.loads(got[TOPIC_CONFIG][0].msg.data)["laser_ranging"]
    assert raw["stations"]["7090"]["frame"] == "itrf"
    assert raw["reference"]["states"] == 288
    # the reference: the CPF's ITRF positions in the GCRF, their velocities derived
    cpf = read_cpf(lageos(CPF))
    ref = [messages.estimate_from_msg(m.msg) for m in got[TOPIC_REFERENCE]]
    assert all(m.msg.header.frame_id == "gcrf" for m in got[TOPIC_REFERENCE])
    np.testing.assert_allclose(ref[5].x[:3], itrs_to_gcrs(cpf.position_km[5], cpf.t[5]),
                               atol=1e-9)
    speed = np.linalg.norm(ref[5].x[3:])
    assert 5.6 < speed < 5.8 and not ref[5].P.any()  # LAGEOS: 5.7 km/s, no covariance
    # replayed, reported and predicted: test_laser_commands.py


def test_a_small_import_and_its_refusals(tmp_path, capsys):
    crd, snx = tmp_path / "a.npt", tmp_path / "s.snx"
    crd.write_text(V1)
    snx.write_text(SINEX)
    bag = tmp_path / "bag"
    assert cli.main(["import", "crd", str(crd), "--stations", str(snx), "--bag", str(bag),
                     "--sigma", "0.02", "--bias-sigma", "0.5"]) == 0
    assert "2 laser ranges of 8820 (lageos1) from 1 station(s) (7001 TEST 2)" in \
        capsys.readouterr().out
    got = _read(bag)
    config = recorded_laser([got[TOPIC_CONFIG][0].msg.data])
    assert not config.stations["7001"].eccentricity_une_km.any()  # no --eccentricities
    assert config.bias_sigma_km["7001"] == pytest.approx(0.5e-3)
    assert got[TOPIC_MEASUREMENT][0].msg.covariance[0] == pytest.approx(0.02**2)

    def refused(args, expected, out=tmp_path / "refused"):
        existed = out.exists()
        assert cli.main(["import", "crd", *args, "--bag", str(out)]) == 2
        err = capsys.readouterr().err.strip()
        assert err.startswith("error: ") and "\n" not in err and len(err) <= MAX_MESSAGE + 7
        assert expected in err, err
        assert out.exists() == existed

    refused([str(crd), "--stations", str(snx)], "exists already", out=bag)
    other = tmp_path / "b.npt"
    other.write_text(V1.replace("7603901", "9999901"))
    refused([str(other), "--stations", str(snx)], "no centre-of-mass offset known for "
                                                  "target 9999901")
    nowhere = tmp_path / "c.npt"
    nowhere.write_text(V1.replace("7001", "7002"))
    refused([str(nowhere), "--stations", str(snx)], "no SOLUTION/ESTIMATE of station 7002")
    refused([str(crd), "--stations", str(crd)], ":1: not a SINEX file")
    refused([str(snx), "--stations", str(snx)], ":1: %=SNX: not a CRD file")
    refused([str(crd), "--stations", str(snx), "--reference", str(crd)],
            "neither a CPF (H1 first) nor a CCSDS OEM")
    refused([str(crd), "--stations", str(snx), "--sigma", "nan"], "--sigma nan")
    assert set(json.loads(got[TOPIC_CONFIG][0].msg.data)) == {"node", "laser_ranging"}

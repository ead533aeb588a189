"""Your own station, end to end: a sites file, a TDM of its radar, `import tdm --sites`,
`replay --offline --sites`, estimates that land on the orbit the TDM was computed from.

The TDM is written by hand here: range/azimuth/elevation of a fictional radar (not built in)
over its passes of a known SGP4 orbit, computed independently of ssa_fusion's frames and
measurement models: the `sgp4` library for the orbit (TEME), astropy (the IERS table
`core.earth.eop` uses too) for TEME -> GCRS/ITRS and for the WGS-84 site, the topocentric
geometry written out here with light time, Gaussian noise of the site's sigmas added.
"""

from __future__ import annotations

import contextlib
import io
import json
import math
import re
from pathlib import Path

import numpy as np
import pytest
from astropy import units as u
from astropy.coordinates import (
    GCRS,
    ITRS,
    TEME,
    CartesianDifferential,
    CartesianRepresentation,
    EarthLocation,
)
from astropy.time import Time
from astropy.utils import iers
from sgp4.api import WGS72, Satrec

from ssa_fusion.apps import cli, evaluate
from ssa_fusion.core.base import types
from ssa_fusion.formats.ccsds import common as ccsds_format
from ssa_fusion.ros import bagio

T0 = 1736035200.0  # 2025-01-05T00:00:00 UTC
SPAN_S = 3.0 * 3600.0  # two passes: ~0.9 h and ~2.6 h after T0, ~9.5 min each
CADENCE_S = 10.0
C_KM_S = 299792.458
SITE = {"id": "nordlys", "lat": 69.60, "lon": 19.20, "height_m": 110.0,
        "range_m": 20.0, "angle_deg": 0.02, "mask_deg": 10.0}
SITES_YAML = f"""\
# a fictional radar far north
sites:
  - id: {SITE['id']}
    latitude_deg: {SITE['lat']}
    longitude_deg: {SITE['lon']}
    height_m: {SITE['height_m']}
    type: radar
    noise: {{range_m: {SITE['range_m']}, azimuth_deg: {SITE['angle_deg']},
             elevation_deg: {SITE['angle_deg']}}}
    cadence_s: {CADENCE_S}
    min_elevation_deg: {SITE['mask_deg']}
"""


@pytest.fixture(scope="module", autouse=True)
def astropy_offline():
    """astropy with the IERS-A table of astropy-iers-data: the EOP `core.earth.eop` uses."""
    iers.conf.auto_download = False
    iers.conf.auto_max_age = None
    iers.earth_orientation_table.set(iers.IERS_A.open(iers.IERS_A_FILE))


def orbit() -> Satrec:
    """An object at ~800 km, inclination 98.6 deg (SGP4 elements at T0, no drag)."""
    sat = Satrec()
    epoch_days = (T0 + 631152000.0) / 86400.0  # days since 1949-12-31 00:00 UTC
    no_kozai = 14.3 * 2 * math.pi / 1440.0  # 14.3 rev/day in rad/min
    sat.sgp4init(WGS72, "i", 99001, epoch_days, 0.0, 0.0, 0.0, 0.0012,
                 math.radians(90.0), math.radians(98.6), math.radians(30.0), no_kozai,
                 math.radians(180.0))
    return sat


def teme_km(sat: Satrec, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """TEME position and velocity (n, 3) km, km/s at Unix stamps `t` (UTC)."""
    jd = Time(t, format="unix", scale="utc").jd
    jd1 = np.floor(jd)
    e, r, v = sat.sgp4_array(jd1, jd - jd1)
    assert not e.any()
    return np.asarray(r), np.asarray(v)


def gcrs_km(sat: Satrec, t: np.ndarray) -> np.ndarray:
    """True GCRS state (n, 6) km, km/s by astropy's TEME -> GCRS."""
    r, v = teme_km(sat, t)
    obstime = Time(t, format="unix", scale="utc")
    rep = CartesianRepresentation(r.T * u.km, differentials=CartesianDifferential(
        v.T * u.km / u.s))
    g = TEME(rep, obstime=obstime).transform_to(GCRS(obstime=obstime))
    pos = g.cartesian.xyz.to_value(u.km).T
    vel = g.cartesian.differentials["s"].d_xyz.to_value(u.km / u.s).T
    return np.hstack([pos, vel])


def observed(sat: Satrec, t: np.ndarray) -> np.ndarray:
    """Range (km), azimuth, elevation (deg) of the object from the site at `t`, light time in.

    The object where it was when the light left it (GCRS at t - tau), turned into the ITRS
    of the reception epoch, minus the WGS-84 site (astropy), in the site's east/north/up.
    """
    site = EarthLocation.from_geodetic(SITE["lon"] * u.deg, SITE["lat"] * u.deg,
                                       SITE["height_m"] * u.m, ellipsoid="WGS84")
    s = np.array([site.x.to_value(u.km), site.y.to_value(u.km), site.z.to_value(u.km)])
    obstime = Time(t, format="unix", scale="utc")
    tau = np.zeros_like(t)
    for _ in range(3):
        emitted = gcrs_km(sat, t - tau)[:, :3]
        itrs = GCRS(CartesianRepresentation(emitted.T * u.km), obstime=obstime).transform_to(
            ITRS(obstime=obstime)).cartesian.xyz.to_value(u.km).T
        rho = itrs - s
        tau = np.linalg.norm(rho, axis=1) / C_KM_S
    lat, lon = math.radians(SITE["lat"]), math.radians(SITE["lon"])
    east = np.array([-math.sin(lon), math.cos(lon), 0.0])
    north = np.array([-math.sin(lat) * math.cos(lon), -math.sin(lat) * math.sin(lon),
                      math.cos(lat)])
    up = np.array([math.cos(lat) * math.cos(lon), math.cos(lat) * math.sin(lon),
                   math.sin(lat)])
    rng = np.linalg.norm(rho, axis=1)
    az = np.degrees(np.arctan2(rho @ east, rho @ north)) % 360.0
    el = np.degrees(np.arcsin((rho @ up) / rng))
    return np.column_stack([rng, az, el])


def write_tdm(path: Path, t: np.ndarray, z: np.ndarray) -> Path:
    """A KVN TDM of one AZEL segment: RANGE (km), ANGLE_1/ANGLE_2 (deg) at epochs `t`."""
    rows = []
    for ti, (r, az, el) in zip(t.tolist(), z.tolist(), strict=True):
        epoch = ccsds_format.format_epoch(ti)
        rows += [f"RANGE = {epoch} {r!r}", f"ANGLE_1 = {epoch} {az!r}",
                 f"ANGLE_2 = {epoch} {el!r}"]
    meta = ("TIME_SYSTEM = UTC\nPARTICIPANT_1 = NORDLYS\nPARTICIPANT_2 = SAT-99001\n"
            "PATH = 2,1,2\nANGLE_TYPE = AZEL\nRANGE_UNITS = km\n")
    path.write_text("CCSDS_TDM_VERS = 2.0\nCREATION_DATE = 2025-01-05T00:00:00\n"
                    "ORIGINATOR = hand\nMETA_START\n" + meta + "META_STOP\nDATA_START\n"
                    + "\n".join(rows) + "\nDATA_STOP\n")
    return path


@pytest.fixture(scope="module")
def passes(tmp_path_factory) -> tuple[Path, Path, Satrec, np.ndarray]:
    """(TDM, sites file, orbit, measurement epochs): the radar's two passes, with noise."""
    d = tmp_path_factory.mktemp("own_sites")
    sat = orbit()
    t = T0 + np.arange(0.0, SPAN_S, CADENCE_S)
    z = observed(sat, t)
    seen = z[:, 2] > SITE["mask_deg"]
    t, z = t[seen], z[seen]
    rng = np.random.default_rng(7)
    sigma = np.array([SITE["range_m"] / 1000.0, SITE["angle_deg"], SITE["angle_deg"]])
    z = z + rng.normal(size=z.shape) * sigma
    sites = d / "sites.yaml"
    sites.write_text(SITES_YAML)
    return write_tdm(d / "nordlys.tdm", t, z), sites, sat, t


def test_a_tdm_of_your_own_radar_replays_onto_its_orbit(passes, tmp_path, capsys):
    """`import tdm --sites` then `replay --offline --sites`: the filter (the real-sky
    filter, two-body + J2, for a bag without settings) initialises on the first pass and
    fuses the second.

    Bound: at the second pass's fused epochs the position error has a median under 0.2 km
    and a maximum under 0.5 km. One measurement's angle noise (0.02 deg) is 0.35-0.9 km
    across the line of sight at the pass's ranges (1000-2500 km); the filter fuses ~57 of
    them on top of the first pass's orbit, and its J2 model differs from SGP4's by well
    under 0.1 km over the 1.7 h between the passes. Measured over six noise seeds: median
    0.03-0.08 km, maximum 0.13-0.27 km.
    """
    tdm, sites, sat, t = passes
    bag = tmp_path / "bag"
    assert cli.main(["import", "tdm", str(tdm), "--sites", str(sites), "--bag", str(bag)]) == 0
    out = capsys.readouterr().out
    assert f"{len(t)} range/az/el measurements of SAT-99001 from nordlys" in out, out
    ms = evaluate.load(bag).measurements
    assert {m.frame_id for m in ms} == {"nordlys"}
    sigma = [SITE["range_m"] / 1000.0, math.radians(SITE["angle_deg"]),
             math.radians(SITE["angle_deg"])]  # the site's noise: the TDM gives none
    np.testing.assert_allclose(ms[0].R, np.diag(np.square(sigma)), rtol=1e-12)

    replayed = tmp_path / "replayed"
    assert cli.main(["replay", str(bag), "--offline", "--sites", str(sites),
                     "--out", str(replayed)]) == 0
    out = capsys.readouterr().out
    assert (f"radar, from the data ({len(t)} range/az/el from nordlys; --filter "
            "radar|optical|network|position or --params-file choose another): the real-sky "
            "filter for the stations of its measurements (nordlys)") in out, out
    fused = [e for e in evaluate.load(replayed).estimates
             if e.update_source == types.UpdateSource.SENSOR]
    second = [e for e in fused if e.t > T0 + 2.0 * 3600.0]
    assert len(second) > 30, len(second)
    truth = gcrs_km(sat, np.array([e.t for e in second]))
    err = np.linalg.norm(np.array([e.x[:3] for e in second]) - truth[:, :3], axis=1)
    assert np.median(err) < 0.2 and err.max() < 0.5, (np.median(err), err.max())

    # without the sites file the bag's station is unknown: refused in one line with the fix
    assert cli.main(["replay", str(bag), "--offline", "--out", str(tmp_path / "no_sites")]) == 2
    err = capsys.readouterr().err
    assert err == ("error: station id(s) nordlys are neither built in nor in a sites file: "
                   "define them in one (docs/SITES.md) and give it with --sites\n"), err
    assert not (tmp_path / "no_sites").exists()


def test_import_without_the_sites_file_is_refused_with_one_line(passes, tmp_path, capsys):
    tdm, *_ = passes
    assert cli.main(["import", "tdm", str(tdm), "--bag", str(tmp_path / "bag")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith(f"error: {tdm}:6: segment 1: "), err
    assert ("participants NORDLYS, SAT-99001: need one known station (altair, calar_alto, "
            "columbus") in err
    assert "a station of your own: --sites FILE" in err
    assert not (tmp_path / "bag").exists()


@pytest.fixture(scope="module")
def replayed(passes, tmp_path_factory) -> tuple[Path, Path]:
    """(imported bag, its `replay --offline --smooth --sites`): estimates, no truth."""
    tdm, sites, *_ = passes
    d = tmp_path_factory.mktemp("own_report")
    with contextlib.redirect_stdout(io.StringIO()):
        assert cli.main(["import", "tdm", str(tdm), "--sites", str(sites), "--bag",
                         str(d / "bag")]) == 0
        assert cli.main(["replay", str(d / "bag"), "--offline", "--smooth", "--sites",
                         str(sites), "--out", str(d / "replayed")]) == 0
    return d / "bag", d / "replayed"


def test_report_on_measurements_without_estimates_says_to_replay_first(passes, replayed,
                                                                       tmp_path, capsys):
    """The imported bag holds measurements only: nothing to judge yet."""
    bag, _ = replayed
    assert cli.main(["report", str(bag), "--out", str(tmp_path / "report")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith(f"error: {bag}: the bag has no "
                                                   f"/ssa/truth messages"), err
    assert f"run `ssa-fusion replay {bag} --offline --smooth` (add --sites FILE" in err
    assert not (tmp_path / "report").exists()


def test_report_on_your_own_radar_residuals_nis_sigma_and_passes(passes, replayed, tmp_path,
                                                                 capsys, monkeypatch):
    """`report --sites` on the replayed bag (no truth): exit 0, three readable plots, the
    passes table and the consistency numbers.

    Bounds, for a consistent filter on this noise (the site's sigmas, seed 7): the NIS of
    the ~115 fused measurements lies in its 95 % χ²(3) band for a fraction in [0.85, 0.99]
    (binomial with p = 0.95: a standard deviation of 2 %; 0.85 is five below, and above 0.99
    a too large covariance would show); the RMS of the residuals normalised by their
    innovation σ (~345 values: sampling spread ~0.04) is within [0.75, 1.25] (measured 0.90;
    the filter's J2 model differs from SGP4's, its process noise absorbs that). The
    recomputed innovations reproduce the filter's published NIS to 1e-6 relative. Two
    passes of nordlys, each with all its measurements counted.
    """
    from plot_checks import assert_readable  # test/apps on sys.path

    from ssa_fusion.apps import report_figures

    _, sites, _, t = passes
    _, bag = replayed
    drawn = {}
    saved = report_figures.save

    def keep(fig, path, dpi=100):
        drawn[Path(path).name] = fig
        saved(fig, path, dpi)

    monkeypatch.setattr(report_figures, "save", keep)
    out = tmp_path / "report"
    assert cli.main(["report", str(bag), "--sites", str(sites), "--out", str(out)]) == 0
    text = capsys.readouterr().out
    assert set(drawn) == {"residuals.png", "nis.png", "position_sigma.png"}, text
    for name, fig in drawn.items():
        assert (out / name).stat().st_size > 10_000
        assert_readable(name, fig)
        for ax in fig.get_axes():  # no line joins samples further apart than a pass break
            for line in ax.get_lines():
                if line.get_linestyle() in ("None", ""):
                    continue
                x = np.asarray(line.get_xdata(), float)
                ok = np.isfinite(x[:-1]) & np.isfinite(x[1:])
                assert (np.diff(x)[ok] <= 600.0 / 3600.0 + 1e-9).all(), (name, line.get_label())
    labels = [ax.get_ylabel() for ax in drawn["residuals.png"].get_axes()]
    assert labels == ["range [m]", "azimuth [arcsec]", "elevation [arcsec]"]
    sigma_legend = [x.get_text() for x in drawn["position_sigma.png"].get_axes()[0]
                    .get_legend().get_texts()]
    assert "smoothed (/ssa/estimate_smoothed)" in sigma_legend
    assert (out / "report.html").stat().st_size > 50_000 and (out / "report.json").exists()

    nis = re.search(r"NIS inside the 95 % χ² band \[0\.22, 9\.35\] \(3 dof\): ([\d.]+) % "
                    r"of (\d+) fused", text)
    assert nis, text
    fraction, n = float(nis[1]) / 100.0, int(nis[2])
    assert n > 100 and 0.85 <= fraction <= 0.99, (fraction, n)
    rms = re.search(r"residual RMS in units of the innovation σ: ([\d.]+) over all", text)
    assert rms and 0.75 <= float(rms[1]) <= 1.25, text
    agree = re.search(r"reproduces the filter's published one: passed \(([\d.e+-]+) relative\)",
                      text)
    assert agree and float(agree[1]) < 1e-6, text
    rows = [line.split("|")[1:-1] for line in text.splitlines()
            if re.match(r"\| \d+ \| ", line)]
    assert [r[1].strip() for r in rows] == ["nordlys", "nordlys"], text
    assert sum(int(r[4]) + int(r[5]) for r in rows) == len(t)
    assert all(float(r[6]) > SITE["mask_deg"] for r in rows)


def test_the_replayed_bag_records_its_settings_so_the_report_needs_no_sites_file(
        passes, replayed, tmp_path, capsys):
    """`replay --offline` writes the settings it used on /ssa/config (the sites' positions
    included), as the live nodes do: the report of its bag needs no --sites."""
    _, bag = replayed
    recorded = [json.loads(m.msg.data) for m in bagio.read_bag(bag, topics=["/ssa/config"])]
    assert sorted(r["node"] for r in recorded) == ["filter", "surrogate"]
    filt = next(r for r in recorded if r["node"] == "filter")
    assert filt["estimator"]["frame"] == "gcrf"
    assert [s["id"] for s in filt["estimator"]["sites"]] == ["nordlys"]
    out = tmp_path / "report"
    assert cli.main(["report", str(bag), "--out", str(out)]) == 0
    text = capsys.readouterr().out
    assert "settings: recorded with the bag (/ssa/config)" in text, text
    assert "no residuals for station" not in text, text
    assert (out / "residuals.png").exists() and (out / "nis.png").exists()
    # settings that do not know the station: its NIS and sigma, and why no residuals
    other = tmp_path / "report_columbus"
    assert cli.main(["report", str(bag), "--scenario", "iss_radar_columbus",
                     "--out", str(other)]) == 0
    text = capsys.readouterr().out
    assert ("no residuals for station(s) nordlys: the settings do not take them (give their "
            "sites file with --sites)") in text, text
    assert not (other / "residuals.png").exists() and (other / "nis.png").exists()


def test_a_replay_whose_orbit_determination_never_converges_says_so(passes, tmp_path, capsys):
    """Five measurements, where the real-sky filter's IOD takes seven of one pass."""
    tdm, sites, *_ = passes
    lines = tdm.read_text().splitlines()
    start = lines.index("DATA_START")
    short = tmp_path / "short.tdm"
    short.write_text("\n".join([*lines[:start + 1], *lines[start + 1:start + 16], "DATA_STOP",
                                ""]))
    bag = tmp_path / "bag"
    assert cli.main(["import", "tdm", str(short), "--sites", str(sites), "--bag", str(bag)]) == 0
    assert cli.main(["replay", str(bag), "--offline", "--sites", str(sites), "--out",
                     str(tmp_path / "out")]) == 1  # no estimate is no success
    err = capsys.readouterr().err
    assert ("error: no estimate: the initial orbit determination never converged (5 "
            "measurement(s) waited for it, 0 attempt(s) failed; it needs 7 real measurements "
            "of one station within 300 s (one pass)): a pass of the data too short or too "
            "sparse for it; a --params-file with a smaller iod_samples or a longer "
            "iod_max_span starts it") in err, err

"""Real-sky scenarios (`sim.sky`): sensors measure only above their masks (optical: dark
site, sunlit object), in passes separated by hours; the scheduled outage withholds exactly
its station's measurements; a J2 filter fusing one radar's passes is within 1 km after each.

The geometry under these rules (Sun, shadow, rise and set times) is checked against astropy
and skyfield in `test/core/test_sky_geometry.py`; here the simulation must obey it."""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest

from ssa_fusion.core.base.types import Kind
from ssa_fusion.core.earth import frames, sun
from ssa_fusion.core.earth.stations import SENSORS
from ssa_fusion.evaluation.passes import passes
from ssa_fusion.sim import sky
from ssa_fusion.studies.sky_runs import evaluate_sky

DAY = 86400.0


@pytest.fixture(scope="module")
def radar_day() -> sky.SkySimulation:
    s = sky.SKY_SCENARIOS["iss_radar_columbus"].with_(
        duration_s=DAY, outages=(("columbus", 0.55 * DAY, 0.15 * DAY),))
    return sky.simulate_sky(s, seed=3)


def _true_razel(sim: sky.SkySimulation, name: str) -> tuple[np.ndarray, np.ndarray]:
    """Measurements of station `name` and the true (geometric) range/az/el at their epochs."""
    ms = [m for m in sim.measurements if m.frame_id == name]
    t = np.array([m.t for m in ms])
    rae = frames.razel_gcrs(sky.truth(sim.scenario, t), t, SENSORS[name].station)
    return np.array([m.z for m in ms]), rae


def test_radar_measures_only_above_its_mask_in_passes(radar_day):
    z, rae = _true_razel(radar_day, "columbus")
    mask = math.radians(SENSORS["columbus"].min_elevation_deg)
    assert len(z) > 50
    assert rae[:, 2].min() >= mask  # the true elevation of every measurement
    sigma = SENSORS["columbus"].sigma
    # measured = true + noise of the stated size (light time moves the ISS by < 40 m)
    assert np.std(z[:, 0] - rae[:, 0]) == pytest.approx(sigma[0], rel=0.3)
    assert np.abs(z[:, 2] - rae[:, 2]).max() < 6 * sigma[2]
    runs = passes(radar_day.measurements)
    assert 4 <= len(runs) <= 8  # a LEO object over one site: ~5 passes a day
    t = np.array([m.t for m in radar_day.measurements])
    for first, last in runs:
        assert 60.0 <= t[last] - t[first] <= 12 * 60.0  # minutes long
    gaps = np.array([t[b[0]] - t[a[1]] for a, b in itertools.pairwise(runs)])
    assert gaps.min() > 1.4 * 3600  # hours apart (at least one orbit)


def test_outage_withholds_exactly_its_stations_measurements(radar_day):
    s = radar_day.scenario
    _, start, length = s.outages[0]
    t = np.array([m.t for m in radar_day.measurements])
    inside = (t >= s.t0 + start) & (t < s.t0 + start + length)
    assert inside.any()
    assert np.array_equal(radar_day.withheld, inside)
    assert len(radar_day.real) + len(radar_day.withheld_measurements) == len(t)
    # the truth keeps its cadence through every gap
    assert np.allclose(np.diff(radar_day.t), s.truth_cadence_s)


def test_optical_sites_see_only_at_night_a_sunlit_object():
    s = sky.SKY_SCENARIOS["leo_optical"].with_(duration_s=DAY)
    sim = sky.simulate_sky(s, seed=1)
    assert len(sim.measurements) > 10
    for name in {m.frame_id for m in sim.measurements}:
        ms = [m for m in sim.measurements if m.frame_id == name]
        assert all(m.kind == Kind.RA_DEC for m in ms)
        t = np.array([m.t for m in ms])
        station = SENSORS[name].station
        assert sun.sun_elevation(t, station).max() < math.radians(-12.0)
        assert sun.sunlit(sky.truth(s, t)[:, :3], t).all()
    # the mask alone would let the site see the object more often (by day, in shadow)
    grid = s.t0 + np.arange(0.0, DAY, SENSORS["socorro"].cadence_s)
    rae = frames.razel_gcrs(sky.truth(s, grid), grid, SENSORS["socorro"].station)
    above = int(np.sum(rae[:, 2] >= math.radians(SENSORS["socorro"].min_elevation_deg)))
    seen = sum(m.frame_id == "socorro" for m in sim.measurements)
    assert seen > 0 and above > 1.5 * seen  # here: 116 epochs above the mask, 59 seen


def test_filter_is_within_a_kilometre_after_each_radar_pass(radar_day):
    """Radar noise (20 m, 0.02 deg): the J2 filter's position error after each pass is below
    1 km, and its sigma covers it to 3 sigma."""
    report = evaluate_sky(radar_day, seed=3, only=()).passes
    assert len(report.passes) >= 4
    err = np.array([p[3] for p in report.passes])
    sig = np.array([p[4] for p in report.passes])
    assert err.max() < 1.0, err
    assert np.all(err < 3 * sig + 0.05), (err, sig)
    # through the gaps the filter publishes its prediction: errors grow to km, not more
    assert 1.0 < report.pos_err_km.max() < 20.0
    assert np.isfinite(report.nees).all()


def test_reproduce_runs_the_real_sky_study_over_evaluation_seeds(tmp_path, monkeypatch):
    """`ssa-fusion reproduce --scenario iss_radar_columbus --quick`: every arm over the outage
    and the passes of 3 evaluation seeds (here on one day of the scenario, to stay fast)."""
    import json

    from ssa_fusion.apps.cli import build_parser
    from ssa_fusion.studies.distributions import EVALUATION_SEEDS

    short = sky.SKY_SCENARIOS["iss_radar_columbus"].with_(
        duration_s=DAY, outages=(("columbus", 0.55 * DAY, 0.15 * DAY),))
    monkeypatch.setitem(sky.SKY_SCENARIOS, "iss_radar_columbus", short)  # forked workers see it
    args = build_parser().parse_args(["reproduce", "--scenario", "iss_radar_columbus", "--quick",
                                      "--no-plots", "--workers", "3", "--out", str(tmp_path)])
    assert args._run(args) == 0
    got = json.loads((tmp_path / "results.json").read_text())["sky"]["iss_radar_columbus"]
    assert got["runs"] == 3 and EVALUATION_SEEDS[0] == 101
    assert got["after_pass_km_max"] < 1.0
    arms_km = got["outage_mean_km_median"]
    assert set(arms_km) == {"placeholder", "coast", "j2_coast", "batch_fit", "dmd_ekf",
                            "hypothetical_ekf"}
    assert all(0.0 < v < 5.0 for v in arms_km.values()), arms_km  # km over a 3.6 h outage
    pub = got["published"]  # what the filter publishes between passes, per gap_forecast
    assert set(pub) == {"none", "residual", "batch_fit", "batch_init", "fit_residual"}
    assert all(0.0 < m["err_median_km"] < 5.0 and 0.0 <= m["nees_in_95"] <= 1.0
               for m in pub.values()), pub
    assert "## The real sky" in (tmp_path / "results.md").read_text()


def test_the_optical_network_observes_in_april_and_not_in_january():
    """iss_network's optical sites measure nothing in its three days of January (the ISS is
    in the Earth's shadow whenever they are dark: module docstring of sim.sky); the same
    network from 2025-04-16 (iss_network_april) has every optical site measuring, only at
    night, of a sunlit object."""
    january = sky.simulate_sky(sky.SKY_SCENARIOS["iss_network"], seed=1)
    assert not [m for m in january.measurements if m.kind == Kind.RA_DEC]
    s = sky.SKY_SCENARIOS["iss_network_april"]
    april = sky.simulate_sky(s, seed=1)
    optical = [m for m in april.measurements if m.kind == Kind.RA_DEC]
    assert {m.frame_id for m in optical} == {"socorro", "maui", "diego_garcia"}
    assert len(optical) > 60
    t = np.array([m.t for m in optical])
    for name in ("socorro", "maui", "diego_garcia"):
        tn = np.array([m.t for m in optical if m.frame_id == name])
        assert sun.sun_elevation(tn, SENSORS[name].station).max() < math.radians(-12.0)
    assert sun.sunlit(sky.truth(s, t)[:, :3], t).all()


RADAR_AT = """
  - id: {id}
    latitude_deg: 39.0
    longitude_deg: -83.0
    height_m: 250.0
    type: radar
    noise: {{range_m: 20.0, azimuth_deg: 0.02, elevation_deg: 0.02}}
    cadence_s: 10.0
    min_elevation_deg: 10.0
"""
SCOPE_AT = """
  - id: {id}
    latitude_deg: 32.5
    longitude_deg: -106.0
    height_m: 1500.0
    type: optical
    noise: {{ra_arcsec: 1.5, dec_arcsec: 1.5}}
    cadence_s: 20.0
    min_elevation_deg: 20.0
"""
"""A telescope near Socorro, as a sites file's entry (`id` to fill in)."""
SITES_YAML = ("sites:" + RADAR_AT.format(id="near_radar") + "    max_range_km: 1000.0\n"
              + RADAR_AT.format(id="far_radar"))
"""Two radars at one site; the near one measures only within 1000 km."""


def test_sites_of_a_file_observe_within_their_mask_and_range(tmp_path):
    """`with_sites`: the file's sites replace the scenario's sensors, in the simulator and in
    the filter's settings; a radar's maximum range removes the far part of each pass (the
    geometry is checked independently with the measured range, not the simulator's)."""
    path = tmp_path / "sites.yaml"
    path.write_text(SITES_YAML)
    s = sky.SKY_SCENARIOS["iss_radar_columbus"].with_window(sky.ORBIT_EPOCH_UNIX, 86400.0)
    own = s.with_sites(str(path))
    assert own.sensors == ("near_radar", "far_radar")
    assert own.outages == tuple((sky.ALL_STATIONS, a, b) for _, a, b in s.outages)
    assert {st.name for st in own.estimator().sites} == {"near_radar", "far_radar"}
    assert own.network == "near_radar,far_radar,"
    sim = sky.simulate_sky(own, seed=3)
    by = {k: np.array([m.z for m in sim.measurements if m.frame_id == k])
          for k in own.sensors}
    near, far = by["near_radar"], by["far_radar"]
    assert len(far) > len(near) > 20  # the same site: the range limit cuts passes short
    assert near[:, 0].max() <= 1000.0 + 0.5  # noise is 20 m: 25 sigma of slack
    assert far[:, 0].max() > 1500.0
    assert np.degrees(np.concatenate([near, far])[:, 2]).min() > 10.0 - 0.1


def test_a_shorter_window_keeps_the_outage_inside_the_run():
    s = sky.SKY_SCENARIOS["iss_radar_columbus"]
    (who, start, length), = s.outages
    short = s.with_window(s.t0 + 86400.0 * 30, s.duration_s / 3)
    assert short.t0 == s.t0 + 86400.0 * 30 and short.duration_s == s.duration_s / 3
    assert short.outages == ((who, start / 3, length / 3),)
    assert start / 3 + length / 3 < short.duration_s


CALSPHERE = """CALSPHERE 1
1 00900U 64063C   25207.12662947  .00000539  00000+0  54429-3 0  9994
2 00900  90.2135  64.2751 0024196 195.2435 287.7917 13.76124948 26562
"""


def test_an_element_set_is_the_object_a_scenario_observes(tmp_path):
    """`with_elements`: the truth is the element set's SGP4 (here against the `sgp4`
    package directly, TEME rotated to the GCRF by astropy), from the first whole minute
    after its epoch; the scenario's radars measure it."""
    from astropy import units as u
    from astropy.coordinates import GCRS, TEME, CartesianDifferential, CartesianRepresentation
    from astropy.time import Time
    from sgp4.api import Satrec

    path = tmp_path / "calsphere.tle"
    path.write_text(CALSPHERE)
    s = sky.SKY_SCENARIOS["iss_network"].with_elements(str(path))
    line1, line2 = CALSPHERE.splitlines()[1:3]
    sat = Satrec.twoline2rv(line1, line2)
    epoch = (sat.jdsatepoch - 2440587.5) * 86400.0 + sat.jdsatepochF * 86400.0
    assert s.t0 == 60.0 * math.ceil(epoch / 60.0) and s.t0 - epoch < 60.0
    t = s.t0 + np.array([0.0, 3600.0, 86400.0])
    x = sky.truth(s, t)
    when = Time(t, format="unix", scale="utc")
    err, r, v = sat.sgp4_array(when.jd1, when.jd2)
    assert not err.any()
    teme = TEME(CartesianRepresentation(r.T * u.km, differentials=CartesianDifferential(
        v.T * u.km / u.s)), obstime=when)
    gcrs = teme.transform_to(GCRS(obstime=when))
    ref = np.hstack([gcrs.cartesian.xyz.to_value(u.km).T,
                     gcrs.velocity.d_xyz.to_value(u.km / u.s).T])
    np.testing.assert_allclose(x[:, :3], ref[:, :3], atol=1e-4)  # 0.1 m
    sim = sky.simulate_sky(s.with_window(s.t0, 86400.0), seed=1)
    radar = {r.station.name for r in s.radars}
    assert {m.frame_id for m in sim.measurements} & radar  # the radars see it in a day
    assert sim.t[0] == s.t0


def test_an_evaluation_case_turns_the_orbit_but_keeps_its_shape():
    """`with_geometry` (the real-sky study's cases, `sky_study.case_geometry`): the node
    moves by the shift asked, the phase along the orbit by its own; inclination, energy and
    angular momentum's size stay (checked on the state, not on the rotation code)."""
    from ssa_fusion.core.base.constants import MU_EARTH
    from ssa_fusion.studies.sky_study import RAAN_SPREAD_DEG, case_geometry

    def elements(x: np.ndarray) -> tuple[float, float, float, float]:
        r, v = x[:3], x[3:]
        h = np.cross(r, v)
        node = math.atan2(h[0], -h[1])
        inc = math.acos(h[2] / np.linalg.norm(h))
        energy = v @ v / 2 - MU_EARTH / np.linalg.norm(r)
        return node, inc, energy, float(np.linalg.norm(h))

    base = sky.SKY_SCENARIOS["iss_radar_columbus"]
    shifts = [case_geometry(seed) for seed in range(101, 121)]
    assert all(abs(d) <= math.radians(RAAN_SPREAD_DEG) for d, _ in shifts)
    assert len({round(p, 6) for _, p in shifts}) == 20  # every case its own phase
    d_raan, d_phase = shifts[0]
    x0, x1 = np.array(base.x0), np.array(base.with_geometry(d_raan, d_phase).x0)
    n0, i0, e0, h0 = elements(x0)
    n1, i1, e1, h1 = elements(x1)
    assert math.remainder(n1 - n0 - d_raan, 2 * math.pi) == pytest.approx(0.0, abs=1e-12)
    assert (i1, e1, h1) == pytest.approx((i0, e0, h0), rel=1e-12)
    # the phase: the angle between the positions, seen in the (turned back) plane
    back = base.with_geometry(0.0, d_phase).x0
    cos = np.dot(x0[:3], back[:3]) / np.linalg.norm(x0[:3]) / np.linalg.norm(back[:3])
    assert math.acos(np.clip(cos, -1, 1)) == pytest.approx(
        abs(math.remainder(d_phase, 2 * math.pi)), abs=1e-9)


def test_network_cases_draw_their_own_sites_and_tuning_and_evaluation_never_share_one():
    """`sky_study.case_sites`: every evaluation case of a network scenario observes with its
    own network of real sites (the scenario's count of radars and optical sites, from its
    `site_pool`), the same for the same seed; tuning and evaluation seeds are disjoint and
    so are their networks; the single radar keeps its station. `case_scenario` observes
    with the drawn sites, the outage of a slot's site moving to its replacement."""
    from ssa_fusion.studies.distributions import EVALUATION_SEEDS, TUNING_SEEDS
    from ssa_fusion.studies.sky_study import case_scenario, case_sites

    assert not set(TUNING_SEEDS) & set(EVALUATION_SEEDS)
    for name in ("iss_network", "iss_network_april", "leo_optical"):
        base = sky.SKY_SCENARIOS[name]
        evaluation = [case_sites(base, seed) for seed in EVALUATION_SEEDS]
        tuning = {frozenset(case_sites(base, seed)) for seed in TUNING_SEEDS}
        assert len({frozenset(n) for n in evaluation}) == len(EVALUATION_SEEDS)
        assert len(tuning) == len(TUNING_SEEDS)
        assert not tuning & {frozenset(n) for n in evaluation}
        for n in evaluation:
            assert set(n) <= set(base.site_pool) and len(set(n)) == len(n)
            assert [SENSORS[a].type for a in n] == [SENSORS[a].type for a in base.sensors]
    leo = sky.SKY_SCENARIOS["leo_optical"]
    assert case_sites(leo, 101) == case_sites(leo, 101) == (
        "zimmerwald", "xinglong", "calar_alto")  # the same seed, the same sites
    s = case_scenario("leo_optical", 0.0, 101)
    assert s.network == "zimmerwald,xinglong,calar_alto,"
    assert [o[0] for o in leo.outages] == ["maui"] and [o[0] for o in s.outages] == ["xinglong"]
    radar = sky.SKY_SCENARIOS["iss_radar_columbus"]
    assert {case_sites(radar, seed) for seed in EVALUATION_SEEDS} == {("columbus",)}
    with pytest.raises(ValueError, match="sensor type"):
        leo.with_sensors(("millstone", "maui", "socorro"))


def test_an_optical_site_sees_only_what_is_brighter_than_its_limiting_magnitude(tmp_path):
    """`limiting_magnitude`: the same telescope with a limit of 3 measures a subset of what it
    measures without one, and every epoch it keeps has the object at most that faint (the
    magnitude recomputed from the truth); `iss_network_april`'s orbit over two days, an
    object of standard magnitude 4 (the ISS, -1.3, is brighter than 0 at every pass)."""
    from ssa_fusion.core.earth import visibility

    path = tmp_path / "scopes.yaml"
    path.write_text("sites:" + SCOPE_AT.format(id="any") + SCOPE_AT.format(id="faint")
                    + "    limiting_magnitude: 3.0\n")
    base = sky.SKY_SCENARIOS["iss_network_april"]
    s = base.with_window(base.t0, 2 * 86400.0).with_sites(str(path)).with_(
        standard_magnitude=4.0)
    sim = sky.simulate_sky(s, seed=2)
    t = {k: np.array([m.t for m in sim.measurements if m.frame_id == k]) for k in s.sensors}
    assert len(t["any"]) > len(t["faint"]) > 0
    assert set(t["faint"]) <= set(t["any"])
    kept = sky.truth(s, t["faint"])
    mag = visibility.apparent_magnitude(kept, t["faint"], s.sensor("faint").station,
                                        s.standard_magnitude)
    assert mag.max() <= 3.0


def test_a_site_that_waits_for_a_darker_sky_sees_less(tmp_path):
    """`dark_below_deg`: -18 (astronomical night) keeps a subset of what -12 (nautical
    twilight's end, the default) sees, each kept epoch with the Sun below -18 deg there."""
    from ssa_fusion.core.earth import sun

    path = tmp_path / "scopes.yaml"
    path.write_text("sites:" + SCOPE_AT.format(id="nautical") + SCOPE_AT.format(id="night")
                    + "    dark_below_deg: -18.0\n")
    base = sky.SKY_SCENARIOS["iss_network_april"]
    s = base.with_window(base.t0, 2 * 86400.0).with_sites(str(path))
    sim = sky.simulate_sky(s, seed=2)
    t = {k: np.array([m.t for m in sim.measurements if m.frame_id == k]) for k in s.sensors}
    assert len(t["nautical"]) > len(t["night"])
    assert set(t["night"]) <= set(t["nautical"])
    if len(t["night"]):
        assert np.degrees(sun.sun_elevation(t["night"], s.sensor("night").station)).max() < -18


def test_a_window_ending_after_the_last_representable_second_is_refused():
    """A start in range whose end (start + duration) passes 2038-01-19T03:14:07 (a ROS 2
    stamp's int32 seconds) ran on and hung; now one line names the end."""
    s = sky.SKY_SCENARIOS["iss_radar_columbus"]
    last = 2**31 - 1
    assert s.with_window(last - 7200.0, 7200.0).t0 == last - 7200.0  # ends on the last second
    with pytest.raises(ValueError, match=r"the run's end .* 2038-01-19T04:00:00.000Z is outside"):
        s.with_window(last - 7200.0 - 847.0, 3 * 3600.0)
    with pytest.raises(ValueError, match=r"start 1971-12-31"):
        s.with_window(63_072_000.0 - 86400.0, 3600.0)

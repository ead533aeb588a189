"""Station measurement models (radar, optical, light time), station networks, and a filter
that fuses several stations and initialises from one pass."""

from __future__ import annotations

import math

import numpy as np
import pytest

from ssa_fusion.core.base.constants import C_KM_S
from ssa_fusion.core.base.metrics import chi2_bounds, nees
from ssa_fusion.core.base.types import Cause, Kind, Measurement
from ssa_fusion.core.earth import frames
from ssa_fusion.core.earth.stations import SENSORS, STATIONS, network_stations
from ssa_fusion.core.earth.timescales import UNIX_EPOCH_JD
from ssa_fusion.core.filter.options import FilterOptions
from ssa_fusion.core.gaps.estimator import EstimatorConfig, make_tracker
from ssa_fusion.core.measure.measurement import RadecModel, RazelModel, StationModels
from ssa_fusion.core.motion import dynamics
from ssa_fusion.sim.scenarios import ISS_ELEMENTS

T0 = 1735689600.0  # 2025-01-01T00:00:00Z
X0 = dynamics.elements_to_state(**ISS_ELEMENTS)


def truth(t: np.ndarray) -> np.ndarray:
    return dynamics.sgp4_ephemeris(X0, T0, np.asarray(t, float) - T0, bstar=1.027e-4)


def first_pass(station: str, mask_deg: float = 10.0, cadence: float = 10.0,
               hours: float = 24.0) -> tuple[np.ndarray, np.ndarray]:
    """Epochs and states of the first pass of the ISS over `station` above the mask."""
    t = T0 + np.arange(0.0, hours * 3600.0, cadence)
    x = truth(t)
    el = frames.razel_gcrs(x, t, STATIONS[station])[:, 2]
    up = np.flatnonzero(el > math.radians(mask_deg))
    assert len(up), "no pass"
    run = up[: np.argmax(np.diff(np.concatenate([up, [up[-1] + 10]])) > 1) + 1]
    return t[run], x[run]


def test_radec_is_the_direction_razel_sees():
    """ra/dec and az/el of one state are one line of sight: az/el turned into a GCRF unit
    vector through ENU -> ITRF -> GCRF (frames) gives the model's ra/dec."""
    t, x = first_pass("columbus")
    st = STATIONS["columbus"]
    rae, radec = RazelModel(st, UNIX_EPOCH_JD), RadecModel(st, UNIX_EPOCH_JD)
    for ti, xi in zip(t[::5], x[::5], strict=True):
        _r, az, el = rae.h(xi, ti)
        enu = np.array([math.cos(el) * math.sin(az), math.cos(el) * math.cos(az), math.sin(el)])
        los_itrs = frames.enu_matrix(st.lat_rad, st.lon_rad).T @ enu
        los = frames.itrs_to_gcrs(los_itrs, ti)
        ra, dec = radec.h(xi, ti)
        assert math.isclose(ra, math.atan2(los[1], los[0]) % (2 * math.pi), abs_tol=1e-9)
        assert math.isclose(dec, math.asin(los[2]), abs_tol=1e-9)


@pytest.mark.parametrize("cls", [RazelModel, RadecModel])
@pytest.mark.parametrize("light_time", [False, True])
def test_jacobians_match_finite_differences(cls, light_time):
    t, x = first_pass("columbus")
    model = cls(STATIONS["columbus"], UNIX_EPOCH_JD, light_time)
    xi, ti = x[len(x) // 2], float(t[len(t) // 2])
    _z, H = model.h_and_H(xi, ti)
    num = np.zeros_like(H)
    for j, step in enumerate([1e-3] * 3 + [1e-1] * 3):  # h is linear in v
        dx = np.zeros(6)
        dx[j] = step
        num[:, j] = (model.h(xi + dx, ti) - model.h(xi - dx, ti)) / (2 * step)
    assert np.allclose(H[:, :3], num[:, :3], rtol=1e-6, atol=1e-12)
    assert np.allclose(H[:, 3:], num[:, 3:], rtol=1e-6, atol=1e-15)
    if not light_time:
        assert not H[:, 3:].any()


def test_light_time_matches_the_exact_retarded_position():
    """The first-order light-time model against the exact solution of
    t_e = t - |r(t_e) - r_site(t)| / c with the SGP4 truth: agree to 1 mm in range, while
    ignoring light time is off by the 1.4-5 ms of travel times the ISS's 7.7 km/s."""
    t, x = first_pass("columbus")
    st = STATIONS["columbus"]
    fast, exact_model = RazelModel(st, UNIX_EPOCH_JD), RazelModel(st, UNIX_EPOCH_JD, True)
    shifts = []
    for ti, xi in zip(t, x, strict=True):
        site = exact_model.site_gcrs(ti)
        te = ti
        for _ in range(4):
            te = ti - np.linalg.norm(truth(np.array([te]))[0, :3] - site) / C_KM_S
        r_exact = truth(np.array([te]))[0]
        want = fast.h(r_exact, ti)  # the retarded position seen at reception
        got = exact_model.h(xi, ti)
        assert abs(got[0] - want[0]) < 1e-6  # km
        assert np.allclose(got[1:], want[1:], atol=1e-9)
        shifts.append(np.linalg.norm(xi[:3] - r_exact[:3]) * 1000.0)
        assert 1.4e-3 < ti - te < 5.0e-3
    assert min(shifts) > 11.0 and max(shifts) < 39.0  # m: 7.7 km/s for 1.4-5 ms


def test_station_models_pick_by_frame_and_kind():
    net = StationModels(network_stations("network"), UNIX_EPOCH_JD)
    assert isinstance(net.get(Kind.RANGE_AZ_EL, "millstone"), RazelModel)
    assert isinstance(net.get(Kind.RA_DEC, "socorro"), RadecModel)
    assert net.get(Kind.RANGE_AZ_EL, "millstone") is net.get(Kind.RANGE_AZ_EL, "millstone")
    assert net.get(Kind.RANGE_AZ_EL, "columbus") is None  # not in the network
    assert net.get(Kind.POSITION, "millstone") is None
    assert set(network_stations("columbus,tira")) == {"columbus", "tira"}
    with pytest.raises(ValueError, match="unknown"):
        network_stations("columbus,atlantis")


def _radar(t: np.ndarray, x: np.ndarray, station: str, rng: np.random.Generator,
           ) -> list[Measurement]:
    sensor = SENSORS[station]
    z = frames.razel_gcrs(x, t, sensor.station)
    z = z + rng.standard_normal(z.shape) * np.array(sensor.sigma)
    return [Measurement(t=float(ti), z=zi, R=sensor.R, kind=Kind.RANGE_AZ_EL,
                        frame_id=sensor.station.name) for ti, zi in zip(t, z, strict=True)]


def network_config(station: str, **tracker) -> EstimatorConfig:
    options = FilterOptions().with_(**{"motion_model": "j2", "p0_sigma": (0.0,) * 6,
                                       "q": 1e-13, "iod_samples": 7, **tracker})
    return EstimatorConfig(kind=Kind.RANGE_AZ_EL, station=station, filter=options)


def test_iod_from_one_radar_pass_lies_within_its_covariance():
    """Herrick-Gibbs on 7 radar measurements (60 s of one pass, 20 m / 0.02 deg noise): over
    40 noise draws the NEES of the initial state against the truth is chi-square (6 dof)."""
    t, x = first_pass("columbus")
    t, x = t[:7], x[:7]
    values = []
    for seed in range(40):
        tracker = make_tracker(network_config("columbus,"))
        out = None
        for m in _radar(t, x, "columbus", np.random.default_rng(seed)):
            out = tracker.process(m)
        assert out is not None and out.estimate is not None
        values.append(float(nees(out.estimate.x - x[-1], out.estimate.P)[0]))
    lo, hi = chi2_bounds(6, n_runs=40)
    assert lo < np.mean(values) < hi, np.mean(values)


def test_iod_batch_is_one_pass_of_one_station():
    t, x = first_pass("columbus")
    rng = np.random.default_rng(1)
    tracker = make_tracker(network_config("columbus,tira", iod_samples=3, iod_max_span_s=300.0))
    ms = _radar(t, x, "columbus", rng)
    assert tracker.process(ms[0]).rejected == Cause.IOD_PENDING
    far = Measurement(t=ms[0].t + 1000.0, z=ms[1].z, R=ms[1].R, kind=Kind.RANGE_AZ_EL,
                      frame_id="columbus")
    assert tracker.process(far).rejected == Cause.IOD_PENDING  # > 300 s: a new batch
    assert tracker._initiator.batch == [far]
    other = Measurement(t=far.t + 10.0, z=ms[2].z, R=ms[2].R, kind=Kind.RANGE_AZ_EL,
                        frame_id="tira")
    tracker.process(other)
    assert tracker._initiator.batch == [other]  # another station: a new batch
    unknown = Measurement(t=far.t + 20.0, z=ms[2].z, R=ms[2].R, kind=Kind.RANGE_AZ_EL,
                          frame_id="atlantis")
    out = tracker.process(unknown)
    assert out.rejected == Cause.REJECTED_FRAME and "not in the network" in out.detail


def test_filter_fuses_two_stations():
    """Two radars (Columbus and Millstone) see the ISS within an hour of each other: the
    filter initialises on one, fuses the other's pass with its own model, and ends the
    second pass within a few times its noise of the truth."""
    rng = np.random.default_rng(7)
    ms = []
    for station in ("columbus", "millstone"):
        t, x = first_pass(station)
        ms += _radar(t, x, station, rng)
    ms.sort(key=lambda m: m.t)
    tracker = make_tracker(network_config("columbus,millstone"))
    fused = {m.frame_id: 0 for m in ms}
    last = None
    for m in ms:
        out = tracker.process(m)
        if out.estimate is not None:
            fused[m.frame_id] += 1
            last = out.estimate
    assert all(n > 10 for n in fused.values()), fused
    assert last is not None
    err = np.linalg.norm(last.x[:3] - truth(np.array([last.t]))[0, :3])
    assert err < 0.3, err  # km; 20 m range, 0.02 deg (~0.3 km at 1000 km) per measurement
    assert float(nees(last.x - truth(np.array([last.t]))[0], last.P)[0]) < 22.5  # chi2(6) 99.9 %

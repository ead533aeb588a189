"""A laser network's model (core.measure.laser_model) in the fit and the filter, on simulated
ranges whose truth is known:

* one station's model for the filter agrees with the vectorised model, and its Jacobian
  (the orbit's columns and the station's bias column in an augmented state) with finite
  differences;
* `batch_ls.fit` with the network's range biases as measurement parameters recovers the
  biases put into simulated ranges (5 mm noise) and the orbit, from a first guess 1 km off;
* the contexts kept by the day (core.motion.contexts) propagate as `high_fidelity.propagate`
  does, and the filter's augmented motion holds the STM, the k_R sensitivity and constants.
"""

from __future__ import annotations

import numpy as np
import pytest

from ssa_fusion.core.base.types import Kind, Measurement, Source
from ssa_fusion.core.earth.timescales import parse_utc
from ssa_fusion.core.measure import laser_range as lr
from ssa_fusion.core.measure.laser_model import LaserModels, LaserNetwork, bias_name
from ssa_fusion.core.measure.laser_station import LaserStation
from ssa_fusion.core.motion import high_fidelity as hf
from ssa_fusion.core.motion.contexts import Contexts, augmented_motion
from ssa_fusion.core.motion.force_spec import ForceSpec, SrpSpec
from ssa_fusion.core.od import batch_ls
from ssa_fusion.formats.icgem import egm96

T0 = parse_utc("2016-02-13T00:00:00")
X0 = np.array([-9060.818, -5864.078, 5836.7, 0.488606, -4.367428, -3.629409])  # 12,270 km, 52.6 deg
STATIONS = {  # (latitude, longitude) deg of three ranging sites, on the ellipsoid
    "A": (-29.05, 115.35), "B": (20.71, -156.26), "C": (40.65, 16.70)}
BIASES_KM = {"A": 0.02e-3, "B": -0.03e-3, "C": 0.0}
SPEC = ForceSpec(egm96(), 4, sun=False, moon=False)


def _station(sid: str, lat: float, lon: float) -> LaserStation:
    la, lo = np.radians(lat), np.radians(lon)
    p = 6378.137 * np.array([np.cos(la) * np.cos(lo), np.cos(la) * np.sin(lo), np.sin(la)])
    return LaserStation(sid, p, np.zeros(3), T0)


def _network() -> LaserNetwork:
    return LaserNetwork({s: _station(s, *ll) for s, ll in STATIONS.items()},
                        bias_sigma_km=dict.fromkeys(STATIONS, 1e-3))


def _visible(models: LaserModels, t: np.ndarray, sid: str, x: np.ndarray) -> np.ndarray:
    return models.points(t, [sid] * len(t)).predict(x, np.zeros(3)).elevation > np.radians(20)


def _simulated(models: LaserModels) -> list[Measurement]:
    """Ranges of the truth orbit from every station above 20 deg, every 2 min over 2 days."""
    t = T0 + np.arange(0.0, 2 * 86400.0, 120.0)
    x = hf.propagate(SPEC, X0, T0, t, stm=False, max_step_s=120.0).x
    rng = np.random.default_rng(11)
    out = []
    for sid in STATIONS:
        seen = _visible(models, t, sid, x)
        bias = np.array([BIASES_KM[s] for s in STATIONS])
        z = models.points(t[seen], [sid] * int(seen.sum())).predict(x[seen], bias).range_km
        z = z + rng.normal(0.0, 5e-6, z.size)
        out += [Measurement(t=float(ti), z=np.array([zi]), R=np.array([[25e-12]]),
                            kind=Kind.LASER_RANGE, source=Source.SENSOR, frame_id=sid)
                for ti, zi in zip(t[seen], z, strict=True)]
    return sorted(out, key=lambda m: m.t)


def test_one_stations_model_is_the_networks_and_its_jacobian_the_derivative():
    models = LaserModels(_network())
    t = next(m.t for m in _simulated(models) if m.frame_id == "B")  # B sees it
    x6 = hf.propagate(SPEC, X0, T0, [t], stm=False).x[0]
    x = np.concatenate([x6, [0.01e-3, -0.02e-3, 0.03e-3], [1.0]])  # orbit, 3 biases, k_R
    model = models.get(Kind.LASER_RANGE, "B")
    assert model is not None and models.get(Kind.RANGE_AZ_EL, "B") is None
    z, H = model.h_and_H(x, t)
    direct = lr.two_way_range(lr.geometry([models.stations["B"]], [0], [t]), None, x6[None],
                              shapiro=False).range_km[0]
    pts = models.points([t], ["B"]).predict(x6[None], x[6:9])
    assert z[0] == pytest.approx(pts.range_km[0], abs=1e-12)
    assert 1e-3 < z[0] - direct + 0.02e-3 + lr.LAGEOS_COM_KM < 0.02  # troposphere & Shapiro
    for j, h in enumerate([1e-3] * 3 + [1e-6] * 3 + [1e-3] * 4):
        e = np.zeros(x.size)
        e[j] = h
        fd = (model.h_and_H(x + e, t)[0][0] - model.h_and_H(x - e, t)[0][0]) / (2 * h)
        assert H[0, j] == pytest.approx(fd, abs=2e-5 if j < 6 else 1e-8), j
    assert H[0, 7] == 1.0 and H[0, 6] == H[0, 8] == H[0, 9] == 0.0


def test_the_fit_recovers_the_biases_and_the_orbit():
    models = LaserModels(_network())
    ms = _simulated(models)
    guess = X0 + np.array([0.6, -0.5, 0.6, 4e-4, -3e-4, 5e-4])
    fit = batch_ls.fit(ms, models, guess, T0, batch_ls.BatchOptions(force=SPEC, max_step_s=120.0),
                       epoch=T0)
    print(f"\n{len(ms)} ranges: {fit.status}, RMS {fit.rms:.2f}; biases (mm) "
          f"{ {k: round(v * 1e6, 2) for k, v in fit.measurement_params.items()} }")
    assert fit.converged and 0.8 < fit.rms < 1.2  # the 5 mm noise, whitened
    assert list(fit.measurement_params) == [bias_name(s) for s in STATIONS]
    for sid, truth in BIASES_KM.items():
        got, sig = fit.measurement_params[bias_name(sid)], fit.sigma(bias_name(sid))
        assert abs(got - truth) < 4 * sig and sig < 3e-6  # millimetres
    assert np.linalg.norm(fit.x[:3] - X0[:3]) < 2e-5  # 2 cm


def test_contexts_by_the_day_propagate_as_the_propagator_does():
    spec = ForceSpec(egm96(), 8, srp=SrpSpec(7e-4, 1.13), solid_tides=True)
    t0 = T0 - 3600.0  # the day before
    t = [t0 + 7200.0, t0 + 30000.0]  # the next day
    a = Contexts(spec).propagate(X0, t0, t, which=[4])
    b = hf.propagate(spec, X0, t0, t, which=[4])
    assert np.allclose(a.x, b.x, atol=1e-9, rtol=0) and np.allclose(a.phi, b.phi, atol=1e-9)
    f = augmented_motion(spec, 9, ("srp_scale",))
    x = np.concatenate([X0, [0.1, 0.2], [1.05]])
    x1, F = f(x, 3600.0, t0)
    tr = hf.propagate(spec, X0, t0, [t0 + 3600.0], [1.0, 0.0, 0.0, 0.0, 1.05], [4])
    assert np.allclose(x1[:6], tr.x[0], atol=1e-9) and np.array_equal(x1[6:], x[6:])
    assert np.allclose(F[:6, :6], tr.phi[0]) and np.allclose(F[:6, 8], tr.s[0][:, 0])
    assert np.array_equal(F[6:, 6:], np.eye(3)) and not F[6:, :6].any()

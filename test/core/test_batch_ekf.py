"""The batched EKF (`core.catalog.batch_ekf`) equals the per-object filter object by object.

Twenty objects on different orbits (LEO at several inclinations, high-drag-altitude LEO, MEO,
GEO, Molniya), each with its own time step (1 s to 50 min) and station, go through one cycle
(predict + range/az/el update) of the batched filter and, one by one, of the project's
per-object `Tracker` (and FilterPy's `ExtendedKalmanFilter`); they must agree to 1e-9
relative (max |difference| / max |reference| per object, for x and for P).
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from ssa_fusion.core.base.types import Cause, Kind, Measurement
from ssa_fusion.core.catalog.batch_ekf import REASONS, BatchEKF, Code
from ssa_fusion.core.earth.frames import razel_gcrs, wrap_angle
from ssa_fusion.core.earth.stations import RADAR_SIGMA, STATIONS
from ssa_fusion.core.earth.timescales import UNIX_EPOCH_JD
from ssa_fusion.core.filter.ekf import ExtendedKalmanFilter, bound_covariance, process_noise
from ssa_fusion.core.filter.options import FilterOptions
from ssa_fusion.core.gaps.estimator import EstimatorConfig, make_tracker
from ssa_fusion.core.measure.measurement import RazelModel
from ssa_fusion.core.motion import dynamics, kepler, propagation
from ssa_fusion.core.motion.dynamics import elements_to_state
from ssa_fusion.core.motion.kepler import kepler_state, kepler_stm
from ssa_fusion.core.motion.propagation import integrate_stm

NAMES = ("millstone", "tira", "altair", "columbus")
STATION_LIST = [STATIONS[s] for s in NAMES]
T0 = 1.7e9  # s, Unix time
R = np.diag(np.square(RADAR_SIGMA)) * 25.0  # a coarser radar: 100 m, 0.1 deg
P0 = np.diag([1.0, 1.0, 1.0, 1e-6, 1e-6, 1e-6])
TOL = 1e-9


def _rel(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.abs(a - b).max() / np.abs(b).max())


def _objects(n: int = 20, seed: int = 3) -> dict[str, np.ndarray]:
    """Estimates, steps, stations and measurements of `n` objects (truth = estimate + error)."""
    rng = np.random.default_rng(seed)
    regimes = [  # (a km, e)
        (6778.0, 0.001), (6878.0, 0.0005), (7178.0, 0.01), (6578.0, 0.002),  # LEO, low
        (26560.0, 0.01), (42164.0, 0.0002), (26555.9, 0.7294), (8000.0, 0.15),
    ]
    x, dt, st = [], [], []
    for i in range(n):
        a, e = regimes[i % len(regimes)]
        angles = rng.uniform(0.0, 2.0 * math.pi, 3)
        x.append(elements_to_state(a, e, rng.uniform(0.0, math.pi), *angles))
        dt.append((1.0, 10.0, 30.0, 60.0, 300.0, 1200.0, 3000.0)[i % 7])
        st.append(i % len(NAMES))
    X = np.array(x)
    DT = np.array(dt)
    err = rng.normal(0.0, 1.0, (n, 6)) * np.array([0.3, 0.3, 0.3, 3e-4, 3e-4, 3e-4])
    truth, _, ok = kepler_stm(X + err, DT)
    assert ok.all()
    T = T0 + DT
    Z = np.array([razel_gcrs(truth[i], T[i], STATION_LIST[st[i]])
                  for i in range(n)])
    Z += rng.normal(0.0, 1.0, Z.shape) * np.sqrt(np.diag(R))
    Z[:, 1] %= 2.0 * math.pi
    return {"x": X, "P": np.tile(P0, (n, 1, 1)), "dt": DT, "t": T, "station": np.array(st),
            "z": Z}


def _tracker_cycle(model: str, x0: np.ndarray, t: float, z: np.ndarray,
                   station: int) -> tuple[np.ndarray, np.ndarray]:
    """One cycle of the project's per-object filter (a `Tracker` past its IOD)."""
    tracker = make_tracker(EstimatorConfig(station=",".join(NAMES),
                                           filter=FilterOptions().with_(motion_model=model)))
    tracker.ekf = ExtendedKalmanFilter(x0, P0)
    tracker.t = tracker.t_real = T0
    out = tracker.process(Measurement(t, z, R, Kind.RANGE_AZ_EL, frame_id=NAMES[station]))
    assert out.estimate is not None, out.detail
    return out.estimate.x, out.estimate.P


@pytest.mark.parametrize("model", ["kepler", "j2"])
def test_equals_per_object_tracker(model: str) -> None:
    o = _objects()
    bank = BatchEKF(FilterOptions().with_(motion_model=model), STATION_LIST)
    out = bank.step(o["x"], o["P"], o["dt"], o["z"], R, o["t"], o["station"])
    assert (out.code == Code.FUSED).all(), [out.reason(i) for i in range(len(out.code))]
    worst = 0.0
    for i in range(len(o["x"])):
        x, P = _tracker_cycle(model, o["x"][i], float(o["t"][i]), o["z"][i], int(o["station"][i]))
        worst = max(worst, _rel(out.x[i], x), _rel(out.P[i], P))
    # j2: fixed-step DOP853 (60 s) against the tracker's adaptive DOP853 (rtol 1e-10)
    assert worst < TOL, worst


def test_equals_filterpy() -> None:
    filterpy = pytest.importorskip("filterpy.kalman")
    o = _objects(seed=5)
    bank = BatchEKF(FilterOptions(), STATION_LIST)
    out = bank.step(o["x"], o["P"], o["dt"], o["z"], R, o["t"], o["station"])

    def residual(a: np.ndarray, b: np.ndarray) -> np.ndarray:
        y = a - b
        y[1:] = wrap_angle(y[1:])
        return y

    for i in range(len(o["x"])):
        dt, t = float(o["dt"][i]), float(o["t"][i])
        model = RazelModel(STATION_LIST[int(o["station"][i])], UNIX_EPOCH_JD)
        kf = filterpy.ExtendedKalmanFilter(dim_x=6, dim_z=3)
        kf.x, kf.P = o["x"][i].copy(), P0.copy()
        kf.x, kf.F = kepler.propagate(kf.x, dt)
        kf.P = kf.F @ kf.P @ kf.F.T + process_noise(dt, 1e-10)
        kf.update(o["z"][i], model.H, model.h, R=R, args=(t,), hx_args=(t,), residual=residual)
        assert _rel(out.x[i], kf.x) < TOL
        assert _rel(out.P[i], kf.P) < TOL


def test_motion_models_match_per_object() -> None:
    o = _objects()
    x1, phi, ok = kepler_stm(o["x"], o["dt"])
    xs, ok_s = kepler_state(o["x"], o["dt"])
    assert ok.all() and ok_s.all()
    for i in range(len(x1)):
        xr, pr = kepler.propagate(o["x"][i], float(o["dt"][i]))
        assert _rel(x1[i], xr) < 1e-12 and _rel(phi[i], pr) < 1e-12 and _rel(xs[i], xr) < 1e-12
    # one Kepler solver: against an independent reference, the two-body variational
    # equations integrated (numpy DOP853, 5 s steps)
    xi, phii, oki = propagation._integrate_stm_numpy("two_body", o["x"], o["dt"], 5.0)
    assert oki.all()
    for i in range(len(x1)):
        assert _rel(x1[i], xi[i]) < 1e-12 and _rel(phi[i], phii[i]) < 1e-12, i
    # J2: the batched fixed-step integrator equals a per-object integration with the same
    # fixed-step DOP853 scheme (dynamics' own right-hand side and Jacobian) to round-off
    from scipy.integrate._ivp import dop853_coefficients as dop

    sel = np.arange(0, len(x1), 3)
    x1, phi, ok = integrate_stm("j2", o["x"][sel], o["dt"][sel], max_step_s=60.0)
    assert ok.all()
    for k, i in enumerate(sel):
        y = np.concatenate([o["x"][i], np.eye(6).ravel()])
        steps = math.ceil(o["dt"][i] / 60.0)
        h = o["dt"][i] / steps

        def f(y: np.ndarray) -> np.ndarray:
            phi0 = y[6:].reshape(6, 6)
            return np.concatenate([dynamics.rhs("j2", y[:6]),
                                   (dynamics.jacobian("j2", y[:6]) @ phi0).ravel()])

        for _ in range(steps):
            K = np.zeros((dop.N_STAGES, 42))
            for s in range(dop.N_STAGES):
                K[s] = f(y + h * (dop.A[s, :s] @ K[:s]))
            y = y + h * (dop.B @ K)
        assert _rel(x1[k], y[:6]) < 1e-12 and _rel(phi[k], y[6:].reshape(6, 6)) < 1e-12


def test_mask_and_update_only() -> None:
    o = _objects()
    bank = BatchEKF(FilterOptions(), STATION_LIST)
    full = bank.step(o["x"], o["P"], o["dt"], o["z"], R, o["t"], o["station"])
    mask = np.arange(len(o["x"])) % 3 == 0
    part = bank.step(o["x"], o["P"], o["dt"], o["z"], R, o["t"], o["station"], mask=mask)
    assert (part.code[~mask] == Code.NOT_MEASURED).all() and (part.code[mask] == 0).all()
    assert np.array_equal(part.x[~mask], o["x"][~mask])
    assert np.array_equal(part.P[~mask], o["P"][~mask])
    np.testing.assert_allclose(part.x[mask], full.x[mask], rtol=1e-14, atol=0)
    np.testing.assert_allclose(part.P[mask], full.P[mask], rtol=1e-12, atol=1e-18)
    assert np.isnan(part.nis[~mask]).all() and np.isfinite(part.nis[mask]).all()
    # a mask is one bool per object: an index list or a wrong length is an error
    for bad in ([0, 2], mask[:-1], np.r_[mask, True]):
        with pytest.raises(ValueError, match="mask must be a boolean array"):
            bank.step(o["x"], o["P"], o["dt"], o["z"], R, o["t"], o["station"], mask=bad)
    # dt == 0: an update without prediction, as ExtendedKalmanFilter.update
    up = bank.update(o["x"], o["P"], o["z"], R, T0, o["station"])
    for i in range(len(o["x"])):
        model = RazelModel(STATION_LIST[int(o["station"][i])], UNIX_EPOCH_JD)
        kf = ExtendedKalmanFilter(o["x"][i], P0)
        res = kf.update(o["z"][i], lambda x, m=model: m.h_and_H(x, T0), R, model.angle_mask,
                        1000.0)
        assert res.accepted == (up.code[i] == Code.FUSED)
        if res.accepted:
            assert _rel(up.x[i], kf.x) < TOL and _rel(up.P[i], kf.P) < TOL
            assert abs(up.nis[i] - res.nis) <= 1e-9 * res.nis


def test_bad_input_rejected_per_object() -> None:
    o = _objects()
    bank = BatchEKF(FilterOptions(), STATION_LIST)
    clean = bank.step(o["x"], o["P"], o["dt"], o["z"], R, o["t"], o["station"])
    z, x = o["z"].copy(), o["x"].copy()
    Rs = np.tile(R, (len(x), 1, 1))
    z[1, 0] = math.nan
    x[2, 4] = math.inf
    Rs[3, 1, 1] = math.nan
    z[4, 0] = -1.0
    z[5, 2] = 2.0
    z[6, 0] += 1e4  # 10,000 km off: beyond the gate
    x[7, :3] = 0.0  # r0 = 0: no Kepler solution
    before_x, before_P = x.copy(), o["P"].copy()
    out = bank.step(x, o["P"], o["dt"], z, Rs, o["t"], o["station"])
    expected = {1: Cause.REJECTED_NONFINITE, 2: Cause.REJECTED_NONFINITE,
                3: Cause.REJECTED_NONFINITE, 4: Cause.REJECTED_NEGATIVE_RANGE,
                5: Cause.REJECTED_ELEVATION, 6: Cause.REJECTED_GATE,
                7: Cause.REJECTED_NUMERIC}
    for i in range(len(x)):
        if i in expected:
            assert out.reason(i) == expected[i]
            # a rejected object keeps its state (its prediction is dropped too)
            assert np.array_equal(out.x[i], before_x[i], equal_nan=True)
            assert np.array_equal(out.P[i], before_P[i])
        else:
            assert out.reason(i) == REASONS[Code.FUSED] == ""
            np.testing.assert_allclose(out.x[i], clean.x[i], rtol=1e-15, atol=0)
            np.testing.assert_allclose(out.P[i], clean.P[i], rtol=1e-13, atol=1e-20)
    assert out.nis[6] > 1000.0 and np.isnan(out.nis[1])


def test_sigma_bound_and_inplace() -> None:
    o = _objects()
    cfg = FilterOptions().with_(sigma_bound=1e-4, q=1e-6)  # a bound that bites after a long gap
    bank = BatchEKF(cfg, STATION_LIST)
    pred = bank.predict(o["x"], o["P"], o["dt"] * 50.0, T0)
    assert pred.ok.all()
    for i in range(len(o["x"])):
        xr, F = kepler.propagate(o["x"][i], float(o["dt"][i]) * 50.0)
        Pr = F @ P0 @ F.T + process_noise(float(o["dt"][i]) * 50.0, 1e-6)
        Pr = bound_covariance(xr, 0.5 * (Pr + Pr.T), 1e-4)
        assert _rel(pred.P[i], Pr) < TOL
    x, P = o["x"].copy(), o["P"].copy()
    out = bank.step(x, P, o["dt"], o["z"], R, o["t"], o["station"], inplace=True)
    assert out.x is x and out.P is P and not np.array_equal(x, o["x"])


def test_input_layouts() -> None:
    """Broadcast, scalar, list, strided, Fortran-ordered and read-only inputs: the same cycle."""
    o = _objects()
    bank = BatchEKF(FilterOptions(), STATION_LIST)
    n = len(o["x"])
    ref = bank.step(o["x"], o["P"], 30.0, o["z"], np.tile(R, (n, 1, 1)), np.full(n, T0 + 30.0),
                    np.full(n, 2))
    P_ro = np.asfortranarray(o["P"])
    P_ro.flags.writeable = False
    wide = np.zeros((n, 12))
    wide[:, ::2] = o["x"]
    out = bank.step(wide[:, ::2], P_ro, 30.0, o["z"].tolist(), R, T0 + 30.0, 2)
    assert np.array_equal(out.code, ref.code)
    assert np.array_equal(out.x, ref.x) and np.array_equal(out.P, ref.P)
    x1, phi, ok = kepler_stm(o["x"][0].tolist(), 30.0)
    assert x1.shape == (1, 6) and phi.shape == (1, 6, 6) and ok.all()
    assert np.array_equal(x1[0], kepler_stm(o["x"], 30.0)[0][0])


@pytest.mark.parametrize("model,params", [("j2", {}), ("two_body", {}),
                                          ("j2", {"mu": 4.0e5, "j2": 2e-3, "re": 6400.0})])
def test_compiled_integration_equals_numpy(model: str, params: dict[str, float]) -> None:
    """The compiled two-body/J2 integration with its STM equals the numpy path to ~1e-12.

    Every orbit regime, steps of both signs, dt = 0, a day-long step, two step lengths and
    the model's parameters as given (not its defaults); a non-finite input gives what the
    numpy path gives (no step: x1 = x, Phi = I, not ok).
    """
    from ssa_fusion.core.motion.propagation import _integrate_stm_numpy

    o = _objects(n=24, seed=11)
    x = o["x"].copy()
    dt = o["dt"] * np.where(np.arange(24) % 2 == 0, 1.0, -1.0)  # both signs
    dt[3], dt[4] = 0.0, 86400.0
    x[5, 2] = math.nan
    dt[6] = math.inf
    for max_step in (60.0, 25.0):
        x1, phi, ok = integrate_stm(model, x, dt, max_step, **params)
        x2, phi2, ok2 = _integrate_stm_numpy(model, x, dt, max_step, **params)
        assert np.array_equal(ok, ok2) and ok.sum() == 22 and not ok[5] and not ok[6]
        assert np.array_equal(x1[~ok], x2[~ok], equal_nan=True)
        assert np.array_equal(phi[~ok], phi2[~ok]) and (phi[~ok] == np.eye(6)).all()
        assert np.array_equal(x1[3], x[3]) and np.array_equal(phi[3], np.eye(6))
        for i in np.flatnonzero(ok):
            assert _rel(x1[i], x2[i]) < 1e-12 and _rel(phi[i], phi2[i]) < 1e-12, i
    # one state, a scalar step: shapes as the numpy path's
    one = integrate_stm(model, x[0].tolist(), 30.0, **params)
    assert one[0].shape == (1, 6) and one[1].shape == (1, 6, 6) and one[2].all()


def test_numpy_integration_kept_where_not_compiled() -> None:
    """"drag" (and a parameter the model does not take) go through the numpy path as before."""
    from ssa_fusion.core.motion.propagation import _integrate_stm_numpy

    o = _objects(n=6)
    a = integrate_stm("drag", o["x"], o["dt"], bc=50.0)
    b = _integrate_stm_numpy("drag", o["x"], o["dt"], bc=50.0)
    assert all(np.array_equal(u, v) for u, v in zip(a, b, strict=True)) and a[2].all()
    with pytest.raises(TypeError):
        integrate_stm("j2", o["x"], o["dt"], bc=50.0)
    with pytest.raises(ValueError, match="is not one of"):
        integrate_stm("kepler", o["x"], o["dt"])


def test_j2_acts_about_the_earths_pole_in_the_gcrf() -> None:
    """J2 is symmetric about the Earth's axis, so it conserves the component of the angular
    momentum along it: with `pole_frame` that component (about the CIP) is constant over a
    day while the one along the GCRF z axis (0.14 deg away in 2025) drifts; and the compiled
    J2 about the pole equals turning the states to the pole's axes by hand (and the numpy
    path, which does that)."""
    from ssa_fusion.core.earth import frames

    t0 = 1.7355e9
    x0 = elements_to_state(6778.0, 0.001, math.radians(51.6), 1.0, 0.5, 0.2)[None]
    pole = frames.pole_frame(t0)
    p = frames.cip_gcrs(t0)
    assert math.degrees(math.acos(p[2])) == pytest.approx(0.14, abs=0.02)
    x1, phi, ok = integrate_stm("j2", x0, 86400.0, pole_frame=pole)
    assert ok.all()
    h0, h1 = np.cross(x0[0, :3], x0[0, 3:]), np.cross(x1[0, :3], x1[0, 3:])
    assert abs((h1 - h0) @ p) / np.linalg.norm(h0) < 1e-8  # integration error: ~3e-10
    assert abs((h1 - h0)[2]) / np.linalg.norm(h0) > 1e-5  # not conserved about GCRF z
    xr, phir, _ = integrate_stm("j2", dynamics.rotate_states(x0, pole), 86400.0)
    np.testing.assert_allclose(x1, dynamics.rotate_states(xr, pole.T), rtol=0, atol=1e-9)
    B = np.kron(np.eye(2), pole)
    np.testing.assert_allclose(phi[0], B.T @ phir[0] @ B, rtol=1e-11, atol=1e-12)
    xn, phin, _ = propagation._integrate_stm_numpy("j2", dynamics.rotate_states(x0, pole), 86400.0)
    np.testing.assert_allclose(x1, dynamics.rotate_states(xn, pole.T), rtol=0, atol=1e-8)
    np.testing.assert_allclose(phi[0], B.T @ phin[0] @ B, rtol=1e-9, atol=1e-12)
    # the numpy (scipy) truth propagator takes the same pole
    ref = dynamics.propagate("j2", x0[0], np.array([0.0, 86400.0]), pole_frame=pole)
    np.testing.assert_allclose(x1[0], ref[-1], rtol=0, atol=1e-5)

"""Tests for ssa_fusion.core.od.batch_ls: batch least squares over a window of radar passes.

References: the closed-form weighted least squares and the Kalman filter (information
form: with no process noise its final estimate is the batch estimate with the same prior)
on a linear problem; noise-free measurements of a two-body + J2 (+ drag) truth integrated
by `force_model` (the fit must recover it to round-off); the chi-square distribution of
the normalised estimation errors of a consistent estimator; and the linear consider and
process-noise covariances built by brute force.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import pytest
from scipy.stats import chi2

from ssa_fusion.core.base.types import Kind, Measurement
from ssa_fusion.core.earth import frames
from ssa_fusion.core.earth.frames import COLUMBUS
from ssa_fusion.core.earth.timescales import UNIX_EPOCH_JD
from ssa_fusion.core.filter.ekf import ExtendedKalmanFilter
from ssa_fusion.core.filter.process_noise import snc
from ssa_fusion.core.measure.measurement import StationModels
from ssa_fusion.core.motion import force_model as fm
from ssa_fusion.core.motion.dynamics import elements_to_state
from ssa_fusion.core.od import batch_ls as bl
from ssa_fusion.sim.scenarios import ISS_ELEMENTS, ORBIT_EPOCH_UNIX

SIGMA = np.array([0.02, math.radians(0.02), math.radians(0.02)])  # the columbus radar's
R = np.diag(SIGMA**2)
MODELS = StationModels({"columbus": COLUMBUS}, UNIX_EPOCH_JD, light_time=True)
RAZEL = MODELS.get(Kind.RANGE_AZ_EL, "columbus")
EXACT = bl.SolverOptions(correction_tol=1e-6, rms_rtol=0.0, max_iterations=20)
"""Iterate until the correction is round-off (for comparisons to round-off)."""


@dataclass
class World:
    """A noise-free truth and its radar passes: t (N,), x (N, 6) at the measurements."""

    force: fm.ForceModel
    params: np.ndarray
    t: np.ndarray
    x: np.ndarray
    z: np.ndarray

    @property
    def epoch(self) -> float:
        return float(self.t[-1])

    @property
    def x_epoch(self) -> np.ndarray:
        return self.x[-1]

    def measurements(self, rng: np.random.Generator | None = None) -> list[Measurement]:
        z = self.z.copy()
        if rng is not None:
            z += rng.standard_normal(z.shape) * SIGMA
        return [Measurement(float(t), zi, R.copy(), Kind.RANGE_AZ_EL, frame_id="columbus")
                for t, zi in zip(self.t, z, strict=True)]

    def truth(self, t: np.ndarray) -> np.ndarray:
        return fm.trajectory(self.force, self.x_epoch, self.epoch, t, self.params,
                             pole=frames.pole_frame(self.epoch)[2]).x


def _world(force: fm.ForceModel, params: tuple[float, ...] = fm.NOMINAL,
           n_passes: int = 3) -> World:
    """The ISS over Columbus from ORBIT_EPOCH_UNIX: its first passes, every 10 s above 10 deg."""
    t0 = ORBIT_EPOCH_UNIX
    x0 = elements_to_state(**ISS_ELEMENTS)
    t = t0 + np.arange(0.0, 12 * 3600.0, 10.0)
    tr = fm.trajectory(force, x0, t0, t, params, pole=frames.pole_frame(t0)[2])
    up = frames.razel_gcrs(tr.x, t, COLUMBUS)[:, 2] >= math.radians(10.0)
    tv = t[up]
    starts = np.concatenate([[0], np.flatnonzero(np.diff(tv) > 600.0) + 1])
    tv = tv[: starts[n_passes]] if starts.size > n_passes else tv
    epoch, x_epoch = float(tv[-1]), tr.x[up][tv.size - 1]
    # the truth at the measurements, from the epoch with its pole (the fit's integration)
    x = fm.trajectory(force, x_epoch, epoch, tv, params, pole=frames.pole_frame(epoch)[2]).x
    z = np.array([RAZEL.h(xi, float(ti)) for ti, xi in zip(tv, x, strict=True)])
    return World(force, np.array(params, dtype=float), tv, x, z)


@pytest.fixture(scope="module")
def j2_world() -> World:
    return _world(fm.ForceModel())


@pytest.fixture(scope="module")
def drag_world() -> World:
    return _world(fm.ForceModel(drag=True), (1.7, 0.0, 0.0, 0.0))


# ------------------------------------------------------------------------------------------
# A linear problem: closed form and Kalman filter
# ------------------------------------------------------------------------------------------
def test_linear_problem_equals_closed_form_and_kalman_filter() -> None:
    rng = np.random.default_rng(7)
    n, dt = 4, 2.0
    F = np.eye(4)
    F[0, 2] = F[1, 3] = dt
    H = np.array([[1.0, 0.0, 0.0, 0.0], [0.0, 1.0, 0.0, 0.0]])
    Rl = np.array([[0.5, 0.2], [0.2, 0.8]])
    x_true = np.array([1.0, -2.0, 0.3, 0.1])
    x_ap, P0 = np.array([0.0, 0.0, 0.0, 0.0]), np.diag([10.0, 10.0, 1.0, 1.0])
    k = 25
    Fk = [np.linalg.matrix_power(F, i) for i in range(1, k + 1)]  # epoch 0 -> step i
    zs = [H @ f @ x_true + np.linalg.cholesky(Rl) @ rng.standard_normal(2) for f in Fk]
    W = np.linalg.inv(np.linalg.cholesky(Rl))

    def evaluate(x: np.ndarray) -> bl.Linearization:
        r = np.concatenate([W @ (z - H @ f @ x) for z, f in zip(zs, Fk, strict=True)])
        J = np.vstack([W @ H @ f for f in Fk])
        return bl.Linearization(r, J, np.repeat(np.arange(k), 2), k)

    no_edit = bl.SolverOptions(edit_sigma=math.inf, first_edit_sigma=math.inf)
    sol = bl.gauss_newton(evaluate, np.array([5.0, 5.0, -1.0, 1.0]), no_edit, x_ap,
                          np.linalg.inv(P0))
    assert sol.status == bl.FitStatus.CONVERGED, sol.reason
    # closed form: (sum F^T H^T R^-1 H F + P0^-1)^-1 (sum F^T H^T R^-1 z + P0^-1 x_ap)
    Ri = np.linalg.inv(Rl)
    N = np.linalg.inv(P0) + sum(f.T @ H.T @ Ri @ H @ f for f in Fk)
    b = np.linalg.inv(P0) @ x_ap + sum(f.T @ H.T @ Ri @ z for z, f in zip(zs, Fk, strict=True))
    np.testing.assert_allclose(sol.x, np.linalg.solve(N, b), rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(sol.P, np.linalg.inv(N), rtol=1e-10, atol=1e-14)
    # the Kalman filter, no process noise, from the same prior: at step k it holds F^k x_hat
    kf = ExtendedKalmanFilter(x_ap, P0)
    for z in zs:
        kf.predict(lambda x: (F @ x, F), np.zeros((n, n)))
        kf.update(z, lambda x: (H @ x, H), Rl)
    Fn = Fk[-1]
    np.testing.assert_allclose(kf.x, Fn @ sol.x, rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(kf.P, Fn @ sol.P @ Fn.T, rtol=1e-9, atol=1e-13)
    assert sol.iterations <= 3  # linear: one correction, then the check


def test_underdetermined_is_reported() -> None:
    def evaluate(x: np.ndarray) -> bl.Linearization:  # one channel, two unknowns
        return bl.Linearization(np.array([1.0 - x[0] - x[1]]), np.array([[1.0, 1.0]]),
                                np.array([0]), 1)

    sol = bl.gauss_newton(evaluate, np.zeros(2))
    assert sol.status == bl.FitStatus.UNDERDETERMINED


# ------------------------------------------------------------------------------------------
# The orbit
# ------------------------------------------------------------------------------------------
def test_noise_free_j2_truth_is_recovered(j2_world: World) -> None:
    w = j2_world
    assert w.t.size > 60 and np.ptp(w.t) > 2 * 3600.0  # three passes
    guess = w.x_epoch + np.array([1.0, -0.5, 0.7, 1e-3, -5e-4, 2e-4])
    f = bl.fit(w.measurements(), MODELS, guess, w.epoch,
               bl.BatchOptions(solver=EXACT))
    assert f.status == bl.FitStatus.CONVERGED, f.reason
    assert f.t == w.epoch and f.accepted.all()
    np.testing.assert_allclose(f.x[:3], w.x_epoch[:3], rtol=0, atol=1e-8)  # 10 um
    np.testing.assert_allclose(f.x[3:], w.x_epoch[3:], rtol=0, atol=1e-11)
    assert f.rms < 1e-5
    assert max(np.abs(r).max() for r in f.residuals) < 1e-9


def test_a_window_of_interleaved_kinds_recovers_the_truth(j2_world: World) -> None:
    """Every third measurement a pair of angles: the fit takes each kind at its own state.

    Two groups of rows (range and angles, angles alone) whose measurements interleave: a
    group's states are those of its own measurements (a fit that took another's diverged or
    raised IndexError on a radar network's windows).
    """
    w = j2_world
    meas = w.measurements()
    radec = MODELS.get(Kind.RA_DEC, "columbus")
    assert radec is not None
    mixed = [Measurement(m.t, radec.h(w.x[i], m.t), np.diag([1e-10, 1e-10, 0.0]), Kind.RA_DEC,
                         frame_id="columbus") if i % 3 == 1 else m for i, m in enumerate(meas)]
    guess = w.x_epoch + np.array([1.0, -0.5, 0.7, 1e-3, -5e-4, 2e-4])
    f = bl.fit(mixed, MODELS, guess, w.epoch, bl.BatchOptions(solver=EXACT))
    assert f.status == bl.FitStatus.CONVERGED, f.reason
    np.testing.assert_allclose(f.x[:3], w.x_epoch[:3], rtol=0, atol=1e-8)
    np.testing.assert_allclose(f.x[3:], w.x_epoch[3:], rtol=0, atol=1e-11)
    assert max(np.abs(r).max() for r in f.residuals) < 1e-9


def test_guess_at_another_epoch(j2_world: World) -> None:
    """A first guess at an epoch other than the fit's is propagated there first."""
    w = j2_world
    t_g = float(w.t[0])
    f = bl.fit(w.measurements(), MODELS, w.x[0] + np.r_[0.5, 0.5, 0.5, 0, 0, 0], t_g)
    assert f.converged and f.t == w.epoch
    np.testing.assert_allclose(f.x[:3], w.x_epoch[:3], atol=1e-6)
    # and an epoch inside the window (measurements on both sides of it)
    t_mid = float(w.t[w.t.size // 2])
    f = bl.fit(w.measurements(), MODELS, w.x[0], t_g, bl.BatchOptions(snc_psd=(1e-14,) * 3),
               epoch=t_mid)
    assert f.converged and f.t == t_mid
    np.testing.assert_allclose(f.x[:3], w.x[w.t.size // 2, :3], atol=1e-6)
    assert np.linalg.eigvalsh(f.P_realistic - f.P).min() > -1e-15


@pytest.mark.parametrize("solve", [("drag_scale",), ("drag_scale", "accel_t")])
def test_drag_scale_is_recovered(drag_world: World, solve: tuple[str, ...]) -> None:
    w = drag_world
    opts = bl.BatchOptions(force=fm.ForceModel(drag=True), solve_for=solve, solver=EXACT,
                           param_sigma=(math.inf, math.inf, math.inf, math.inf))
    f = bl.fit(w.measurements(), MODELS, w.x_epoch + np.r_[0.3, 0.3, 0.3, 0, 0, 0], w.epoch,
               opts)
    assert f.converged, f.reason
    assert f.params["drag_scale"] == pytest.approx(1.7, rel=1e-5)
    assert f.P.shape == (6 + len(solve),) * 2
    np.testing.assert_allclose(f.x[:3], w.x_epoch[:3], atol=1e-7)
    if "accel_t" in solve:
        assert abs(f.params["accel_t"]) < 1e-14
    # without drag in the model the fit is worse and says so by its RMS
    j2 = bl.fit(w.measurements(), MODELS, w.x_epoch, w.epoch)
    assert j2.rms > 1e3 * f.rms


def test_constant_along_track_acceleration_is_recovered() -> None:
    """A truth with a known constant along-track acceleration (3e-9 km/s^2, no drag): the fit
    that solves for it recovers it and the state; the fit without it misses by its RMS."""
    accel = 3e-9
    w = _world(fm.ForceModel(), (1.0, 0.0, accel, 0.0))
    opts = bl.BatchOptions(solve_for=("accel_t",), solver=EXACT,
                           param_sigma=(math.inf, math.inf, math.inf, math.inf))
    f = bl.fit(w.measurements(), MODELS, w.x_epoch + np.r_[0.3, 0.3, 0.3, 0, 0, 0], w.epoch,
               opts)
    assert f.converged, f.reason
    assert f.params["accel_t"] == pytest.approx(accel, rel=1e-5)
    assert f.params["accel_r"] == f.params["accel_n"] == 0.0
    np.testing.assert_allclose(f.x[:3], w.x_epoch[:3], atol=1e-7)
    without = bl.fit(w.measurements(), MODELS, w.x_epoch, w.epoch)
    assert without.rms > 1e3 * f.rms


def test_solve_for_needs_drag() -> None:
    with pytest.raises(ValueError, match="drag"):
        bl.BatchOptions(solve_for=("drag_scale",))
    with pytest.raises(ValueError, match="both"):
        bl.BatchOptions(solve_for=("accel_t",), consider=("accel_t",))


def test_normalised_errors_are_chi_square(j2_world: World) -> None:
    """50 noise draws: the epoch errors' NEES (6 dof) average within the band of a mean."""
    w = j2_world
    rng = np.random.default_rng(2024)
    nees = []
    for _ in range(50):
        f = bl.fit(w.measurements(rng), MODELS, w.x_epoch + np.r_[0.1, 0.1, 0.1, 0, 0, 0],
                   w.epoch)
        assert f.converged, f.reason
        e = f.x - w.x_epoch
        nees.append(float(e @ np.linalg.solve(f.covariance, e)))
    lo, hi = chi2.ppf([0.025, 0.975], 6 * 50) / 50
    assert lo <= np.mean(nees) <= hi, (np.mean(nees), lo, hi)
    assert 0.6 < np.mean(np.array(nees) <= chi2.ppf(0.95, 6)) <= 1.0


def test_outlier_is_edited_out(j2_world: World) -> None:
    w = j2_world
    meas = w.measurements(np.random.default_rng(5))
    k = len(meas) // 2
    bad = [Measurement(m.t, m.z.copy(), m.R, m.kind, frame_id=m.frame_id) for m in meas]
    bad[k].z[0] += 1000.0 * SIGMA[0]
    opts = bl.BatchOptions(solver=EXACT)
    guess = w.x_epoch + np.r_[0.2, -0.2, 0.1, 0, 0, 0]
    with_outlier = bl.fit(bad, MODELS, guess, w.epoch, opts)
    without = bl.fit(meas[:k] + meas[k + 1:], MODELS, guess, w.epoch, opts)
    assert with_outlier.converged and without.converged
    assert not with_outlier.accepted[k]
    assert with_outlier.normalized[k] > 900.0
    np.testing.assert_array_equal(np.delete(with_outlier.accepted, k), without.accepted)
    # the same solution to the convergence test's round-off (1 um, 3e-13 relative)
    np.testing.assert_allclose(with_outlier.x, without.x, rtol=0, atol=1e-9)
    np.testing.assert_allclose(with_outlier.P, without.P, rtol=1e-9, atol=0)


@pytest.mark.parametrize("start", ["inside_earth", "hyperbolic", "geostationary"])
def test_nonsense_start_is_reported_diverged(j2_world: World, start: str) -> None:
    w = j2_world
    x = {"inside_earth": np.array([1000.0, 0.0, 0.0, 1.0, 0.0, 0.0]),
         "hyperbolic": np.r_[w.x_epoch[:3], 3.0 * w.x_epoch[3:]],
         "geostationary": np.array([42164.0, 0.0, 0.0, 0.0, 3.0747, 0.0])}[start]
    f = bl.fit(w.measurements(), MODELS, x, w.epoch)
    assert f.status == bl.FitStatus.DIVERGED
    assert f.reason and not f.converged


def test_prediction_through_a_gap(j2_world: World) -> None:
    w = j2_world
    f = bl.fit(w.measurements(np.random.default_rng(1)), MODELS, w.x_epoch, w.epoch)
    t = bl.grid(f.t, f.t + 3 * 3600.0)
    assert t.size == 180 and np.all(np.diff(t) == 60.0) and t[0] > f.t
    x, P = f.predict(t, realistic=False)
    # the formal covariance is the epoch covariance mapped by the STM
    tr = fm.trajectory(f.options.force, f.x, f.t, t[[0, -1]], pole=f.pole)
    for i, k in enumerate([0, -1]):
        np.testing.assert_allclose(P[k], tr.phi[i] @ f.covariance @ tr.phi[i].T,
                                   rtol=1e-10, atol=1e-18)
        np.testing.assert_allclose(x[k], tr.x[i], rtol=0, atol=1e-12)
    # and the truth lies within it (noise only: the model is the truth's)
    err = x - w.truth(t)
    nees = np.einsum("ki,kij,kj->k", err[:, :3], np.linalg.inv(P[:, :3, :3]), err[:, :3])
    assert np.median(nees) < chi2.ppf(0.99, 3)
    # at the epoch: the fit itself; estimates are StateEstimates on the grid
    x0, P0 = f.predict([f.t])
    np.testing.assert_allclose(x0[0], f.x, atol=1e-12)
    np.testing.assert_allclose(P0[0], f.covariance_realistic, rtol=1e-12, atol=1e-20)
    est = f.estimates(t[:3], object_id="iss")
    assert [e.t for e in est] == t[:3].tolist() and est[0].object_id == "iss"


def test_consider_parameter_maps_its_effect(j2_world: World) -> None:
    """A truth with an along-track acceleration the fit does not estimate: the error it
    causes is, to first order, the consider term (rank one, sigma = the acceleration)."""
    a_t = 3e-9
    w = _world(fm.ForceModel(), (1.0, 0.0, a_t, 0.0))
    opts = bl.BatchOptions(consider=("accel_t",), param_sigma=(1.0, 1e-8, a_t, 1e-8),
                           solver=EXACT)
    f = bl.fit(w.measurements(), MODELS, w.x_epoch, w.epoch, opts)
    assert f.converged, f.reason
    e = f.x - w.x_epoch
    extra = f.P_realistic - f.P
    np.testing.assert_allclose(np.outer(e, e), extra, rtol=0, atol=2e-3 * np.abs(extra).max())
    t = np.array([f.t + 3600.0, f.t + 6 * 3600.0])
    xr, Pr = f.predict(t, realistic=True)
    _, Pf = f.predict(t, realistic=False)
    et = xr - w.truth(t)
    for k in range(2):
        d = Pr[k] - Pf[k]
        np.testing.assert_allclose(np.outer(et[k], et[k]), d, rtol=0,
                                   atol=5e-3 * np.abs(d).max())


def test_window_process_noise_is_the_brute_force_sum(j2_world: World) -> None:
    """P_realistic = P + P J^T C_e J P, C_e the measurements' errors' covariance from the
    process noise between each measurement and the epoch, built here pair by pair."""
    w = j2_world
    meas = w.measurements(np.random.default_rng(3))[::4]  # fewer pairs
    psd = (1e-13, 4e-13, 2e-14)
    opts = bl.BatchOptions(snc_psd=psd, noise_step_s=120.0)
    f = bl.fit(meas, MODELS, w.x_epoch, w.epoch, opts)
    assert f.converged and f.accepted.all()
    # the grid, its STMs, the noise in epoch coordinates accumulated outwards
    tm = np.array([m.t for m in meas])
    nodes = np.unique(np.concatenate([tm, f.t - np.arange(0.0, f.t - tm.min(), 120.0)]))
    nodes = nodes[::-1]  # outwards (backwards in time) from the epoch
    assert nodes[0] == f.t
    tr = fm.trajectory(f.options.force, f.x, f.t, nodes, pole=f.pole)
    cbar = [np.zeros((6, 6))]
    for k in range(1, nodes.size):
        q = snc(tr.x[k], nodes[k] - nodes[k - 1], psd)
        inv = np.linalg.inv(tr.phi[k])
        cbar.append(cbar[-1] + inv @ q @ inv.T)
    at = {float(t): k for k, t in enumerate(nodes)}
    trm = fm.trajectory(f.options.force, f.x, f.t, tm, pole=f.pole)
    W = np.linalg.inv(np.linalg.cholesky(R))
    U = [W @ RAZEL.H(trm.x[i], tm[i]) @ trm.phi[i] for i in range(tm.size)]
    K = np.zeros((6, 6))
    for i in range(tm.size):
        for j in range(tm.size):
            c = cbar[min(at[float(tm[i])], at[float(tm[j])])]
            K += U[i].T @ U[i] @ c @ U[j].T @ U[j]
    expected = f.P + f.P @ K @ f.P
    # P K P through a formal covariance of condition 6e10 and STM inverses: BLAS kernels
    # (OPENBLAS_CORETYPE Haswell vs SkylakeX) differ by up to 7e-9 of the largest entry
    np.testing.assert_allclose(f.P_realistic, expected, rtol=1e-6,
                               atol=1e-8 * np.abs(expected).max())
    # realistic >= formal, and predictions grow by the noise accumulated after the epoch
    assert np.linalg.eigvalsh(f.P_realistic - f.P).min() > -1e-15
    _, Pr = f.predict([f.t + 7200.0])
    _, Pf = f.predict([f.t + 7200.0], realistic=False)
    assert np.trace(Pr[0][:3, :3]) > 1.5 * np.trace(Pf[0][:3, :3])


def test_without_noise_or_consider_realistic_is_formal(j2_world: World) -> None:
    w = j2_world
    f = bl.fit(w.measurements(np.random.default_rng(4)), MODELS, w.x_epoch, w.epoch)
    np.testing.assert_array_equal(f.P_realistic, f.P)
    scaled = bl.fit(w.measurements(np.random.default_rng(4)), MODELS, w.x_epoch, w.epoch,
                    bl.BatchOptions(scale_by_rms=True))
    np.testing.assert_allclose(scaled.P_realistic, max(1.0, scaled.rms**2) * scaled.P)


def test_angle_residuals_are_wrapped(j2_world: World) -> None:
    """Azimuths given as az + 2 pi or az - 2 pi fit as the azimuths themselves."""
    w = j2_world
    meas = w.measurements(np.random.default_rng(8))
    turned = [Measurement(m.t, m.z + np.array([0.0, 2 * np.pi * (-1) ** i, 0.0]), m.R,
                          m.kind, frame_id=m.frame_id) for i, m in enumerate(meas)]
    a = bl.fit(meas, MODELS, w.x_epoch, w.epoch)
    b = bl.fit(turned, MODELS, w.x_epoch, w.epoch)
    assert a.converged and b.converged
    np.testing.assert_allclose(b.x, a.x, rtol=0, atol=1e-9)
    assert max(abs(r[1]) for r in b.residuals) < 0.01

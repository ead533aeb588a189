"""Tests for ssa_fusion.core.gaps.residual: fits on irregular samples against analytic signals,
recovery of an injected acceleration, and the held-out covariance calibration."""

import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from ssa_fusion.core.base.constants import MU_EARTH
from ssa_fusion.core.gaps import forecaster as gap_forecaster
from ssa_fusion.core.gaps import residual, residual_design, residual_frame
from ssa_fusion.core.motion import dynamics
from ssa_fusion.sim.scenarios import ISS_ELEMENTS

X0 = np.array(dynamics.elements_to_state(**ISS_ELEMENTS))


def _passes(rng: np.random.Generator, days: float, per_day: int = 5) -> np.ndarray:
    """Irregular epochs (s): a few pass-like clusters per day, hours apart."""
    starts = np.sort(rng.uniform(0.0, days * 86400.0, int(days * per_day)))
    return np.unique(np.concatenate([starts, starts + rng.uniform(60, 400, len(starts))]))


def _truth(f_along: float, t: np.ndarray) -> np.ndarray:
    """Two-body truth plus a constant along-track (velocity-direction) acceleration f."""

    def rhs(_t: float, y: np.ndarray) -> np.ndarray:
        r, v = y[:3], y[3:]
        a = -MU_EARTH * r / np.linalg.norm(r) ** 3 + f_along * v / np.linalg.norm(v)
        return np.concatenate([v, a])

    sol = solve_ivp(rhs, (0.0, float(t.max())), X0, method="DOP853", rtol=1e-12, atol=1e-12,
                    dense_output=True)
    return sol.sol(t).T


def test_curvilinear_round_trip():
    rng = np.random.default_rng(0)
    ref = np.tile(X0, (5, 1))
    x = ref + np.concatenate([rng.normal(0, 50, (5, 3)), rng.normal(0, 0.05, (5, 3))], axis=1)
    res = residual_frame.state_residual(ref, x)
    back = residual_frame.apply_residual(ref, res)
    np.testing.assert_allclose(back[:, :3], x[:, :3], atol=1e-8)  # km
    np.testing.assert_allclose(back[:, 3:], x[:, 3:], atol=1e-6)  # km/s (differences)


def test_hill_design_matches_the_closed_form_response_to_a_constant_push():
    # Hill from rest under a constant along-track f: x = 2f/n (t - sin(nt)/n),
    # y = -3/2 f t^2 + 4f/n^2 (1 - cos nt) (radial x, along-track y), at any sign of t
    n, f = 2 * math.pi / 5560.0, 1e-8
    t = np.array([-40000.0, -3000.0, 17.0, 5000.0, 60000.0])
    D = residual_design.hill_design(t, n, 0.3, harmonics=0)
    along_const = 6 + 1  # columns: z0 (6), then radial, along, cross constants
    z = D[:, :, along_const] * f
    np.testing.assert_allclose(z[:, 0], 2 * f / n * (t - np.sin(n * t) / n), rtol=1e-9,
                               atol=1e-12)
    np.testing.assert_allclose(z[:, 1], -1.5 * f * t ** 2 + 4 * f / n ** 2 * (1 - np.cos(n * t)),
                               rtol=1e-9, atol=1e-12)
    # the free part is the Hill state transition: a radial offset drifts along track
    np.testing.assert_allclose(D[:, 1, 0], 6 * (np.sin(n * t) - n * t), rtol=1e-9, atol=1e-9)


def test_basis_fit_on_irregular_samples_recovers_an_analytic_signal():
    # a residual-like signal with known frequencies (once and twice per orbit, a drifting
    # once-per-orbit term) and a quadratic drift, sampled only in passes: the fit recovers
    # it and extrapolates it a day ahead
    rng = np.random.default_rng(1)
    period = 5560.0
    t = -_passes(rng, 2.0)[::-1]
    u = 2 * math.pi * t / period + 0.4
    ud = np.full_like(t, 2 * math.pi / period)
    cfg = residual.ResidualConfig(model="basis", degrees=(2, 2, 2))
    B, _ = residual_design.basis(t, u, ud, 2, cfg.harmonics, True, period)
    coef = np.array([0.3, -2.0, 0.05, 1.5, -0.7, 0.2, 0.1, 0.02, -0.03])
    y = B @ coef
    c, *_ = np.linalg.lstsq(B, y, rcond=None)
    np.testing.assert_allclose(c, coef, atol=1e-9)
    t_out = np.linspace(0, 86400.0, 50)
    B_out, _ = residual_design.basis(t_out, 2 * math.pi * t_out / period + 0.4,
                              np.full(50, 2 * math.pi / period), 2, 2, True, period)
    np.testing.assert_allclose(B_out @ c, B_out @ coef, atol=1e-7)


@pytest.mark.parametrize("model", ["hill", "basis"])
def test_recovers_an_injected_constant_along_track_acceleration(model):
    # two-body truth + f along track; two-body placeholder; anchors only in passes
    f = 2e-8  # km/s^2
    rng = np.random.default_rng(0)
    t_anchor = np.concatenate([_passes(rng, 2.0), [2 * 86400.0]])
    t_out = 2 * 86400.0 + np.linspace(300.0, 16 * 3600.0, 40)
    x = _truth(f, np.concatenate([t_anchor, t_out]))
    xa, x_out = x[:len(t_anchor)], x[len(t_anchor):]
    P = np.tile(np.diag([1e-4] * 3 + [1e-10] * 3), (len(t_anchor), 1, 1))
    prop = residual_frame.orbit_propagator("two_body")
    fit = residual.fit_residual(residual.ResidualConfig(model=model), prop, t_anchor, xa, P)
    assert fit is not None
    assert fit.along_track_acceleration() == pytest.approx(f, rel=0.05)
    xf, _ = fit.predict(t_out)
    coast = prop(xa[-1], t_anchor[-1], t_out)
    err = np.linalg.norm(xf[:, :3] - x_out[:, :3], axis=1).max()
    err_coast = np.linalg.norm(coast[:, :3] - x_out[:, :3], axis=1).max()
    assert err_coast > 50.0  # 16 h of 2e-8 km/s^2: ~1.5 f t^2 ~ 100 km
    assert err < 0.02 * err_coast


def test_held_out_calibration_makes_an_overconfident_fit_honest():
    # anchors carry noise 10x larger than their stated covariance: the formal covariance
    # is too small; the held-out scale measured on earlier fits must bring the normalised
    # errors of later forecasts near 1
    f = 1e-8
    rng = np.random.default_rng(3)
    t = _passes(rng, 3.0, per_day=4)
    x_true = _truth(f, t)
    sig_true = np.array([0.05] * 3 + [5e-5] * 3)
    x = x_true + rng.standard_normal(x_true.shape) * sig_true
    P = np.diag((sig_true / 10.0) ** 2)
    cfg = residual.ResidualConfig(model="hill", harmonics=0, window_s=86400.0,
                                  min_span_s=0.5 * 86400.0, prior_scale=1.0)
    sur = residual.ResidualSurrogate(cfg, residual_frame.orbit_propagator("two_body"))
    scored, made = [], []
    for k in range(len(t)):
        # score earlier calibrated fits here (out of sample), as the true error allows
        for fit in made:
            if 0 < t[k] - fit.t0 <= cfg.max_horizon_s:
                xf, Pf = fit.predict(t[k:k + 1])
                e = x_true[k] - xf[0]
                scored.append(float(e @ np.linalg.solve(Pf[0], e)) / 6.0)
        sur.add_anchor(t[k], x[k], P)
        fit = sur.fit()
        if fit is not None and len(sur.heldout) >= 8:
            made.append(fit)
    assert len(sur.heldout) > 20 and len(scored) > 10
    assert sur.scale[0] + sur.scale[1] > 5.0  # the formal covariance was far too small
    ratio = float(np.mean(scored))  # normalised error variance of calibrated forecasts
    assert 0.3 < ratio < 3.0, ratio


def test_gap_forecaster_on_a_filter_stream_forecasts_the_gap_and_never_a_pass():
    """The live wrapper: estimates after real measurements (in passes, 2 days of a two-body +
    2e-8 km/s^2 along-track truth) go in; in the gap after the last pass it returns the
    residual model's forecast on the period grid (closer to the truth than coasting), and
    nothing within `pass_break_s` of the pass's end."""
    f = 2e-8
    rng = np.random.default_rng(0)
    t_pass = np.concatenate([_passes(rng, 2.0), [2 * 86400.0]])
    x = _truth(f, t_pass)
    P = np.diag([1e-4] * 3 + [1e-10] * 3)
    gf = gap_forecaster.GapForecaster.for_model("kepler", 60.0)
    for ti, xi in zip(t_pass, x, strict=True):
        gf.on_estimate(float(ti), xi, P)  # pass ends become anchors as the next pass starts
    t_end = float(t_pass[-1])
    assert len(gf.surrogate.t) >= 5  # every earlier pass end
    assert gf.forecast(t_end + 300.0) is None  # inside pass_break_s: still the pass
    t_gap = 60.0 * np.arange(math.ceil((t_end + 600.0) / 60.0), (t_end + 8 * 3600.0) // 60.0)
    got = [gf.forecast(float(t)) for t in t_gap]
    assert all(g is not None for g in got)
    truth = _truth(f, t_gap)
    coast = residual_frame.orbit_propagator("two_body")(x[-1], t_end, t_gap)
    err = max(np.linalg.norm(g[0][:3] - xt[:3]) for g, xt in zip(got, truth, strict=True))
    err_coast = np.linalg.norm(coast[:, :3] - truth[:, :3], axis=1).max()
    assert err_coast > 10.0 and err < 0.05 * err_coast
    assert gf.forecast(t_end + 300.5) is None  # off the grid
    # the chosen live setting is the study's choice
    from ssa_fusion.studies import gap_study

    assert gap_study.tuning_candidates()[gap_study.CHOSEN] == residual.LIVE_RESIDUAL


def test_the_surrogate_keeps_only_what_later_fits_can_use():
    """On a stream of any length, the anchors older than the window before the newest and
    the held-out scores beyond the newest `calibration_samples` are let go."""
    cfg = residual.ResidualConfig(window_s=86400.0, calibration_samples=4)
    sur = residual.ResidualSurrogate(cfg, residual_frame.orbit_propagator("two_body"))
    P = np.eye(6)
    for k in range(200):
        sur.heldout.append((1.0, 0.1))  # as add_anchor would score earlier fits
        sur.add_anchor(k * 21600.0, X0, P)
    assert sur.t == [k * 21600.0 for k in range(195, 200)]  # within a day of the newest
    assert len(sur.x) == len(sur.P) == 5 and len(sur.heldout) == 4


def test_the_placeholder_takes_epochs_in_any_order_repeats_included():
    prop = residual_frame.orbit_propagator("two_body")
    t = np.array([600.0, -300.0, 600.0, 0.0, 1200.0, -300.0])
    got = prop(X0, 0.0, t)
    once = prop(X0, 0.0, np.array([-300.0, 0.0, 600.0, 1200.0]))
    want = once[[2, 0, 2, 1, 3, 0]]
    np.testing.assert_array_equal(got, want)
    np.testing.assert_allclose(got[3], X0, rtol=0, atol=1e-9)


def test_hill_design_on_a_uniform_grid_keeps_the_closed_form_for_a_day():
    # a day of 60 s steps, taken as products of one step's exponential between fresh ones
    n, f = 2 * math.pi / 5560.0, 1e-8
    t = 60.0 * np.arange(1, 1441) + 17.3
    D = residual_design.hill_design(t, n, 0.3, harmonics=0)
    z = D[:, :, 7] * f  # constant along-track push
    x = 2 * f / n * (t - np.sin(n * t) / n)
    y = -1.5 * f * t ** 2 + 4 * f / n ** 2 * (1 - np.cos(n * t))
    assert np.abs(z[:, 0] - x).max() < 1e-11 * np.abs(x).max()  # measured 5e-13
    assert np.abs(z[:, 1] - y).max() < 1e-11 * np.abs(y).max()
    free = 6 * (np.sin(n * t) - n * t)  # a radial offset drifts along track
    assert np.abs(D[:, 1, 0] - free).max() < 1e-11 * np.abs(free).max()


def _hill_design_per_block(tau, n, u0, harmonics, components=(True, True, True)):
    """The Hill design as one copy of the residual state per (axis, forcing term), each
    forced by its term alone, with the oscillator appended: a 6 (3 q) + q generator, one
    exponential per epoch (the reference `hill_design`'s smaller generator must equal)."""
    from scipy.linalg import expm

    q = 1 + 2 * harmonics
    Om = np.zeros((q, q))
    for j in range(1, harmonics + 1):
        Om[2 * j - 1, 2 * j], Om[2 * j, 2 * j - 1] = -j * n, j * n
    w0 = np.ones(q)
    for j in range(1, harmonics + 1):
        w0[2 * j - 1], w0[2 * j] = math.cos(j * u0), math.sin(j * u0)
    blocks = [(c, i) for c in range(3) if components[c] for i in range(q)]
    nb = len(blocks)
    M = np.zeros((6 * nb + q, 6 * nb + q))
    for b, (c, i) in enumerate(blocks):
        M[6 * b:6 * b + 6, 6 * b:6 * b + 6] = residual_design.hill_matrix(n)
        M[6 * b + 3 + c, 6 * nb + i] = 1.0
    M[6 * nb:, 6 * nb:] = Om
    out = np.zeros((len(tau), 6, 6 + nb))
    for k, t in enumerate(np.asarray(tau, float)):
        E = expm(M * t)
        out[k, :, :6] = E[:6, :6]
        out[k, :, 6:] = (E[:6 * nb, 6 * nb:] @ w0).reshape(nb, 6).T
    return out


@pytest.mark.parametrize("harmonics, components", [(1, (True, True, True)),
                                                   (2, (True, False, True))])
def test_hill_design_equals_one_copy_of_the_state_per_forcing_term(harmonics, components):
    rng = np.random.default_rng(4)
    for period in (5560.0, 43082.0, 86164.0):  # LEO, MEO, GEO
        n = 2 * math.pi / period
        u0 = rng.uniform(0.0, 2 * math.pi)
        tau = np.concatenate([-np.sort(rng.uniform(0.0, 2 * 86400.0, 20)),  # a window
                              600.0 * np.arange(1, 145) + 17.0])  # a day's grid
        got = residual_design.hill_design(tau, n, u0, harmonics, components)
        want = _hill_design_per_block(tau, n, u0, harmonics, components)
        scale = np.abs(want).max(axis=0)  # per row and column, over the epochs
        assert np.all(got[:, scale == 0.0] == 0.0)  # structural zeros stay zero
        scale[scale == 0.0] = 1.0
        # measured <= 2.5e-7: the per-block exponential's own error (5e-8 of an extended
        # precision one on a LEO window; hill_design's 2e-12)
        assert (np.abs(got - want) / scale).max() < 1e-6


def test_hill_design_matches_hill_integrated_under_a_once_per_revolution_push():
    # the response to a cos u push along each axis against Hill's equations integrated
    # numerically (rtol 1e-12), a few hours either side of the anchor
    n, u0 = 2 * math.pi / 5560.0, 0.7
    tau = np.array([-20000.0, -7000.0, -300.0, 450.0, 9000.0, 21000.0])
    D = residual_design.hill_design(tau, n, u0, harmonics=1)
    A = residual_design.hill_matrix(n)
    for c in range(3):
        col = 6 + 3 * c + 1  # axis c's cos u term
        for side in (tau[tau > 0], tau[tau < 0][::-1]):
            def rhs(t, z, c=c):
                d = A @ z
                d[3 + c] += math.cos(u0 + n * t)
                return d
            sol = solve_ivp(rhs, (0.0, side[-1]), np.zeros(6), method="DOP853", rtol=1e-12,
                            atol=1e-14, t_eval=side)
            got = D[np.searchsorted(tau, side), :, col]
            scale = np.abs(sol.y.T).max(axis=0)
            np.testing.assert_allclose(got, sol.y.T, rtol=0, atol=1e-8 * scale.max())


def test_forecasts_with_the_smaller_generator_equal_the_per_block_ones(monkeypatch):
    # two and a half days of pass-end estimates of a two-body + along-track-push truth through the
    # live forecaster, with `hill_design` and with the per-block reference: the forecasts
    # agree to 1 cm and 1e-4 of the covariance (measured on 300 catalog objects: 0.4 mm)
    t = _passes(np.random.default_rng(5), 2.5)
    x = _truth(2e-9, t)
    grid = 600.0 * (math.floor(t[-1] / 600.0) + np.arange(2, 32))  # the gap's grid epochs

    def forecasts():
        g = gap_forecaster.GapForecaster.for_model("kepler", 600.0, residual.LIVE_RESIDUAL)
        g.pass_break_s = 600.0
        P = np.diag([1e-6] * 3 + [1e-12] * 3)
        for ti, xi in zip(t, x, strict=True):
            g.on_estimate(float(ti), xi, P)
        return [g.forecast(float(tg)) for tg in grid]

    got = forecasts()
    monkeypatch.setattr(residual, "hill_design", _hill_design_per_block)
    want = forecasts()
    assert sum(w is not None for w in want) > 10
    for a, b in zip(got, want, strict=True):
        assert (a is None) == (b is None)
        if a is not None:
            assert np.linalg.norm(a[0][:3] - b[0][:3]) < 1e-5  # km
            assert np.abs(a[1] - b[1]).max() < 1e-4 * np.abs(b[1]).max()


def test_the_forecast_tabulated_as_asked_equals_the_whole_grid_at_once():
    # the forecaster tabulates the first hours, then doubles as later epochs are asked
    # for: the same numbers as the fit's prediction on the whole grid, in any order asked
    t = _passes(np.random.default_rng(5), 2.5)
    x = _truth(2e-9, t)
    g = gap_forecaster.GapForecaster.for_model("kepler", 600.0, residual.LIVE_RESIDUAL)
    P = np.diag([1e-6] * 3 + [1e-12] * 3)
    for ti, xi in zip(t, x, strict=True):
        g.on_estimate(float(ti), xi, P)
    first = 600.0 * (math.floor(t[-1] / 600.0) + 2)
    assert g.forecast(first) is not None
    assert 0 < g.tabulated < g.grid.size and g.pending  # not the whole day yet
    assert g.fit is not None
    xs, Ps = g.fit.predict(g.grid)
    asked = np.random.default_rng(6).permutation(g.grid.size)
    asked = asked[g.grid[asked] >= t[-1] + g.pass_break_s]  # a gap's epochs
    for i in asked:
        got = g.forecast(float(g.grid[i]))
        assert got is not None
        np.testing.assert_array_equal(got[0], xs[i])
        np.testing.assert_array_equal(got[1], Ps[i])
    assert g.tabulated == g.grid.size and not g.pending

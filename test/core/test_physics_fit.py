"""Tests for the physics-only gap fit (`residual.PHYSICS_RESIDUAL`, `GapBankConfig.physics`):
its covariance grows through the gap as Hill's closed-form response to its acceleration prior,
its forecast from one pass end is the placeholder's, it covers an unmodelled acceleration
within the prior, and the learned residual takes over once its pass ends span enough."""

import math
from dataclasses import replace

import numpy as np
import pytest
from scipy.integrate import solve_ivp
from scipy.stats import chi2

from ssa_fusion.core.base.constants import MU_EARTH
from ssa_fusion.core.catalog.gap_bank import GapBank, GapBankConfig
from ssa_fusion.core.gaps import residual, residual_design, residual_frame
from ssa_fusion.core.gaps.forecaster import GapForecaster
from ssa_fusion.core.gaps.residual import LIVE_RESIDUAL, PHYSICS_RESIDUAL
from ssa_fusion.core.motion import dynamics
from ssa_fusion.sim.scenarios import ISS_ELEMENTS

X0 = np.array(dynamics.elements_to_state(**ISS_ELEMENTS))
P_SMALL = np.diag([1e-8] * 3 + [1e-14] * 3)  # below the fit's floors (1 m, 1 mm/s)
BOUND = float(chi2.ppf(0.95, 3))


def _one_anchor_fit(sigma: float) -> residual.ResidualFit:
    cfg = replace(PHYSICS_RESIDUAL, accel_sigma=sigma)
    f = residual.fit_residual(cfg, residual_frame.orbit_propagator("j2"), np.array([0.0]), X0[None],
                              P_SMALL[None])
    assert f is not None
    return f


def test_one_pass_end_forecasts_the_placeholder_with_hills_response_to_the_prior():
    t = np.array([600.0, 3000.0, 4 * 3600.0, 12 * 3600.0])
    lo, hi = 1e-9, 3e-8
    f_lo, f_hi = _one_anchor_fit(lo), _one_anchor_fit(hi)
    _, res, cov_lo = f_lo.residual(t)
    _, _, cov_hi = f_hi.residual(t)
    np.testing.assert_allclose(res, 0.0, atol=1e-6)  # one anchor: nothing to correct (1 mm)
    x, _ = f_hi.predict(t)
    np.testing.assert_allclose(x, residual_frame.orbit_propagator("j2")(X0, 0.0, t), atol=1e-6)
    # the prior's share: Hill's closed-form response to constant R, T, N accelerations
    # from rest (radial x, along-track y, cross-track z), per unit acceleration
    n = 2 * math.pi / residual_frame.period_of(X0)
    c, s = np.cos(n * t), np.sin(n * t)
    x_r, x_t = (1 - c) / n ** 2, 2 * (n * t - s) / n ** 2
    y_r, y_t = 2 * (s - n * t) / n ** 2, (4 * (1 - c) - 1.5 * (n * t) ** 2) / n ** 2
    z_n = (1 - c) / n ** 2
    d = hi ** 2 - lo ** 2
    got = cov_hi - cov_lo
    np.testing.assert_allclose(got[:, 0, 0], d * (x_r ** 2 + x_t ** 2), rtol=1e-6)
    np.testing.assert_allclose(got[:, 1, 1], d * (y_r ** 2 + y_t ** 2), rtol=1e-6)
    np.testing.assert_allclose(got[:, 2, 2], d * z_n ** 2, rtol=1e-6)
    assert got[-1, 1, 1] > 100 * cov_lo[-1, 1, 1] - 1e-30  # the prior dominates a long gap




@pytest.mark.parametrize("sigma, covered", [(PHYSICS_RESIDUAL.accel_sigma, True),
                                            (1e-12, False)])
def test_the_covariance_covers_an_unmodelled_acceleration_as_large_as_the_prior(sigma,
                                                                                covered):
    """A two-body truth pushed along track by f = the prior's sigma, one exact pass end,
    a two-body placeholder: the forecast's position NEES stays within chi2(3)'s 95 % bound
    through a 6 h gap (NEES near 1: the push is the prior's sigma); with a prior far below f
    it does not. (Beyond about 8 h, tens of km off, the linear Hill map's own error shows.)"""
    f = PHYSICS_RESIDUAL.accel_sigma
    t = np.arange(600.0, 6 * 3600.0 + 1.0, 600.0)

    def rhs(_t: float, y: np.ndarray) -> np.ndarray:
        r, v = y[:3], y[3:]
        return np.concatenate([v, -MU_EARTH * r / np.linalg.norm(r) ** 3
                               + f * v / np.linalg.norm(v)])

    truth = solve_ivp(rhs, (0.0, float(t.max())), X0, method="DOP853", rtol=1e-12,
                      atol=1e-12, dense_output=True).sol(t).T
    cfg = replace(PHYSICS_RESIDUAL, accel_sigma=sigma)
    fit = residual.fit_residual(cfg, residual_frame.orbit_propagator("two_body"), np.array([0.0]),
                                X0[None], P_SMALL[None])
    assert fit is not None
    x, P = fit.predict(t)
    e = x[:, :3] - truth[:, :3]
    nees = np.einsum("ki,ki->k", e, np.linalg.solve(P[:, :3, :3], e[:, :, None])[:, :, 0])
    assert np.linalg.norm(e, axis=1).max() > 5.0  # km: the push shows
    if covered:
        assert nees.max() < BOUND, nees.max()
    else:
        assert np.median(nees) > 100 * BOUND, np.median(nees)


def _stream(hours: float) -> tuple[np.ndarray, np.ndarray]:
    """Estimates of a J2 truth during passes of 5 min every 97 min (30 s apart): (t, x)."""
    starts = np.arange(60.0, hours * 3600.0, 97 * 60.0)
    t = np.concatenate([s + np.arange(0.0, 300.0, 30.0) for s in starts])
    return t, dynamics.propagate("j2", X0, np.concatenate([[0.0], t]))[1:]


LEARNED = replace(LIVE_RESIDUAL, min_anchors=3, min_span_s=3 * 3600.0, window_s=12 * 3600.0,
                  max_horizon_s=6 * 3600.0, heldout_fits=1)


@pytest.mark.parametrize("physics", [PHYSICS_RESIDUAL, None])
def test_the_physics_fit_forecasts_the_gaps_before_the_learned_residual_can(physics):
    t, x = _stream(10.0)
    gf = GapForecaster.for_model("j2", 60.0, LEARNED, physics)
    kinds = []  # per gap: None (no forecast), True (physics-only), False (learned)
    for i in range(len(t)):
        gf.on_estimate(float(t[i]), x[i], P_SMALL)
        if i + 1 < len(t) and t[i + 1] - t[i] > 600.0:  # a pass ends: ask in its gap
            got = gf.forecast(60.0 * (math.floor((t[i] + 600.0) / 60.0) + 1))
            kinds.append(None if got is None else gf.physics_fit)
    n_learned = sum(k is False for k in kinds)
    assert len(kinds) >= 5 and n_learned >= 2
    first = kinds.index(False)
    assert first >= 2 and all(k is False for k in kinds[first:])  # the learned, once it can
    # before: the physics-only fit from the first pass end on, or nothing without it
    assert kinds[:first] == ([True] * first if physics is not None else [None] * first)


def test_the_bank_counts_and_marks_the_physics_fits():
    t, x = _stream(10.0)
    out = {}
    for physics in (PHYSICS_RESIDUAL, None):
        bank = GapBank(GapBankConfig(motion_model="j2", period_s=60.0, hold_s=0.0,
                                     fit_budget=0.0, residual=LEARNED, physics=physics))
        got = []
        for now in np.arange(0.0, 10 * 3600.0, 60.0):
            for i in np.flatnonzero((t > now - 60.0) & (t <= now)):
                got += bank.on_estimate("a", float(t[i]), x[i], P_SMALL)
            got += bank.step(float(now))
        out[physics is not None] = (bank.counts, got)
    (c1, g1), (c0, g0) = out[True], out[False]
    assert c1["fitted_physics"] >= 2 and c0["fitted_physics"] == 0
    learned = c1["fitted"] - c1["fitted_physics"]
    assert learned == c0["fitted"] > 0  # the same learned fits with or without it
    assert sum(f.physics for f in g1) > 0 and not any(f.physics for f in g0)
    assert len([f for f in g1 if not f.physics]) == len(g0)  # the learned forecasts alike
    assert c1["refused"] == 0 and c0["refused"] == c1["fitted_physics"]


def test_the_prior_is_checked():
    with pytest.raises(ValueError, match="accel_sigma"):
        replace(PHYSICS_RESIDUAL, accel_sigma=-1.0)
    with pytest.raises(ValueError, match="Hill"):
        replace(PHYSICS_RESIDUAL, model="basis")


@pytest.mark.parametrize("components", [(True, True, True), (False, True, False),
                                        (True, False, True)])
def test_the_closed_form_without_harmonics_equals_the_matrix_exponential(components):
    """`hill_design` without harmonics (closed form) against Van Loan's exponential of its
    generator, taken here: within 1e-10 of each entry's largest value over +-1 day."""
    from scipy.linalg import expm

    n = 2 * math.pi / 5560.0
    t = np.array([-86400.0, -3000.0, 0.0, 17.0, 5000.0, 60000.0, 86400.0])
    got = residual_design.hill_design(t, n, 0.3, harmonics=0, components=components)
    M = residual_design.hill_generator(n, 0.3, 0, components, n * n)
    want = np.array([expm(M * tk)[:6] for tk in t])
    want[:, :, 6:] /= n * n
    scale = np.maximum(np.abs(want).max(axis=0), 1e-30)
    assert np.max(np.abs(got - want) / scale) < 1e-10

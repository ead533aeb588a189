"""core.conjunction: the 2D Pc against CARA's Alfano (2009) cases and independent integrals,
Pc far below the float range, the maximum Pc, the usage bounds and the Monte Carlo 3D Pc."""

from __future__ import annotations

import math

import numpy as np
import pytest
from cara_cases import ALFANO_2009, ALFANO_2009_PC2D, alfano_case
from scipy import integrate, special, stats

from ssa_fusion.core.conjunction import max_pc
from ssa_fusion.core.conjunction.encounter import (
    encounter_plane,
    inertial_to_rtn,
    relative_state_rtn,
    rtn_to_inertial,
)
from ssa_fusion.core.conjunction.pc2d import log10_pc_circle
from ssa_fusion.core.conjunction.probability import collision_probability, pc2d_batch
from ssa_fusion.core.conjunction.result import PcMethod, PcWarning

LINEAR_CASES = {3, 5}
"""Alfano (2009)'s cases described as linear relative motion (the others: nonlinear or
near-linear, GEO/MEO/HEO slow encounters, leader-follower)."""


def _alfano(case: int) -> tuple[float, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    hbr, x1, c1, x2, c2 = alfano_case(case)
    return hbr, x1, rtn_to_inertial(x1, c1)[0], x2, rtn_to_inertial(x2, c2)[0]


@pytest.mark.parametrize("case", sorted(ALFANO_2009_PC2D))
def test_alfano_2009_pc2d_within_a_tenth_of_a_percent(case: int) -> None:
    hbr, x1, p1, x2, p2 = _alfano(case)
    res = collision_probability(x1, p1, x2, p2, hbr)
    assert res.method is PcMethod.FOSTER_2D
    assert res.pc == pytest.approx(ALFANO_2009_PC2D[case], rel=1e-3)


def test_alfano_usage_bounds_flag_the_nonlinear_cases_only() -> None:
    flagged = {c for c in ALFANO_2009
               if not collision_probability(*_alfano(c)[1:], _alfano(c)[0]).short_encounter_ok}
    assert flagged == set(ALFANO_2009) - LINEAR_CASES


def _dblquad_pc(m: np.ndarray, c: np.ndarray, r: float) -> float:
    """Reference: scipy's dblquad of the 2D Gaussian over the circle (Cartesian)."""
    dist = stats.multivariate_normal(mean=m, cov=c)
    val, _ = integrate.dblquad(lambda y, x: dist.pdf([x, y]), -r, r,
                               lambda x: -math.sqrt(max(r * r - x * x, 0.0)),
                               lambda x: math.sqrt(max(r * r - x * x, 0.0)),
                               epsabs=0.0, epsrel=1e-10)
    return float(val)


GEOMETRIES = [  # miss (km), covariance (km²), HBR (km)
    (np.array([0.1, 0.05]), np.array([[0.04, 0.0], [0.0, 0.01]]), 0.02),
    (np.array([0.3, -0.2]), np.array([[1.0, 0.3], [0.3, 0.1]]), 0.015),  # rotated, elongated
    (np.array([0.002, 0.001]), np.array([[1e-4, 2e-5], [2e-5, 5e-5]]), 0.02),  # HBR >> sigma
    (np.array([0.0, 0.0]), np.array([[2e-4, 0.0], [0.0, 9e-3]]), 0.01),
]


@pytest.mark.parametrize("geometry", range(len(GEOMETRIES)))
def test_pc2d_matches_scipy_dblquad(geometry: int) -> None:
    m, c, r = GEOMETRIES[geometry]
    ours = 10 ** float(log10_pc_circle(m, c, r).log10_pc[0])
    assert ours == pytest.approx(_dblquad_pc(m, c, r), rel=1e-6)


def test_pc2d_matches_monte_carlo_of_the_same_gaussian() -> None:
    m, c, r = GEOMETRIES[1]
    rng = np.random.default_rng(7)
    n = 2_000_000
    u = rng.multivariate_normal(m, c, size=n)
    p = np.count_nonzero(np.einsum("ni,ni->n", u, u) < r * r) / n
    ours = 10 ** float(log10_pc_circle(m, c, r).log10_pc[0])
    assert abs(ours - p) < 4 * math.sqrt(p * (1 - p) / n)


def test_zero_miss_isotropic_is_exact() -> None:
    s, r = 0.05, 0.02
    ours = 10 ** float(log10_pc_circle([0.0, 0.0], np.eye(2) * s * s, r).log10_pc[0])
    assert ours == pytest.approx(-math.expm1(-r * r / (2 * s * s)), rel=1e-10)


def _log10_rice(d: float, s: float, r: float) -> float:
    """Reference of an isotropic Pc in logs: the Rice (polar, Bessel) form, scaled."""
    def log_f(x: float) -> float:
        return (math.log(x / s**2) - (x - d) ** 2 / (2 * s * s)
                + math.log(special.i0e(x * d / s**2)))
    top = log_f(r)
    val, _ = integrate.quad(lambda x: math.exp(log_f(x) - top) if x > 0 else 0.0, 0.0, r,
                            epsabs=0.0, epsrel=1e-12)
    return (top + math.log(val)) / math.log(10)


@pytest.mark.parametrize("d", [1.0, 3.0, 10.0, 30.0])
def test_tiny_pc_far_below_the_float_range_matches_the_rice_integral(d: float) -> None:
    s, r = 0.1, 0.01  # 1e-22 ... 1e-19600
    ours = float(log10_pc_circle([d, 0.0], np.eye(2) * s * s, r).log10_pc[0])
    assert ours == pytest.approx(_log10_rice(d, s, r), abs=1e-6 * abs(ours))
    if d == 30.0:
        assert ours < -19000


def test_tiny_pc_anisotropic_matches_the_small_circle_limit() -> None:
    m, c, r = np.array([4.0, -3.0]), np.array([[0.09, 0.02], [0.02, 0.01]]), 1e-6
    ref = math.log10(math.pi * r * r) + stats.multivariate_normal(mean=m, cov=c).logpdf(
        [0.0, 0.0]) / math.log(10)
    assert float(log10_pc_circle(m, c, r).log10_pc[0]) == pytest.approx(ref, abs=1e-6)
    res = collision_probability([7000.0, 0, 0, 0, 7.5, 0], np.diag([0.09, 0.0, 0.01]),
                                [7000.0, 0, 5.0, 0, 0, 7.5], np.zeros((3, 3)) + 1e-12 *
                                np.eye(3), 1e-5)
    assert res.pc == 0.0 and PcWarning.BELOW_FLOAT_RANGE in res.warnings
    assert res.log10_pc < -400 and math.isfinite(res.log10_pc)


def test_frisbee_maximum_bounds_every_unknown_covariance_along_any_direction() -> None:
    m, c, r = np.array([0.5, 0.1]), np.array([[0.01, 0.002], [0.002, 0.004]]), 0.02
    best = float(max_pc.log10_max_pc_frisbee(m, c, r).log10_pc[0])
    rng = np.random.default_rng(3)
    for _ in range(40):
        u = rng.normal(size=2)
        u /= np.linalg.norm(u)
        v = 10 ** rng.uniform(-4, 1)
        other = float(log10_pc_circle(m, c + v * np.outer(u, u), r).log10_pc[0])
        assert other <= best + 1e-9
    # the worst variance along the miss: the maximum over a 1D scan of it
    scan = [float(log10_pc_circle(m, c + v * np.outer(m, m) / (m @ m), r).log10_pc[0])
            for v in np.linspace(0.0, 1.0, 401)]
    assert best == pytest.approx(max(scan), abs=1e-4)


def test_no_covariance_bound_is_above_any_gaussian() -> None:
    d, r = 0.3, 0.01
    bound = max_pc.log10_max_pc_no_covariance(d, r)
    rng = np.random.default_rng(5)
    for _ in range(40):
        a = rng.normal(size=(2, 2)) * 10 ** rng.uniform(-2, 0)
        assert float(log10_pc_circle([d, 0.0], a @ a.T, r).log10_pc[0]) <= bound + 1e-12
    assert max_pc.log10_max_pc_no_covariance(0.005, r) == 0.0


def test_missing_covariances_give_upper_bounds() -> None:
    hbr, x1, p1, x2, p2 = _alfano(5)
    full = collision_probability(x1, p1, x2, p2, hbr)
    one = collision_probability(x1, p1, x2, None, hbr)
    none = collision_probability(x1, None, x2, None, hbr)
    assert one.method is PcMethod.FRISBEE_MAX and one.is_upper_bound
    assert none.method is PcMethod.ALFANO_MAX
    assert PcWarning.MISSING_COVARIANCE in one.warnings & none.warnings
    assert full.pc <= one.pc * (1 + 1e-9) and one.pc <= none.pc


def test_geometry_rtn_round_trip_and_relative_state() -> None:
    x1 = np.array([7000.0, 100.0, -50.0, 0.1, 7.4, 1.0])
    x2 = np.array([7000.5, 100.2, -50.1, -0.2, 1.0, 7.4])
    c = np.diag([1e-4, 4e-2, 1e-4, 1e-8, 1e-8, 1e-8]) + 1e-6
    back = inertial_to_rtn(x1, rtn_to_inertial(x1, c))[0]
    assert np.allclose(back, c, rtol=0, atol=1e-15)
    rel = relative_state_rtn(x1, x2)[0]
    assert np.linalg.norm(rel[:3]) == pytest.approx(np.linalg.norm(x2[:3] - x1[:3]))
    rhat = x1[:3] / np.linalg.norm(x1[:3])
    assert rel[0] == pytest.approx((x2[:3] - x1[:3]) @ rhat)
    enc = encounter_plane(x1, c, x2, c)
    r, v = x2[:3] - x1[:3], x2[3:] - x1[3:]
    perp = r - (r @ v) / (v @ v) * v
    assert enc.miss_km[0] == pytest.approx(np.linalg.norm(perp))
    assert enc.tca_offset_s[0] == pytest.approx(-(r @ v) / (v @ v))


def test_batch_equals_one_by_one_and_states_off_tca_give_the_same_pc() -> None:
    cases = sorted(ALFANO_2009_PC2D)
    data = [_alfano(c) for c in cases]
    _, res = pc2d_batch(np.stack([d[1] for d in data]), np.stack([d[2] for d in data]),
                        np.stack([d[3] for d in data]), np.stack([d[4] for d in data]),
                        np.array([d[0] for d in data]))
    for k, d in enumerate(data):
        one = collision_probability(d[1], d[2], d[3], d[4], d[0])
        assert res.log10_pc[k] == pytest.approx(one.log10_pc, abs=1e-12)
    hbr, x1, p1, x2, p2 = _alfano(5)  # 1 ms off TCA along straight lines: the same plane
    dt = 1e-3
    moved = [np.concatenate([x[:3] + dt * x[3:], x[3:]]) for x in (x1, x2)]
    a = collision_probability(x1, p1, x2, p2, hbr)
    b = collision_probability(moved[0], p1, moved[1], p2, hbr)
    assert b.pc == pytest.approx(a.pc, rel=1e-9)
    assert b.tca_offset_s == pytest.approx(a.tca_offset_s - dt, abs=1e-9)


def _fast_leo() -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    x1 = np.array([6878.0, 0.0, 0.0, 0.0, 7.6127, 0.0])
    x2 = np.array([6878.0, 0.0, 0.03, 0.0, 5.3830, 5.3830])
    c1 = np.diag([1e-4, 4e-3, 4e-4, 1e-10, 1e-10, 1e-10])
    c2 = np.diag([4e-4, 1e-2, 1e-3, 1e-9, 1e-9, 1e-9])
    return x1, rtn_to_inertial(x1, c1)[0], x2, rtn_to_inertial(x2, c2)[0]


def test_monte_carlo_3d_agrees_with_2d_on_a_fast_encounter() -> None:
    x1, p1, x2, p2 = _fast_leo()
    two = collision_probability(x1, p1, x2, p2, 0.02)
    mc = collision_probability(x1, p1, x2, p2, 0.02, PcMethod.MONTE_CARLO_3D,
                               samples=40_000, seed=11)
    assert two.short_encounter_ok and mc.method is PcMethod.MONTE_CARLO_3D
    assert mc.samples == 40_000 and mc.std_error > 0
    assert abs(mc.pc - two.pc) < 4 * mc.std_error
    assert 1e-3 < two.pc < 0.5  # a Pc the sample size resolves


def test_degenerate_inputs() -> None:
    x1, p1, _, p2 = _fast_leo()
    same = collision_probability(x1, p1, x1 + np.array([0, 0, 0.01, 0, 0, 0]), p2, 0.02)
    assert math.isnan(same.pc) and PcWarning.ZERO_RELATIVE_VELOCITY in same.warnings
    npd = p2.copy()
    npd[:3, :3] -= 2 * np.eye(3) * np.max(np.abs(npd[:3, :3]))
    res = collision_probability(*_fast_leo()[:3], npd, 0.02)
    assert PcWarning.NPD_SECONDARY in res.warnings and 0 <= res.pc <= 1
    with pytest.raises(ValueError, match="hard-body radius"):
        collision_probability(*_fast_leo(), 0.0)


def test_a_refinement_floor_leaves_only_tiny_pc_to_the_gauss_legendre_rule() -> None:
    # random encounters, many of them with the two rules disagreeing (elongated, far)
    rng = np.random.default_rng(0)
    n = 150
    s1 = 10 ** rng.uniform(-3, 1, n)
    s2 = s1 * 10 ** rng.uniform(-3, 0, n)
    th = rng.uniform(0, np.pi, n)
    rot = np.stack([np.stack([np.cos(th), -np.sin(th)], 1), np.stack([np.sin(th), np.cos(th)], 1)],
                   1)
    cov = rot @ (np.eye(2)[None] * np.stack([s1**2, s2**2], 1)[:, :, None]) @ np.swapaxes(rot, 1, 2)
    miss = rng.normal(size=(n, 2)) * 10 ** rng.uniform(-2, 0.7, (n, 1))
    full = log10_pc_circle(miss, cov, 0.02)
    floored = log10_pc_circle(miss, cov, 0.02, refine_below_log10=-15.0)
    left = floored.unrefined
    assert full.adaptive.sum() >= 40 and left.sum() >= 20 and not full.unrefined.any()
    # the rest is refined as before, to the bit; what is left is tiny, by either rule
    np.testing.assert_array_equal(full.log10_pc[~left], floored.log10_pc[~left])
    assert (full.log10_pc[left] < -15.0).all() and (floored.log10_pc[left] < -15.0).all()
    assert (floored.adaptive | left == full.adaptive).all()

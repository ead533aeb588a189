"""Tests for ssa_fusion.core.motion.kepler (analytic two-body propagation + STM).

References: numerical integration of the two-body ODE (scipy DOP853, tight tolerances),
central finite differences of the propagator, and the structural properties of any
Hamiltonian flow (symplectic STM, det = 1, group/composition property, conserved
energy and angular momentum).
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.integrate import solve_ivp
from scipy.spatial.transform import Rotation

from ssa_fusion.core.base.constants import MU_EARTH
from ssa_fusion.core.motion.kepler import propagate, stumpff


def _state(a: float, e: float, i: float, raan: float, argp: float, nu: float) -> np.ndarray:
    """Classical elements (km, rad) -> inertial state (independent textbook conversion)."""
    p = a * (1.0 - e * e)
    r = p / (1.0 + e * math.cos(nu))
    r_pf = np.array([r * math.cos(nu), r * math.sin(nu), 0.0])
    v_pf = math.sqrt(MU_EARTH / p) * np.array([-math.sin(nu), e + math.cos(nu), 0.0])
    q = Rotation.from_euler("ZXZ", [raan, i, argp]).as_matrix()  # Rz(raan) Rx(i) Rz(argp)
    return np.concatenate([q @ r_pf, q @ v_pf])


D = math.radians
ISS = _state(6796.9, 0.0007, D(51.639), D(113.73), D(51.197), D(358.89))
MOLNIYA = _state(26555.94, 0.7294, D(63.324), D(295.46), D(282.69), D(357.32))
MOLNIYA_APO = _state(26555.94, 0.7294, D(63.324), D(295.46), D(282.69), D(180.0))
CIRCULAR = _state(7000.0, 0.0, D(28.5), D(10.0), D(0.0), D(30.0))
HYPERBOLA = np.array([7000.0, 100.0, -50.0, 0.3, 12.0, 1.0])


def _period(x: np.ndarray) -> float:
    r = np.linalg.norm(x[:3])
    a = 1.0 / (2.0 / r - x[3:] @ x[3:] / MU_EARTH)
    return 2.0 * math.pi * math.sqrt(a**3 / MU_EARTH)


def _integrate(x0: np.ndarray, dt: float) -> np.ndarray:
    def rhs(_t: float, s: np.ndarray) -> np.ndarray:
        r = s[:3]
        return np.concatenate([s[3:], -MU_EARTH * r / np.linalg.norm(r) ** 3])

    sol = solve_ivp(rhs, (0.0, dt), x0, method="DOP853", rtol=1e-13, atol=1e-12)
    return sol.y[:, -1]


def _fd_stm(x0: np.ndarray, dt: float) -> np.ndarray:
    out = np.empty((6, 6))
    for j in range(6):
        h = 1e-3 if j < 3 else 1e-6
        e = np.zeros(6)
        e[j] = h
        out[:, j] = (propagate(x0 + e, dt)[0] - propagate(x0 - e, dt)[0]) / (2.0 * h)
    return out


ORBITS = {"iss": ISS, "molniya": MOLNIYA, "molniya_apo": MOLNIYA_APO, "circular": CIRCULAR}
FRACTIONS = [1e-4, -1e-4, 0.013, -0.013, 0.37, -0.61, 1.0, 2.71, -3.3]


@pytest.mark.parametrize("name", sorted(ORBITS))
@pytest.mark.parametrize("frac", FRACTIONS)
def test_matches_numerical_integration(name: str, frac: float) -> None:
    x0 = ORBITS[name]
    dt = frac * _period(x0)
    x1, _ = propagate(x0, dt)
    ref = _integrate(x0, dt)
    np.testing.assert_allclose(x1[:3], ref[:3], rtol=0, atol=1e-9 * np.linalg.norm(ref[:3]))
    np.testing.assert_allclose(x1[3:], ref[3:], rtol=0, atol=1e-9 * np.linalg.norm(ref[3:]))


@pytest.mark.parametrize("dt", [1.0, -30.0, 1500.0, -4000.0, 20000.0])
def test_hyperbola_matches_numerical_integration(dt: float) -> None:
    x1, _ = propagate(HYPERBOLA, dt)
    ref = _integrate(HYPERBOLA, dt)
    np.testing.assert_allclose(x1, ref, rtol=1e-10, atol=1e-9)


@pytest.mark.parametrize("name", sorted(ORBITS))
@pytest.mark.parametrize("frac", [1e-3, -1e-3, 0.2, -0.45, 1.3, -2.2])
def test_stm_matches_finite_differences(name: str, frac: float) -> None:
    x0 = ORBITS[name]
    dt = frac * _period(x0)
    _, stm = propagate(x0, dt)
    fd = _fd_stm(x0, dt)
    # compare per block, relative to the block's scale (blocks differ by ~1/s)
    for rows in (slice(0, 3), slice(3, 6)):
        for cols in (slice(0, 3), slice(3, 6)):
            scale = np.abs(fd[rows, cols]).max()
            np.testing.assert_allclose(stm[rows, cols], fd[rows, cols], rtol=0, atol=1e-6 * scale)


def test_stm_hyperbola_matches_finite_differences() -> None:
    _, stm = propagate(HYPERBOLA, 900.0)
    fd = _fd_stm(HYPERBOLA, 900.0)
    np.testing.assert_allclose(stm, fd, rtol=0, atol=1e-6 * np.abs(fd).max())


def test_zero_step_is_identity() -> None:
    x1, stm = propagate(ISS, 0.0)
    np.testing.assert_array_equal(x1, ISS)
    np.testing.assert_allclose(stm, np.eye(6), atol=1e-15)


J6 = np.block([[np.zeros((3, 3)), np.eye(3)], [-np.eye(3), np.zeros((3, 3))]])


@pytest.mark.parametrize("name", sorted(ORBITS))
@pytest.mark.parametrize("frac", [1e-3, -0.3, 0.77, 4.2])
def test_stm_symplectic_and_unimodular(name: str, frac: float) -> None:
    _, stm = propagate(ORBITS[name], frac * _period(ORBITS[name]))
    scale = np.linalg.norm(stm) ** 2
    np.testing.assert_allclose(stm.T @ J6 @ stm, J6, rtol=0, atol=1e-13 * scale)
    assert np.linalg.det(stm) == pytest.approx(1.0, abs=1e-12 * scale)


@pytest.mark.parametrize("name", sorted(ORBITS))
def test_stm_composition(name: str) -> None:
    x0 = ORBITS[name]
    p = _period(x0)
    for t1, t2 in ((0.1 * p, 0.35 * p), (-0.2 * p, 0.5 * p), (1.4 * p, -0.3 * p)):
        x1, phi10 = propagate(x0, t1)
        x2, phi21 = propagate(x1, t2 - t1)
        x2_direct, phi20 = propagate(x0, t2)
        np.testing.assert_allclose(x2, x2_direct, rtol=0, atol=1e-9 * np.abs(x2).max())
        np.testing.assert_allclose(
            phi21 @ phi10, phi20, rtol=0, atol=1e-10 * np.abs(phi20).max()
        )


def _invariants(x: np.ndarray) -> tuple[float, np.ndarray]:
    energy = 0.5 * x[3:] @ x[3:] - MU_EARTH / np.linalg.norm(x[:3])
    return energy, np.cross(x[:3], x[3:])


@settings(max_examples=200, deadline=None)
@given(
    a=st.floats(6600.0, 60000.0),
    e=st.floats(0.0, 0.95),
    i=st.floats(0.0, math.pi),
    raan=st.floats(0.0, 2 * math.pi),
    argp=st.floats(0.0, 2 * math.pi),
    nu=st.floats(0.0, 2 * math.pi),
    frac=st.floats(-5.0, 5.0),
)
def test_invariants_and_time_reversal(
    a: float, e: float, i: float, raan: float, argp: float, nu: float, frac: float
) -> None:
    x0 = _state(a, e, i, raan, argp, nu)
    dt = frac * _period(x0)
    x1, stm = propagate(x0, dt)
    e0, h0 = _invariants(x0)
    e1, h1 = _invariants(x1)
    assert e1 == pytest.approx(e0, rel=1e-10)
    np.testing.assert_allclose(h1, h0, rtol=0, atol=1e-10 * np.linalg.norm(h0))
    back, stm_back = propagate(x1, -dt)
    np.testing.assert_allclose(back, x0, rtol=0, atol=1e-9 * np.abs(x0).max())
    np.testing.assert_allclose(
        stm_back @ stm, np.eye(6), rtol=0, atol=1e-9 * np.linalg.norm(stm) ** 2
    )


def test_stumpff_values() -> None:
    # closed forms evaluated away from the branch cut, series near zero (continuity)
    for z in (2.5, 0.5000001, 0.4999999, 0.1, 1e-8, 0.0, -1e-8, -0.4999999, -0.5000001, -3.0):
        c2, c3, c4, c5 = stumpff(z)
        ref = [sum((-z) ** j / math.factorial(k + 2 * j) for j in range(30)) for k in (2, 3, 4, 5)]
        np.testing.assert_allclose([c2, c3, c4, c5], ref, rtol=1e-13)
    s = math.sqrt(2.5)
    assert stumpff(2.5)[0] == pytest.approx((1 - math.cos(s)) / 2.5, rel=1e-15)
    assert stumpff(2.5)[1] == pytest.approx((s - math.sin(s)) / s**3, rel=1e-15)


def test_accepts_lists_and_custom_mu() -> None:
    mu = 1.0
    x0 = [1.0, 0.0, 0.0, 0.0, 1.0, 0.0]  # unit circular orbit, period 2 pi
    x1, _ = propagate(x0, math.pi / 2, mu=mu)
    np.testing.assert_allclose(x1, [0.0, 1.0, 0.0, -1.0, 0.0, 0.0], atol=1e-14)


@pytest.mark.parametrize(
    "x0, dt",
    [
        ([np.nan, 0.0, 0.0, 0.0, 7.0, 0.0], 10.0),
        ([7000.0, 0.0, 0.0, 0.0, np.inf, 0.0], 10.0),
        ([0.0, 0.0, 0.0, 0.0, 7.0, 0.0], 10.0),
        ([7000.0, 0.0, 0.0, 0.0, 7.0, 0.0], np.nan),
    ],
)
def test_bad_input_raises(x0: list[float], dt: float) -> None:
    with pytest.raises(ValueError, match="finite state"):
        propagate(np.array(x0), dt)


def test_a_newton_step_below_an_ulp_at_the_bracket_end_is_converged() -> None:
    """Kepler's equation converged with a last Newton step smaller than an ulp of chi, at
    the end of the safeguarding bracket: chi is that Newton iterate, not a bisection of the
    bracket (a multi-revolution arc of an eccentric orbit, a day backwards)."""
    x0 = _state(20464.806022994962, 0.844428199578132, 0.5296541048224832, 4.713413951671188,
                1.1067339419218458, 2.909397918019619)
    x1, _ = propagate(x0, -86400.0)
    np.testing.assert_allclose(x1, _integrate(x0, -86400.0), rtol=0, atol=1e-6)

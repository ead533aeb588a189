"""The solid Earth tides of the high-fidelity force model against the IERS Conventions' own
recipe: the degree-2 Stokes coefficients the Sun and the Moon raise (IERS 2010 eq. 6.6,
one Love number for every order), summed by the geopotential's own harmonics in the ITRF
and differentiated numerically, rotated to the GCRF. The kernel evaluates a closed form
in the GCRF instead (`force_kernel`): two independent routes to one acceleration."""

from __future__ import annotations

import math

import numpy as np

from ssa_fusion.core.base.constants import MU_EARTH
from ssa_fusion.core.earth import frames
from ssa_fusion.core.earth.ephemeris import sun_moon_positions, sun_moon_span
from ssa_fusion.core.earth.timescales import parse_utc
from ssa_fusion.core.motion import high_fidelity as hf
from ssa_fusion.core.motion.force_spec import LOVE_K2, ForceSpec
from ssa_fusion.core.motion.geopotential import GravityField, potential

T = parse_utc("2016-02-13T06:00:00")
LAGEOS = np.array([-6020.0, 8950.0, 5400.0, -3.9, -2.6, 0.2])  # ~12,270 km from the centre


def _tide_field(t: float, gm_earth: float, radius: float) -> GravityField:
    """The degree-2 coefficients of the tide at ``t`` (IERS 2010 eq. 6.6), alone."""
    span = sun_moon_span(t, 0.0, 0.0)
    gms = (span.gm_sun, span.gm_moon)
    c, s = np.zeros((3, 3)), np.zeros((3, 3))
    m_itrs = frames.gcrs_to_itrs_matrix(t)
    for gm, body in zip(gms, sun_moon_positions([t]), strict=True):
        b = m_itrs @ body[0]
        rb = float(np.linalg.norm(b))
        sphi, cphi = b[2] / rb, math.hypot(b[0], b[1]) / rb
        lam = math.atan2(b[1], b[0])
        pbar = (math.sqrt(5.0) * (3.0 * sphi**2 - 1.0) / 2.0,
                math.sqrt(15.0) * sphi * cphi, math.sqrt(15.0) / 2.0 * cphi**2)
        for m in range(3):
            k = LOVE_K2 / 5.0 * gm / gm_earth * (radius / rb) ** 3 * pbar[m]
            c[2, m] += k * math.cos(m * lam)
            s[2, m] += k * math.sin(m * lam)
    return GravityField("tide", gm_earth, radius, c, s)


def test_the_tide_acceleration_is_the_iers_coefficients_gradient() -> None:
    with_tides = ForceSpec(degree=0, sun=False, moon=False, solid_tides=True)
    without = ForceSpec(degree=0, sun=False, moon=False)
    a_kernel = (hf.derivatives(with_tides, LAGEOS, T)[0][3:]
                - hf.derivatives(without, LAGEOS, T)[0][3:])
    field = _tide_field(T, MU_EARTH, with_tides.gravity.radius)
    m_itrs = frames.gcrs_to_itrs_matrix(T)
    p = m_itrs @ LAGEOS[:3]
    h = 1e-3
    grad = np.array([(potential(field, p + h * e, 2) - potential(field, p - h * e, 2)) / (2 * h)
                     for e in np.eye(3)])
    a_iers = m_itrs.T @ grad
    print(f"\ntide acceleration {np.linalg.norm(a_kernel) * 1e3:.3e} m/s^2, "
          f"difference {np.linalg.norm(a_kernel - a_iers) * 1e3:.2e} m/s^2")
    assert 1e-8 < np.linalg.norm(a_kernel) * 1e3 < 1e-7  # LAGEOS: tens of nm/s^2
    assert np.allclose(a_kernel, a_iers, rtol=1e-6, atol=1e-18)


def test_no_tides_unless_asked() -> None:
    spec = ForceSpec(degree=0, sun=False, moon=False)
    a = hf.derivatives(spec, LAGEOS, T)[0][3:]
    r = np.linalg.norm(LAGEOS[:3])
    assert np.allclose(a, -MU_EARTH * LAGEOS[:3] / r**3, rtol=1e-14)

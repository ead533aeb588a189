"""Tests for ssa_fusion.core.measure.measurement."""

import numpy as np
import pytest

from ssa_fusion.core.base.types import Kind
from ssa_fusion.core.earth.frames import COLUMBUS, radec_gcrs, razel_gcrs, wrap_angle
from ssa_fusion.core.earth.timescales import UNIX_EPOCH_JD
from ssa_fusion.core.measure.measurement import PositionModel, RadecModel, RazelModel


def test_position_model_orbit_and_pendulum():
    m = PositionModel()
    assert m.kind == Kind.POSITION == 0 and m.angle_mask == (False, False, False)
    x = np.arange(6.0) + 1
    z, H = m.h_and_H(x, 0.0)
    np.testing.assert_array_equal(z, x[:3])
    np.testing.assert_array_equal(H, np.eye(3, 6))
    z[0] = 99.0  # z is a copy, the state is untouched
    assert x[0] == 1.0
    with pytest.raises(ValueError):
        H[0, 0] = 5.0  # the cached H is read-only

    p = PositionModel(observed=(0,))
    assert p.angle_mask == (False,)
    z, H = p.h_and_H(np.array([0.3, -0.1]), 1.0)
    np.testing.assert_array_equal(z, [0.3])
    np.testing.assert_array_equal(H, [[1.0, 0.0]])

    q = PositionModel(observed=(2, 0))
    z, H = q.h_and_H(x, 0.0)
    np.testing.assert_array_equal(z, [3.0, 1.0])
    np.testing.assert_array_equal(H @ x, z)


def test_razel_model_matches_frames_and_finite_differences():
    jd0 = 2460310.5
    m = RazelModel(COLUMBUS, jd0)
    assert m.kind == Kind.RANGE_AZ_EL == 1 and m.angle_mask == (False, True, True)
    x = np.array([1200.0, -5200.0, 4300.0, 5.1, 1.2, -4.4])
    t = 3725.0
    z, H = m.h_and_H(x, t)
    t_unix = (jd0 - UNIX_EPOCH_JD) * 86400.0 + t
    # the model's fast path (hourly Q, W interpolated) against the vectorised frames: 1e-10 rad
    np.testing.assert_allclose(z, razel_gcrs(x, t_unix, COLUMBUS), atol=1e-9)
    np.testing.assert_array_equal(m.h(x, t), z)
    np.testing.assert_array_equal(m.H(x, t), H)
    assert 0.0 <= z[1] < 2 * np.pi
    num = np.zeros((3, 6))
    for k in range(6):
        dx = np.zeros(6)
        dx[k] = 1e-3
        d = m.h(x + dx, t) - m.h(x - dx, t)
        d[1:] = wrap_angle(d[1:])
        num[:, k] = d / 2e-3
    np.testing.assert_allclose(H, num, rtol=1e-6, atol=1e-12)


def test_radec_model_matches_frames_and_finite_differences():
    jd0 = 2460310.5
    m = RadecModel(COLUMBUS, jd0)
    x = np.array([1200.0, -5200.0, 4300.0, 5.1, 1.2, -4.4])
    t = 3725.0
    z, H = m.h_and_H(x, t)
    t_unix = (jd0 - UNIX_EPOCH_JD) * 86400.0 + t
    np.testing.assert_allclose(z, radec_gcrs(x, t_unix, COLUMBUS), atol=1e-9)
    num = np.zeros((2, 6))
    for k in range(6):
        dx = np.zeros(6)
        dx[k] = 1e-3
        d = wrap_angle(m.h(x + dx, t) - m.h(x - dx, t))
        num[:, k] = d / 2e-3
    np.testing.assert_allclose(H, num, rtol=1e-6, atol=1e-12)


def test_refraction_inverts_bennetts_formula_and_its_jacobian_is_exact():
    """Saemundsson's R(true elevation) against Bennett's independent R(apparent elevation)
    (Meeus, Astronomical Algorithms, eq. 16.3): el + R(el) seen through Bennett gives R back
    within 0.1' from the horizon to the zenith; the radar model adds it to the elevation with
    the matching Jacobian."""
    from ssa_fusion.core.earth.refraction import refraction

    el = np.radians(np.linspace(0.0, 90.0, 91))
    r = refraction(el)
    h0 = np.degrees(el + r)  # the apparent elevation, deg
    bennett = np.radians(1.0 / np.tan(np.radians(h0 + 7.31 / (h0 + 4.4))) / 60.0)
    assert np.abs(np.degrees(r - bennett) * 60.0).max() < 0.1
    assert np.degrees(refraction(np.radians(10.0))) * 60.0 == pytest.approx(5.4, abs=0.05)
    jd0 = 2460310.5
    plain, bent = RazelModel(COLUMBUS, jd0), RazelModel(COLUMBUS, jd0, refraction=True)
    x = np.array([1200.0, -5200.0, 4300.0, 5.1, 1.2, -4.4])
    z0, z1 = plain.h(x, 0.0), bent.h(x, 0.0)
    assert z1[2] - z0[2] == pytest.approx(float(refraction(z0[2])), abs=1e-15)
    np.testing.assert_array_equal(z1[:2], z0[:2])
    _, H = bent.h_and_H(x, 0.0)
    num = np.zeros((3, 6))
    for k in range(6):
        dx = np.zeros(6)
        dx[k] = 1e-3
        d = bent.h(x + dx, 0.0) - bent.h(x - dx, 0.0)
        d[1:] = wrap_angle(d[1:])
        num[:, k] = d / 2e-3
    np.testing.assert_allclose(H, num, rtol=1e-6, atol=1e-12)

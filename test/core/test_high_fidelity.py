"""The high-fidelity force model's propagation (core.motion.high_fidelity) and SRP shadow.

* the Jacobian A of the full model (20 x 20, Sun, Moon, SRP, drag) and the parameter
  partials B against central finite differences of the right-hand side;
* the STM and the sensitivities of a propagation against finite differences of propagations;
* a degree-2 zonal field without EOP against `force_model.trajectory`'s two-body + J2 about
  the same pole (another kernel): millimetres over two hours;
* the conical shadow function against analytic cases;
* `batch_ls.fit` with the full model (a `ForceSpec`) on positions it simulated.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from ssa_fusion.core.base.constants import R_EARTH
from ssa_fusion.core.earth import eop as eop_
from ssa_fusion.core.earth import frames
from ssa_fusion.core.earth.ephemeris import sun_moon_positions
from ssa_fusion.core.earth.timescales import parse_utc
from ssa_fusion.core.motion import force_model
from ssa_fusion.core.motion import high_fidelity as hf
from ssa_fusion.core.motion.force_spec import (
    SUN_RADIUS_KM,
    DragSpec,
    ForceSpec,
    SrpSpec,
    parameter_index,
)
from ssa_fusion.core.motion.srp import shadow_fraction
from ssa_fusion.formats.icgem import egm96

T0 = parse_utc("2016-02-13T00:00:00")
LEO = np.array([7078.0, 0.0, 0.0, 0.0, -1.0437, 7.4271])  # 700 km, i ~ 98 deg
SPEC = ForceSpec(egm96(), 20, sun=True, moon=True, srp=SrpSpec(0.02, 1.3),
                 drag=DragSpec(bc=50.0))
WHICH = parameter_index(("drag_scale", "accel_r", "accel_t", "accel_n", "srp_scale"))


def _sunlit(x: np.ndarray, t: float) -> bool:
    sun, _ = sun_moon_positions([t])
    return shadow_fraction(*x[:3], *sun[0], SUN_RADIUS_KM, R_EARTH) == 1.0


def test_jacobian_and_parameter_partials_equal_finite_differences() -> None:
    t = T0 + 100.0
    assert _sunlit(LEO, t)  # the shadow's own derivative is left out (module srp)
    ctx = hf.setup(SPEC, T0)
    prm = np.array([1.3, 0.0, 0.0, 0.0, 0.9])  # RTN axes' state dependence left out of A
    _, A, B = hf.derivatives(ctx, LEO, t, prm, WHICH)
    for j in range(6):
        h = 1e-2 if j < 3 else 1e-5
        e = np.zeros(6)
        e[j] = h
        fd = (hf.derivatives(ctx, LEO + e, t, prm)[0] - hf.derivatives(ctx, LEO - e, t, prm)[0])
        fd /= 2 * h
        assert np.allclose(A[:, j], fd, rtol=1e-6, atol=1e-13), j
    assert np.array_equal(A[:3, 3:], np.eye(3)) and not A[:3, :3].any()
    prm = np.array([1.3, 1e-9, -2e-9, 3e-9, 0.9])
    _, _, B = hf.derivatives(ctx, LEO, t, prm, WHICH)
    for k in range(5):
        h = 0.1 if k in (0, 4) else 1e-6  # the acceleration is linear in each
        p1, p0 = prm.copy(), prm.copy()
        p1[k] += h
        p0[k] -= h
        fd = (hf.derivatives(ctx, LEO, t, p1)[0] - hf.derivatives(ctx, LEO, t, p0)[0]) / (2 * h)
        assert np.allclose(B[:, k], fd, rtol=1e-6, atol=1e-17), k  # 1e-17: round-off
    assert np.abs(B[3:, 4]).max() > 1e-11  # SRP acts: ~2e-10 km/s^2 at A/m 0.02
    assert np.abs(B[3:, 0]).max() > 1e-12  # drag acts


def test_stm_and_sensitivities_equal_finite_differences() -> None:
    spec = ForceSpec(egm96(), 8, sun=True, moon=True, srp=SrpSpec(0.02, 1.3),
                     drag=DragSpec(bc=50.0))
    ctx = hf.setup(spec, T0, -3600.0, 7200.0)
    t = T0 + np.array([-1800.0, 3000.0, 7200.0])
    which = parameter_index(("drag_scale", "srp_scale"))
    tr = hf.propagate(ctx, LEO, T0, t, which=which)
    assert tr.ok.all()
    for j in range(6):
        h = 1e-3 if j < 3 else 1e-6
        e = np.zeros(6)
        e[j] = h
        xp = hf.propagate(ctx, LEO + e, T0, t, stm=False).x
        xm = hf.propagate(ctx, LEO - e, T0, t, stm=False).x
        fd = (xp - xm) / (2 * h)
        assert np.abs(tr.phi[:, :, j] - fd).max() < 1e-6 * np.abs(fd).max(), j
    for k, idx in enumerate(which):
        p1, p0 = np.array([1.0, 0, 0, 0, 1.0]), np.array([1.0, 0, 0, 0, 1.0])
        p1[idx] += 0.01
        p0[idx] -= 0.01
        fd = (hf.propagate(ctx, LEO, T0, t, p1, stm=False).x
              - hf.propagate(ctx, LEO, T0, t, p0, stm=False).x) / 0.02
        assert np.abs(tr.s[:, :, k] - fd).max() < 1e-4 * np.abs(fd).max(), idx


def test_zonal_field_equals_the_j2_kernel() -> None:
    g = egm96()
    spec = ForceSpec(g, 2, 0, sun=False, moon=False)
    t = T0 + np.arange(600.0, 7201.0, 600.0)
    ours = hf.propagate(spec, LEO, T0, t, eop=eop_.NO_EOP)
    pole = frames.pole_frame(T0, eop_.NO_EOP)[2]
    j2 = force_model.ForceModel(mu=g.gm, j2=-math.sqrt(5.0) * g.c[2, 0], re=g.radius,
                                j3=0.0, j4=0.0)
    ref = force_model.trajectory(j2, LEO, T0, t, pole=pole)
    assert np.linalg.norm(ours.x[:, :3] - ref.x[:, :3], axis=1).max() < 2e-6  # km
    assert np.abs(ours.phi - ref.phi).max() < 1e-6 * np.abs(ref.phi).max()
    # with the whole EOP the ITRF pole is off the CIP by polar motion: metres, not km
    full = hf.propagate(spec, LEO, T0, t, stm=False)
    d = np.linalg.norm(full.x[:, :3] - ref.x[:, :3], axis=1).max()
    assert 1e-6 < d < 1e-2


def test_context_reuse_and_spans() -> None:
    ctx = hf.setup(SPEC, T0, 0.0, 3600.0)
    a = hf.propagate(ctx, LEO, T0 + 60.0, [T0 + 1800.0], stm=False)
    b = hf.propagate(SPEC, LEO, T0 + 60.0, [T0 + 1800.0], stm=False)
    assert np.abs(a.x - b.x).max() < 1e-9
    with pytest.raises(ValueError, match="does not cover"):
        hf.propagate(ctx, LEO, T0, [T0 + 86400.0])
    c = hf.propagate(ctx, LEO, T0 + 60.0, [T0 + 1800.0, math.nan])
    assert c.ok.tolist() == [True, False] and np.isnan(c.x[1]).all()
    assert np.array_equal(c.x[0], a.x[0])
    bad = hf.propagate(ctx, np.full(6, math.nan), T0, [T0 + 600.0])
    assert not bad.ok.any()


def test_shadow_fraction_analytic_cases() -> None:
    sun = np.array([1.496e8, 0.0, 0.0])
    r = 7000.0
    assert shadow_fraction(r, 0.0, 0.0, *sun, SUN_RADIUS_KM, R_EARTH) == 1.0  # sunward
    assert shadow_fraction(-r, 0.0, 0.0, *sun, SUN_RADIUS_KM, R_EARTH) == 0.0  # behind
    assert shadow_fraction(0.0, r, 0.0, *sun, SUN_RADIUS_KM, R_EARTH) == 1.0  # terminator
    # the penumbra: the visible fraction of the Sun's disc (radius a) past the Earth's
    # (radius b) at separation c, counted on a grid over the Sun's disc (discs in the plane,
    # as the model takes them)
    a = math.asin(SUN_RADIUS_KM / 1.496e8)
    b = math.asin(R_EARTH / r)
    g = np.linspace(-a, a, 1601)
    gx, gy = np.meshgrid(g, g)
    disc = gx * gx + gy * gy <= a * a
    for frac in (-0.9, -0.5, 0.0, 0.4, 0.95):
        c = b + frac * a
        sun_dir_sep = c  # the angle between the directions to the Sun and to the Earth
        x, y = -r * math.cos(sun_dir_sep), r * math.sin(sun_dir_sep)
        # the Sun a million times farther and larger: the same a, no parallax of the Sun
        nu = shadow_fraction(x, y, 0.0, 1e6 * sun[0], 0.0, 0.0, 1e6 * SUN_RADIUS_KM, R_EARTH)
        seen = disc & ((gx - c) ** 2 + gy ** 2 > b * b)
        assert nu == pytest.approx(seen.sum() / disc.sum(), abs=2e-3), frac
        assert 0.0 < nu < 1.0
    # an occulting body smaller than the Sun's disc, centred: annular, 1 - b^2 / a^2
    small = 0.5 * SUN_RADIUS_KM / 1.496e8 * r
    nu = shadow_fraction(-r, 0.0, 0.0, *sun, SUN_RADIUS_KM, small)
    bb, aa = math.asin(small / r), math.asin(SUN_RADIUS_KM / (1.496e8 + r))
    assert nu == pytest.approx(1.0 - bb * bb / (aa * aa), rel=1e-9)


def test_batch_fit_with_the_full_model_recovers_the_orbit() -> None:
    from ssa_fusion.core.base.types import Kind, Measurement
    from ssa_fusion.core.measure.measurement import PositionModel
    from ssa_fusion.core.od.batch_ls import BatchOptions, fit

    spec = ForceSpec(egm96(), 12, sun=True, moon=True, srp=SrpSpec(0.02, 1.3),
                     drag=DragSpec(bc=50.0, h0=700.0))  # the density of 400 km at 700 km
    t = T0 + np.arange(0.0, 3 * 3600.0 + 1.0, 120.0)
    truth = hf.propagate(spec, LEO, T0, t, params=[1.4, 0.0, 0.0, 0.0, 1.0], stm=False).x
    rng = np.random.default_rng(3)
    R = np.eye(3) * 0.001 ** 2  # 1 m
    meas = [Measurement(float(ti), xi[:3] + rng.normal(0.0, 0.001, 3), R, Kind.POSITION)
            for ti, xi in zip(t, truth, strict=True)]
    guess = truth[-1] + np.array([1.0, -1.0, 0.5, 1e-3, -1e-3, 5e-4])
    out = fit(meas, PositionModel(), guess, float(t[-1]),
              BatchOptions(force=spec, solve_for=("drag_scale", "srp_scale")))
    assert out.converged, out.reason
    assert np.linalg.norm(out.x[:3] - truth[-1, :3]) < 0.002  # km, from 1.2 km off
    sd = np.sqrt(np.diag(out.P))[6:]  # drag_scale, srp_scale
    assert abs(out.params["drag_scale"] - 1.4) < 3 * sd[0] and sd[0] < 0.01
    assert abs(out.params["srp_scale"] - 1.0) < 3 * sd[1] and sd[1] < 0.5  # 3 h: weakly seen
    assert 0.7 < out.rms < 1.3
    with pytest.raises(ValueError, match="srp_scale needs"):
        BatchOptions(solve_for=("srp_scale",))
    with pytest.raises(ValueError, match="param_sigma has 4 values"):
        BatchOptions(force=spec, solve_for=("srp_scale",), param_sigma=(1.0, 1e-8, 1e-8, 1e-8))

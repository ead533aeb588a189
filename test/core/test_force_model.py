"""Tests for ssa_fusion.core.motion.force_model: the batch fit's force model and its sensitivities.

References: `propagation.integrate_stm` (the compiled two-body + J2 integrator with its STM,
and its numpy path for two-body + drag), `dynamics`' right-hand sides, the gradient of the
J3 and J4 potential (numpy's Legendre series), and central finite differences of the
integrated states for the STM (J3 and J4 on) and the parameter sensitivities.
"""

from __future__ import annotations

import numpy as np
import pytest
from numpy.polynomial import legendre

from ssa_fusion.core.base.constants import J3, J4, MU_EARTH, R_EARTH
from ssa_fusion.core.earth import frames
from ssa_fusion.core.motion import dynamics
from ssa_fusion.core.motion import force_model as fm
from ssa_fusion.core.motion.propagation import integrate_stm
from ssa_fusion.sim.scenarios import ISS_ELEMENTS, ORBIT_EPOCH_UNIX

X0 = dynamics.elements_to_state(**ISS_ELEMENTS)
T0 = ORBIT_EPOCH_UNIX
POLE_FRAME = frames.pole_frame(T0)
POLE = POLE_FRAME[2]
EPOCHS = T0 + np.array([10.0, 20.0, 95.0, 3000.0, 7000.0, -50.0, -4000.0, 20.0])


def _chained(model: str, **params: float) -> tuple[np.ndarray, np.ndarray]:
    """integrate_stm chained over EPOCHS, outwards on each side of T0, as the kernel steps."""
    out: dict[float, tuple[np.ndarray, np.ndarray]] = {}
    for side in (EPOCHS >= T0, EPOCHS < T0):
        ts = np.unique(EPOCHS[side])
        ts = ts[np.argsort(np.abs(ts - T0))]
        x, phi, prev = X0.copy(), np.eye(6), T0
        for t in ts:
            x1, F, ok = integrate_stm(model, x[None], np.array([t - prev]), 60.0,
                                      pole_frame=POLE_FRAME, **params)
            assert ok[0]
            x, phi, prev = x1[0], F[0] @ phi, t
            out[float(t)] = (x, phi)
    return (np.array([out[float(t)][0] for t in EPOCHS]),
            np.array([out[float(t)][1] for t in EPOCHS]))


def test_gravity_equals_integrate_stm() -> None:
    tr = fm.trajectory(fm.ForceModel(j3=0.0, j4=0.0), X0, T0, EPOCHS, pole=POLE)
    x, phi = _chained("j2")
    assert tr.ok.all()
    np.testing.assert_allclose(tr.x, x, rtol=0, atol=1e-9)
    np.testing.assert_allclose(tr.phi, phi, rtol=0, atol=1e-10 * np.abs(phi).max())
    assert tr.s.shape == (EPOCHS.size, 6, 0)


def test_drag_equals_integrate_stm_drag() -> None:
    """J2 off: the "drag" model of `dynamics` (integrated by the numpy path, A by complex step)."""
    tr = fm.trajectory(fm.ForceModel(j2=0.0, j3=0.0, j4=0.0, drag=True), X0, T0, EPOCHS,
                       pole=POLE)
    x, phi = _chained("drag")
    np.testing.assert_allclose(tr.x, x, rtol=0, atol=1e-8)
    np.testing.assert_allclose(tr.phi, phi, rtol=0, atol=1e-10 * np.abs(phi).max())


def test_acceleration_is_dynamics_rhs() -> None:
    f = fm.ForceModel(drag=True, j3=0.0, j4=0.0)
    a = fm.acceleration(f, X0)  # pole = z: dynamics' own frame
    a_j2 = dynamics.rhs("j2", X0)[3:]
    a_drag = dynamics.rhs("drag", X0)[3:] - dynamics.rhs("two_body", X0)[3:]
    np.testing.assert_allclose(a, a_j2 + a_drag, rtol=1e-13, atol=1e-20)
    p = np.array([0.5, 1e-9, -2e-9, 3e-9])
    m = np.array([X0[:3] / np.linalg.norm(X0[:3]), np.zeros(3), np.cross(X0[:3], X0[3:])]).T
    m[:, 2] /= np.linalg.norm(m[:, 2])
    m[:, 1] = np.cross(m[:, 2], m[:, 0])
    expected = a_j2 + 0.5 * a_drag + m @ p[1:]
    np.testing.assert_allclose(fm.acceleration(f, X0, p), expected, rtol=1e-13, atol=1e-20)


def _zonal_potential(r: np.ndarray, pole: np.ndarray) -> float:
    """The J3 + J4 terms of the gravity potential, km^2/s^2 (numpy's Legendre series)."""
    rr = float(np.linalg.norm(r))
    s = float(pole @ r) / rr
    return -sum(MU_EARTH * j * (R_EARTH / rr) ** n / rr * legendre.legval(s, [0] * n + [1])
                for n, j in ((3, J3), (4, J4)))


def test_j3_j4_acceleration_is_the_gradient_of_their_potential() -> None:
    """About a tilted pole, at positions all over a LEO shell and a GEO one."""
    rng = np.random.default_rng(3)
    pole = np.array([0.1, -0.2, 1.0]) / np.linalg.norm([0.1, -0.2, 1.0])
    with_zonal, without = fm.ForceModel(), fm.ForceModel(j3=0.0, j4=0.0)
    for radius in (6800.0, 42164.0):
        for _ in range(20):
            u = rng.normal(size=3)
            r = radius * u / np.linalg.norm(u)
            x = np.r_[r, 0.0, 7.5, 0.0]
            got = fm.acceleration(with_zonal, x, pole=pole) - fm.acceleration(without, x,
                                                                                pole=pole)
            h = 1e-3
            grad = np.array([(_zonal_potential(r + h * e, pole)
                              - _zonal_potential(r - h * e, pole)) / (2 * h) for e in np.eye(3)])
            np.testing.assert_allclose(got, grad, rtol=1e-6, atol=1e-6 * np.abs(grad).max())


@pytest.mark.parametrize("j", range(4))
def test_sensitivities_match_finite_differences(j: int) -> None:
    f = fm.ForceModel(drag=True)
    which = [0, 1, 2, 3]
    tr = fm.trajectory(f, X0, T0, EPOCHS, fm.NOMINAL, which, pole=POLE)
    h = 0.05 if j == 0 else 1e-9
    p1, p2 = np.array(fm.NOMINAL), np.array(fm.NOMINAL)
    p1[j] += h
    p2[j] -= h
    fd = (fm.trajectory(f, X0, T0, EPOCHS, p1, pole=POLE).x
          - fm.trajectory(f, X0, T0, EPOCHS, p2, pole=POLE).x) / (2 * h)
    scale = np.abs(tr.s[:, :, j]).max()
    assert scale > 0
    np.testing.assert_allclose(tr.s[:, :, j], fd, rtol=0, atol=1e-6 * scale)


def test_stm_with_drag_matches_finite_differences() -> None:
    f = fm.ForceModel(drag=True)
    tr = fm.trajectory(f, X0, T0, EPOCHS[:5], pole=POLE)
    for k, h in enumerate([1e-3] * 3 + [1e-6] * 3):
        d = np.zeros(6)
        d[k] = h
        fd = (fm.trajectory(f, X0 + d, T0, EPOCHS[:5], pole=POLE).x
              - fm.trajectory(f, X0 - d, T0, EPOCHS[:5], pole=POLE).x) / (2 * h)
        np.testing.assert_allclose(tr.phi[:, :, k], fd, rtol=0,
                                   atol=1e-6 * np.abs(fd).max())


def test_non_finite_input_is_flagged() -> None:
    tr = fm.trajectory(fm.ForceModel(), np.full(6, np.nan), T0, EPOCHS)
    assert not tr.ok.any()


def test_unknown_parameter_is_refused() -> None:
    with pytest.raises(ValueError, match="drag_factor"):
        fm.parameter_index(["drag_factor"])

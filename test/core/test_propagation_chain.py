"""Tests for ssa_fusion.core.motion.propagation.integrate_chain: each step's state equals
`integrate_stm`'s taken step by step (the same numbers), for every model, both directions,
and a non-finite input or result ends the chain with ok False."""

import numpy as np
import pytest

from ssa_fusion.core.earth import frames
from ssa_fusion.core.motion import dynamics
from ssa_fusion.core.motion.propagation import integrate_chain, integrate_stm
from ssa_fusion.sim.scenarios import ISS_ELEMENTS

X0 = np.array(dynamics.elements_to_state(**ISS_ELEMENTS))


def _step_by_step(model: str, x0: np.ndarray, dt: np.ndarray, pole: np.ndarray | None):
    """The chain by `integrate_stm`, one step a call: (states (N, K, 6), ok (N,))."""
    out = np.empty((*dt.shape, 6))
    ok = np.ones(len(x0), bool)
    x = x0
    for k in range(dt.shape[1]):
        x, _, good = integrate_stm(model, x, dt[:, k], pole_frame=pole)
        ok &= good
        out[:, k] = x
    return out, ok


@pytest.mark.parametrize("model", ["two_body", "j2", "drag"])
def test_the_chain_is_integrate_stm_step_by_step(model):
    rng = np.random.default_rng(3)
    x0 = np.stack([X0, X0 * np.array([1.0, 1.0, 1.0, 1.001, 1.0, 0.999]), X0[[1, 0, 2, 4, 3, 5]]])
    dt = np.stack([rng.uniform(-3000.0, -10.0, 7),  # backwards, uneven steps
                   rng.uniform(10.0, 5000.0, 7),  # forwards
                   np.array([0.0, 600.0, 600.0, -1200.0, 0.0, 37.5, 600.0])])  # mixed, zero steps
    pole = frames.pole_frame(1.75e9)
    got, ok = integrate_chain(model, x0, dt, pole_frame=pole)
    want, ok_want = _step_by_step(model, x0, dt, pole)
    assert ok.all() and ok_want.all()
    if model == "drag":  # the numpy path: integrate_stm itself, step by step
        np.testing.assert_allclose(got, want, rtol=0, atol=1e-12)
    else:  # the compiled chain: the same numbers
        np.testing.assert_array_equal(got, want)
    # and it moved: 7 steps of up to 5000 s are not the start
    assert np.abs(got[1, -1, :3] - x0[1, :3]).max() > 100.0


def test_a_non_finite_step_or_state_ends_the_chain():
    x0 = np.stack([X0, X0, X0 * np.array([1, 1, 1, np.inf, 1, 1])])
    dt = np.array([[60.0, 60.0, 60.0], [60.0, np.nan, 60.0], [60.0, 60.0, 60.0]])
    out, ok = integrate_chain("j2", x0, dt)
    assert ok.tolist() == [True, False, False]
    want, _ = _step_by_step("j2", x0[:1], dt[:1], None)
    np.testing.assert_array_equal(out[0], want[0])
    np.testing.assert_array_equal(out[1, 0], want[0, 0])  # the step before the nan was taken

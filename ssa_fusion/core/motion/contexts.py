"""The high-fidelity model's contexts kept by the day, for a filter that predicts often.

`high_fidelity.propagate` builds what its kernel reads (`high_fidelity.setup`: the Earth's
orientation on a grid, the Sun's and the Moon's series) for the span of each call, ~10 ms:
nothing for a fit over days, too much for a filter predicting a minute ahead thousands of
times. `Contexts` keeps one context per span of whole UTC days (the day of the first and
of the last epoch asked, each with `high_fidelity.MARGIN_S` around it) and propagates
through it: the same numbers (a context covering more gives the same values), one setup a
day.

`augmented_motion` is a filter's motion with it: ``f(x, dt, t0) -> (x1, F)`` for a state
``[r, v, c_1 .. c_k, p_1 .. p_m]`` whose ``c`` are constants (a laser network's range
biases) and ``p`` the force-model parameters the filter estimates (``srp_scale``): F holds
the state transition matrix, the sensitivities to ``p`` and the identity for the rest.

Units: km, km/s, s; GCRF; epochs Unix s (UTC).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ssa_fusion.core.earth.timescales import DAY_S
from ssa_fusion.core.motion import high_fidelity as hf
from ssa_fusion.core.motion.force_model import Trajectory
from ssa_fusion.core.motion.force_spec import NOMINAL, PARAMETERS, ForceSpec

__all__ = ["Contexts", "augmented_motion"]

Array = NDArray[np.float64]
Motion = Callable[[Array, float, float], tuple[Array, Array]]

KEEP = 8
"""Contexts kept at most (the oldest dropped first)."""


class Contexts:
    """`high_fidelity.setup` contexts of one spec by span of UTC days (module docstring)."""

    def __init__(self, spec: ForceSpec, max_step_s: float = 60.0) -> None:
        self.spec = spec
        self.max_step_s = float(max_step_s)
        self._made: dict[tuple[int, int], hf.Context] = {}

    def context(self, t_unix: ArrayLike) -> hf.Context:
        """Return a context covering the epochs ``t_unix`` (Unix s)."""
        t = np.atleast_1d(np.asarray(t_unix, dtype=float))
        key = (math.floor(float(t.min()) / DAY_S), math.floor(float(t.max()) / DAY_S))
        ctx = self._made.get(key)
        if ctx is None:
            t0 = key[0] * DAY_S
            ctx = hf.setup(self.spec, t0, 0.0, (key[1] - key[0] + 1) * DAY_S)
            if len(self._made) >= KEEP:
                self._made.pop(next(iter(self._made)))
            self._made[key] = ctx
        return ctx

    def propagate(self, x0: ArrayLike, t0: float, t: ArrayLike, params: ArrayLike | None = None,
                  which: Sequence[int] = (), stm: bool = True) -> Trajectory:
        """`high_fidelity.propagate` through a cached context (its arguments)."""
        tt = np.atleast_1d(np.asarray(t, dtype=float))
        ctx = self.context(np.append(tt, t0))
        return hf.propagate(ctx, x0, t0, tt, params, which, self.max_step_s, stm=stm)


def augmented_motion(spec: ForceSpec, n: int, estimated: Sequence[str] = (),
                     max_step_s: float = 60.0) -> Motion:
    """Return ``f(x, dt, t0) -> (x1, F)`` of an ``n``-state filter (module docstring).

    ``estimated`` names the force-model parameters (`force_spec.PARAMETERS`) held in the
    last states, in that order; their nominal values are the spec's for the others.
    """
    contexts = Contexts(spec, max_step_s)
    which = [PARAMETERS.index(p) for p in estimated]
    m = len(which)
    if n < 6 + m:
        raise ValueError(f"a state of {n} cannot hold the orbit and {m} parameters")

    def f(x: Array, dt: float, t0: float) -> tuple[Array, Array]:
        xv = np.asarray(x, dtype=float)
        prm = np.array(NOMINAL, dtype=float)
        if m:
            prm[which] = xv[n - m:]
        tr = contexts.propagate(xv[:6], t0, [t0 + dt], prm, which)
        if not tr.ok[0]:
            raise RuntimeError(f"propagation failed: the orbit is not finite {dt} s on")
        x1 = xv.copy()
        x1[:6] = tr.x[0]
        F = np.eye(n)
        F[:6, :6] = tr.phi[0]
        if m:
            F[:6, n - m:] = tr.s[0]
        return x1, F

    return f

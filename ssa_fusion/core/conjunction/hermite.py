"""Trajectories between sampled states: quintic Hermite interpolation, compiled.

A screening samples every object at nodes ``t_k = t_first + k H`` (`NodeTable`) and needs
its state at many epochs in between. Between two nodes the position is the quintic that
matches the position, velocity and acceleration at both (the acceleration from two-body +
J2 gravity about the Earth's pole at the node's position, `propagation.j2_gravity`: the
trajectory's own acceleration up to what that model leaves out, drag and higher
harmonics, ~1e-6 km/s² at most in LEO).

The error of the interpolant: for a trajectory of angular rate w at radius r,
``H⁶ r w⁶ / 46080`` (the quintic's remainder), plus ``0.0174 da H²`` for an error ``da`` in
the node accelerations (at H = 300 s and 280 km altitude, ~0.3 m and ~2 m for
da = 1e-6 km/s²), plus ~0.2 H dv where the node velocities are dv off the derivative of the
positions (SGP4's are: 0.2 m/s in LEO, 13 m/s for an HEO). `interpolation_pad` measures it
on the nodes themselves.

Units: epochs Unix s, states GCRF km, km/s, accelerations km/s².
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ssa_fusion.core.base.constants import J2, MU_EARTH, R_EARTH
from ssa_fusion.core.base.jit import f64, jit
from ssa_fusion.core.motion.propagation import j2_gravity

__all__ = ["NodeTable", "hermite_weights", "interpolate", "interpolation_pad", "node_table",
           "position", "state_at", "velocity"]

Array = NDArray[np.float64]
Weights = tuple[float, ...]
"""The twelve weights of `hermite_weights`."""

@dataclass(frozen=True)
class NodeTable:
    """Objects' states and accelerations at evenly spaced epochs (the interpolation nodes).

    Attributes
    ----------
    t_first : float
        Epoch of node 0, Unix s (UTC).
    step_s : float
        Node spacing H, s.
    nodes : ndarray (K, N, 9)
        Node k of object i: GCRF position km, velocity km/s, acceleration km/s²; NaN where
        the object has no state.
    """

    t_first: float
    step_s: float
    nodes: Array

    @property
    def t_last(self) -> float:
        """Epoch of the last node, Unix s."""
        return float(self.t_first + (self.nodes.shape[0] - 1) * self.step_s)


@jit
def _accelerations(x: Array, pole: Array, out: Array) -> None:
    """``out[k, i] = [r, v, a]`` of states ``x`` (N, K, 6), a from two-body + J2 about pole."""
    n, k = x.shape[0], x.shape[1]
    for j in range(k):
        for i in range(n):
            r0, r1, r2 = x[i, j, 0], x[i, j, 1], x[i, j, 2]
            a0, a1, a2, _, _, _, _, _, _ = j2_gravity(r0, r1, r2, MU_EARTH, J2, R_EARTH,
                                                      pole[0], pole[1], pole[2])
            for c in range(6):
                out[j, i, c] = x[i, j, c]
            out[j, i, 6], out[j, i, 7], out[j, i, 8] = a0, a1, a2


def node_table(x: ArrayLike, t_first: float, step_s: float, pole: ArrayLike) -> NodeTable:
    """Build the `NodeTable` of states ``x`` (N, K, 6) at ``t_first + k step_s``.

    ``pole``: the Earth's pole (3,), a GCRF unit vector (`frames.cip_gcrs`), the axis of J2.
    """
    xs = f64(np.asarray(x, dtype=float))
    out = np.empty((xs.shape[1], xs.shape[0], 9))
    _accelerations(xs, f64(np.asarray(pole, dtype=float).reshape(3)), out)
    return NodeTable(float(t_first), float(step_s), out)


@jit
def hermite_weights(u: float, h: float) -> Weights:
    """Return the quintic Hermite weights at ``u = (t - t_k) / h`` in [0, 1], node spacing h.

    ``(p0, v0, a0, p1, v1, a1)`` weights of the position, then the same six of the
    velocity: ``r(t) = sum w_c y_c`` over node k's and k+1's position, velocity and
    acceleration (the powers of h folded in).
    """
    u2 = u * u
    u3 = u2 * u
    u4 = u3 * u
    u5 = u4 * u
    h2 = h * h
    return (1.0 - 10.0 * u3 + 15.0 * u4 - 6.0 * u5,
            h * (u - 6.0 * u3 + 8.0 * u4 - 3.0 * u5),
            h2 * 0.5 * (u2 - 3.0 * u3 + 3.0 * u4 - u5),
            10.0 * u3 - 15.0 * u4 + 6.0 * u5,
            h * (-4.0 * u3 + 7.0 * u4 - 3.0 * u5),
            h2 * 0.5 * (u3 - 2.0 * u4 + u5),
            (-30.0 * u2 + 60.0 * u3 - 30.0 * u4) / h,
            1.0 - 18.0 * u2 + 32.0 * u3 - 15.0 * u4,
            h * 0.5 * (2.0 * u - 9.0 * u2 + 12.0 * u3 - 5.0 * u4),
            (30.0 * u2 - 60.0 * u3 + 30.0 * u4) / h,
            -12.0 * u2 + 28.0 * u3 - 15.0 * u4,
            h * 0.5 * (3.0 * u2 - 8.0 * u3 + 5.0 * u4))


@jit
def position(nodes: Array, k: int, i: int, w: Weights, out: Array) -> None:
    """``out[:3]`` = position of object ``i`` in node interval ``k`` with weights ``w``."""
    a = nodes[k, i]
    b = nodes[k + 1, i]
    for c in range(3):
        out[c] = (w[0] * a[c] + w[1] * a[3 + c] + w[2] * a[6 + c]
                  + w[3] * b[c] + w[4] * b[3 + c] + w[5] * b[6 + c])


@jit
def velocity(nodes: Array, k: int, i: int, w: Weights, out: Array) -> None:
    """``out[3:6]`` = velocity of object ``i`` in node interval ``k`` with weights ``w``."""
    a = nodes[k, i]
    b = nodes[k + 1, i]
    for c in range(3):
        out[3 + c] = (w[6] * a[c] + w[7] * a[3 + c] + w[8] * a[6 + c]
                      + w[9] * b[c] + w[10] * b[3 + c] + w[11] * b[6 + c])


@jit
def interpolate(nodes: Array, k: int, i: int, w: Weights, out: Array) -> None:
    """``out[:6]`` = state of object ``i`` in node interval ``k`` with weights ``w``."""
    position(nodes, k, i, w, out)
    velocity(nodes, k, i, w, out)


@jit
def state_at(nodes: Array, t_first: float, h: float, i: int, t: float, out: Array) -> None:
    """``out[:6]`` = interpolated state of object ``i`` at epoch ``t`` (s after node 0 ...).

    ``t`` in Unix s; the node interval is the one holding ``t`` (clamped to the table:
    outside it the end intervals extrapolate).
    """
    s = (t - t_first) / h
    k = min(max(math.floor(s), 0), nodes.shape[0] - 2)
    interpolate(nodes, k, i, hermite_weights(s - k, h), out)


def interpolation_pad(table: NodeTable, safety: float = 2.0,
                      floor_km: float = 0.005) -> tuple[Array, Array]:
    """Return bounds on each object's interpolation errors: position km, velocity km/s (N,).

    Measured on the table itself: nodes k + 1 and k + 2 predicted by the interpolant of
    three times the spacing between nodes k and k + 3 (at u = 1/3 and 2/3), for every k.
    Where the node velocities are dv off the derivative of the positions (SGP4's are:
    0.2 m/s in LEO, 13 m/s for an HEO under SDP4's lunisolar terms), the table's error is
    at most 0.147 H dv (antisymmetric in the interval: nothing at its middle) and the wide
    interpolant's 0.37 H dv there (2.5 times more); where the trajectory is smooth, the
    wide interpolant's error is 3⁶ = 729 times the table's. The position bound is
    ``safety / 2.5`` times the largest error seen, plus ``floor_km``; the velocity bound
    4 / H times that (dv itself is at most 2.7 / H times the error seen). NaN nodes are
    skipped; with fewer than four nodes the bounds are the floors.
    """
    nodes, h = table.nodes, table.step_s
    err = np.zeros(nodes.shape[1])
    if nodes.shape[0] >= 4:
        a, b = nodes[:-3], nodes[3:]
        for third in (1, 2):
            w = np.asarray(hermite_weights(third / 3.0, 3.0 * h))
            pos = (w[0] * a[..., :3] + w[1] * a[..., 3:6] + w[2] * a[..., 6:]
                   + w[3] * b[..., :3] + w[4] * b[..., 3:6] + w[5] * b[..., 6:])
            with np.errstate(invalid="ignore"):
                e = np.linalg.norm(pos - nodes[third:nodes.shape[0] - 3 + third, :, :3],
                                   axis=-1)
                err = np.maximum(err, np.max(np.where(np.isfinite(e), e, 0.0), axis=0))
    eps = floor_km + safety / 2.5 * err
    return eps, 4.0 * eps / h

"""The residual's frame: curvilinear coordinates about a placeholder trajectory.

A gap forecaster's residual (`residual`) is the difference between an estimate and the
placeholder's trajectory (`orbit_propagator`: two-body or two-body + J2), expressed in the
curvilinear frame of that trajectory (`curvilinear`): radial distance difference,
along-track arc and cross-track arc, km, at the placeholder's predicted radius, with their
rates (`state_residual`, `apply_residual`); covariances map between that frame and the GCRF
(`to_eci_covariance`, `residual_sigmas`). Frames and units: GCRF km, km/s; times s (Unix
s); the frame's axes radial / along-track / cross-track (RTN, `frames.rtn_axes`).
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ssa_fusion.core.base.constants import MU_EARTH
from ssa_fusion.core.base.types import MotionModel
from ssa_fusion.core.earth import frames
from ssa_fusion.core.earth.frames import cross3, rtn_axes
from ssa_fusion.core.motion.propagation import integrate_chain

__all__ = ["Propagator", "apply_residual", "argument_of_latitude", "curvilinear",
           "from_curvilinear", "orbit_propagator", "period_of", "residual_sigmas",
           "state_residual", "to_eci_covariance"]

Array = NDArray[np.float64]


Propagator = Callable[[Array, float, Array], Array]
"""propagate(x0 (6,), t0 s, t (k,) s) -> (k, 6): the placeholder's trajectory from x0 at t0,
sampled at t (before or after t0, any order)."""


def orbit_propagator(model: MotionModel | str) -> Propagator:
    """Return a placeholder trajectory as a `Propagator`.

    The placeholder trajectory of `dynamics` model ``"two_body"`` or ``"j2"`` (GCRF, km,
    km/s, epochs Unix s; J2 about the Earth's pole at the anchor, `frames.pole_frame`) as a
    `Propagator`: integrated backwards and forwards from x0 as needed (epochs in
    any order, repeats included), epoch to epoch outwards from t0 on either side, by
    `propagation.integrate_chain` (fixed-step DOP853, steps of at most 60 s, compiled, one
    call a side; each step's state the same numbers as `propagation.integrate_stm`'s;
    within ~5e-9 relative of scipy's adaptive DOP853 at rtol 1e-10 over three days of a LEO
    orbit, and ~40x faster). RuntimeError when the orbit cannot be propagated (a
    non-finite result).
    """

    def propagate(x0: Array, t0: float, t: Array) -> Array:
        pole = frames.pole_frame(t0)  # J2 about the Earth's pole (t0: Unix s)
        t_all, back = np.unique(np.asarray(t, float), return_inverse=True)  # repeats too
        out = np.empty((len(t_all), 6))
        out[t_all == t0] = x0
        for side in (t_all < t0, t_all > t0):
            order = np.flatnonzero(side)  # increasing epochs
            if not order.size:
                continue
            if t_all[order[0]] < t0:
                order = order[::-1]  # backwards: decreasing epochs
            steps = np.diff(np.concatenate([[float(t0)], t_all[order]]))  # epoch to epoch
            xs, ok = integrate_chain(model, np.asarray(x0, float)[None], steps[None],
                                     pole_frame=pole)
            if not ok[0]:
                raise RuntimeError(f"the {model} orbit cannot be propagated to every epoch "
                                   f"from t={t0}")
            out[order] = xs[0]
        return out[back.reshape(-1)]

    return propagate


def curvilinear(x_ref: ArrayLike, r: ArrayLike) -> Array:
    """Return curvilinear coordinates of positions about reference states.

    Positions r (k, 3) relative to reference states x_ref (k, 6), km: (|r| - |r_ref|,
    |r_ref| * in-plane angle from r_ref, |r_ref| * angle out of the reference plane).
    """
    x = np.atleast_2d(np.asarray(x_ref, float))
    r = np.atleast_2d(np.asarray(r, float))
    ax = rtn_axes(x)
    c = np.einsum("kij,kj->ki", ax, r)
    rr = np.linalg.norm(x[:, :3], axis=1)
    rn = np.linalg.norm(r, axis=1)
    du = np.arctan2(c[:, 1], c[:, 0])
    dw = np.arcsin(np.clip(c[:, 2] / rn, -1.0, 1.0))
    return np.stack([rn - rr, rr * du, rr * dw], axis=1)


def from_curvilinear(x_ref: ArrayLike, rho: ArrayLike) -> Array:
    """Return the positions whose curvilinear coordinates are given.

    The GCRF positions (k, 3) whose `curvilinear` coordinates about x_ref are rho (k, 3).
    """
    x = np.atleast_2d(np.asarray(x_ref, float))
    rho = np.atleast_2d(np.asarray(rho, float))
    ax = rtn_axes(x)
    rr = np.linalg.norm(x[:, :3], axis=1)
    du, dw = rho[:, 1] / rr, rho[:, 2] / rr
    local = np.stack([np.cos(dw) * np.cos(du), np.cos(dw) * np.sin(du), np.sin(dw)], axis=1)
    out: Array = (rr + rho[:, 0])[:, None] * np.einsum("kji,kj->ki", ax, local)
    return out


_H_S = 1.0
"""Time step (s) of the central differences that give the residual's rate."""


def _with_rate(fn: Callable[[Array, Array], Array], x_ref: ArrayLike, y: ArrayLike) -> Array:
    """Return (fn(x_ref, y position), its rate) over +-`_H_S` of straight-line motion.

    x_ref (k, 6) reference states and y (k, 6) [position, rate] move in straight lines for
    +-h; the rate is the central difference of fn (the gravity both feel cancels to
    O(1e-9) km over 1 s).
    """
    x_ref = np.atleast_2d(np.asarray(x_ref, float))
    y = np.atleast_2d(np.asarray(y, float))
    h = _H_S

    def at(dt: float) -> Array:
        ref = np.concatenate([x_ref[:, :3] + dt * x_ref[:, 3:], x_ref[:, 3:]], axis=1)
        return fn(ref, y[:, :3] + dt * y[:, 3:])

    return np.concatenate([fn(x_ref, y[:, :3]), (at(h) - at(-h)) / (2 * h)], axis=1)


def state_residual(x_ref: ArrayLike, x: ArrayLike) -> Array:
    """Return the curvilinear residual of states and its rate.

    Residual (k, 6) of GCRF states x against reference states x_ref (both (k, 6)): the
    `curvilinear` position residual (km) and its rate (km/s).
    """
    return _with_rate(curvilinear, x_ref, x)


def apply_residual(x_ref: ArrayLike, res: ArrayLike) -> Array:
    """Return the states whose `state_residual` is given.

    The GCRF states (k, 6) whose `state_residual` against x_ref (k, 6) is res (k, 6).
    """
    return _with_rate(from_curvilinear, x_ref, res)


def argument_of_latitude(x: ArrayLike) -> tuple[Array, Array]:
    """Return the argument of latitude and its rate.

    Argument of latitude u (rad, from the ascending node) and its rate |h|/|r|^2 (rad/s)
    of GCRF states (k, 6).
    """
    x = np.atleast_2d(np.asarray(x, float))
    r, v = x[:, :3], x[:, 3:]
    h = cross3(r, v)
    hn = np.linalg.norm(h, axis=1)
    node = np.stack([-h[:, 1], h[:, 0], np.zeros(len(h))], axis=1)  # z x h
    nn = np.linalg.norm(node, axis=1)
    node = np.where(nn[:, None] > 1e-12 * hn[:, None], node / np.maximum(nn, 1e-300)[:, None],
                    np.array([1.0, 0.0, 0.0]))
    y_axis = cross3(h / hn[:, None], node)
    u = np.arctan2(np.einsum("ki,ki->k", r, y_axis), np.einsum("ki,ki->k", r, node))
    rn2 = np.einsum("ki,ki->k", r, r)
    return u, hn / rn2


def to_eci_covariance(x_ref: ArrayLike, cov: ArrayLike) -> Array:
    """Map residual-frame covariances to GCRF.

    Covariances (k, 6, 6) of residual-frame errors (position, rate) about x_ref (k, 6)
    mapped to GCRF position and velocity: dr = M rho, dv = M (rho_dot + w x rho), with M the
    frame's axes and w = (0, 0, |h|/|r|^2) its rotation rate (rad/s) in the frame.
    """
    x_ref = np.atleast_2d(np.asarray(x_ref, float))
    ax = rtn_axes(x_ref)
    _, w = argument_of_latitude(x_ref)
    k = ax.shape[0]
    Mt = np.transpose(ax, (0, 2, 1))
    W = np.zeros((k, 3, 3))
    W[:, 0, 1], W[:, 1, 0] = -w, w  # w x rho, w along the cross-track axis
    J = np.zeros((k, 6, 6))
    J[:, :3, :3] = J[:, 3:, 3:] = Mt
    J[:, 3:, :3] = Mt @ W
    out: Array = np.einsum("kij,kjl,kml->kim", J, np.asarray(cov, float), J)
    return 0.5 * (out + np.transpose(out, (0, 2, 1)))


def residual_sigmas(x_ref: ArrayLike, P: ArrayLike, floor: tuple[float, float]) -> Array:
    """Return an estimate's standard deviations along the residual frame.

    Standard deviations (k, 6) of estimates with GCRF covariances P (k, 6, 6) along the
    residual frame's axes about x_ref (k, 6), floored at `floor` (km, km/s).
    """
    ax = rtn_axes(x_ref)
    P = np.asarray(P, float)
    sp = np.einsum("kij,kjl,kil->ki", ax, P[:, :3, :3], ax)
    sv = np.einsum("kij,kjl,kil->ki", ax, P[:, 3:, 3:], ax)
    out: Array = np.sqrt(np.concatenate([np.maximum(sp, floor[0] ** 2),
                                         np.maximum(sv, floor[1] ** 2)], axis=1))
    return out


def period_of(x: ArrayLike) -> float:
    """Osculating orbital period (s) of an GCRF state (6,) (two-body; inf if unbound)."""
    x = np.asarray(x, float)
    energy = 0.5 * float(x[3:] @ x[3:]) - MU_EARTH / float(np.linalg.norm(x[:3]))
    if energy >= 0.0:
        return math.inf
    a = -MU_EARTH / (2.0 * energy)
    return 2.0 * math.pi * math.sqrt(a ** 3 / MU_EARTH)

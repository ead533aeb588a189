"""The geometry of a close approach: RTN frames, relative state, the encounter plane.

Vectorised over n conjunctions (leading axis). States are inertial (GCRF, or any inertial
frame both objects share), km and km/s; covariances km², km²/s, km²/s². Relative quantities
are object 2 minus object 1 (as a CDM's ``RELATIVE_POSITION_R`` ...).

The encounter plane is the plane through object 1 perpendicular to the relative velocity.
Its axes (`Encounter.axes`, rows): ``x`` the miss direction (the relative position's part in
the plane), ``y`` the relative velocity's direction, ``z = x × y``. The miss vector and the
combined covariance are projected onto (x, z). Projecting the relative position onto the
plane is the linear-motion shift to the true closest approach (`Encounter.tca_offset_s`),
so states given a few milliseconds off TCA (as CDMs round it) give the same plane.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ssa_fusion.core.base.constants import MU_EARTH
from ssa_fusion.core.earth.frames import rtn_axes

Array = NDArray[np.float64]
BoolArray = NDArray[np.bool_]

__all__ = ["Encounter", "encounter_plane", "inertial_to_rtn", "orbital_period",
           "relative_state_rtn", "rtn_to_inertial"]


def _states(x: ArrayLike) -> Array:
    """States as (n, 6) floats."""
    a = np.asarray(x, dtype=float)
    return a.reshape(1, 6) if a.shape == (6,) else a


def _covs(c: ArrayLike) -> Array:
    """Covariances as (n, k, k) floats (k = 3 or 6)."""
    a = np.asarray(c, dtype=float)
    return a[None] if a.ndim == 2 else a


def _block_rotation(x: Array, k: int) -> Array:
    """Return the RTN -> inertial rotations (n, k, k) of states x (n, 6).

    The RTN axes as columns, repeated on the velocity block when k = 6.
    """
    m = np.swapaxes(rtn_axes(x), 1, 2)
    if k == 3:
        return m
    out = np.zeros((len(x), 6, 6))
    out[:, :3, :3] = m
    out[:, 3:, 3:] = m
    return out


def rtn_to_inertial(x: ArrayLike, c_rtn: ArrayLike) -> Array:
    """Rotate covariances from each state's RTN frame to the inertial frame.

    The frame is taken as it is at the epoch (no ω × r term): how a CDM's RTN covariance is
    meant (CCSDS 508.0-B-1) and how CARA converts it.

    Parameters
    ----------
    x : array_like (6,) or (n, 6)
        Inertial states, km, km/s (they define R, T, N).
    c_rtn : array_like (k, k) or (n, k, k), k = 3 or 6
        Covariances in RTN, km² (and km²/s, km²/s²).

    Returns
    -------
    ndarray (n, k, k)
        Inertial covariances, same units.
    """
    c = _covs(c_rtn)
    m = _block_rotation(_states(x), c.shape[-1])
    out: Array = m @ c @ np.swapaxes(m, 1, 2)
    return out


def inertial_to_rtn(x: ArrayLike, c: ArrayLike) -> Array:
    """Rotate inertial covariances (k, k) or (n, k, k) into each state's RTN frame.

    The inverse of `rtn_to_inertial`; km² (and km²/s, km²/s²).
    """
    cc = _covs(c)
    m = _block_rotation(_states(x), cc.shape[-1])
    out: Array = np.swapaxes(m, 1, 2) @ cc @ m
    return out


def relative_state_rtn(x1: ArrayLike, x2: ArrayLike) -> Array:
    """Return object 2's state relative to object 1 in object 1's RTN frame (n, 6), km, km/s.

    The non-rotating frame of the epoch (a CDM's ``RELATIVE_POSITION_R`` .. ``_VELOCITY_N``).
    """
    a, b = _states(x1), _states(x2)
    rot = rtn_axes(a)
    d = b - a
    return np.concatenate([np.einsum("nij,nj->ni", rot, d[:, :3]),
                           np.einsum("nij,nj->ni", rot, d[:, 3:])], axis=1)


def orbital_period(x: ArrayLike, mu: float = MU_EARTH) -> Array:
    """Osculating two-body periods (n,) of inertial states (n, 6), s (inf when not bound)."""
    s = _states(x)
    r = np.linalg.norm(s[:, :3], axis=1)
    v2 = np.einsum("ni,ni->n", s[:, 3:], s[:, 3:])
    inv_a = 2.0 / r - v2 / mu
    with np.errstate(divide="ignore", invalid="ignore"):
        period = np.where(inv_a > 0, 2 * np.pi * np.sqrt(1.0 / np.abs(inv_a) ** 3 / mu), np.inf)
    out: Array = period
    return out


@dataclass(frozen=True)
class Encounter:
    """The encounter plane of n conjunctions (module docstring for the axes).

    Attributes
    ----------
    rel_position : ndarray (n, 3)
        Object 2 - object 1 at the given epoch, inertial, km.
    rel_velocity : ndarray (n, 3)
        Its rate, km/s.
    axes : ndarray (n, 3, 3)
        Rows x (miss direction), y (relative velocity), z = x × y, inertial unit vectors.
    miss : ndarray (n, 2)
        Miss vector at the linear TCA in the plane's (x, z) axes, km (z is 0 by construction).
    cov : ndarray (n, 2, 2)
        Combined position covariance projected on (x, z), km².
    cov_3d : ndarray (n, 3, 3)
        Combined inertial position covariance (object 1's + object 2's), km².
    tca_offset_s : ndarray (n,)
        Linear TCA minus the epoch, s (NaN where the relative velocity is zero).
    """

    rel_position: Array
    rel_velocity: Array
    axes: Array
    miss: Array
    cov: Array
    cov_3d: Array
    tca_offset_s: Array

    @property
    def miss_km(self) -> Array:
        """Miss distance at the linear TCA (n,), km."""
        out: Array = np.linalg.norm(self.miss, axis=1)
        return out

    @property
    def speed_km_s(self) -> Array:
        """Relative speed (n,), km/s."""
        out: Array = np.linalg.norm(self.rel_velocity, axis=1)
        return out

    @property
    def moving(self) -> BoolArray:
        """Where the relative velocity is not zero (n,): where the plane exists."""
        out: BoolArray = self.speed_km_s > 0
        return out


def _plane_axes(r: Array, v: Array) -> tuple[Array, Array]:
    """Rows (x, y, z) (n, 3, 3) of the encounter frame and the linear TCA offsets (n,), s."""
    speed = np.linalg.norm(v, axis=1)
    with np.errstate(divide="ignore", invalid="ignore"):
        y = v / speed[:, None]
        dt = -np.einsum("ni,ni->n", r, v) / speed ** 2
    y = np.where(speed[:, None] > 0, y, np.array([0.0, 1.0, 0.0]))
    perp = r - np.einsum("ni,ni->n", r, y)[:, None] * y
    norm = np.linalg.norm(perp, axis=1)
    # a zero miss: any direction in the plane (the one least along y's largest component)
    pick = np.eye(3)[np.argmin(np.abs(y), axis=1)]
    fallback = pick - np.einsum("ni,ni->n", pick, y)[:, None] * y
    small = norm <= 1e-15 * np.maximum(np.linalg.norm(r, axis=1), 1.0)
    perp = np.where(small[:, None], fallback, perp)
    x = perp / np.linalg.norm(perp, axis=1, keepdims=True)
    return np.stack([x, y, np.cross(x, y)], axis=1), np.where(speed > 0, dt, np.nan)


def encounter_plane(x1: ArrayLike, p1: ArrayLike, x2: ArrayLike, p2: ArrayLike) -> Encounter:
    """Project a conjunction onto its encounter plane (module docstring).

    Parameters
    ----------
    x1, x2 : array_like (6,) or (n, 6)
        Inertial states of objects 1 and 2 at (or near) TCA, km, km/s.
    p1, p2 : array_like (k, k) or (n, k, k), k >= 3
        Their inertial covariances (only the position block is used), km².

    Returns
    -------
    Encounter
    """
    a, b = _states(x1), _states(x2)
    c = _covs(p1)[:, :3, :3] + _covs(p2)[:, :3, :3]
    c = np.broadcast_to(c, (len(a), 3, 3))
    r, v = b[:, :3] - a[:, :3], b[:, 3:] - a[:, 3:]
    axes, dt = _plane_axes(r, v)
    plane = axes[:, [0, 2], :]
    miss = np.einsum("nij,nj->ni", plane, r)
    cov = plane @ c @ np.swapaxes(plane, 1, 2)
    return Encounter(r, v, axes, miss, 0.5 * (cov + np.swapaxes(cov, 1, 2)), c,
                     np.asarray(dt, dtype=float))

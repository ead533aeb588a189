"""When the short-encounter (2D) assumption holds: the encounter's time bounds (Coppola 2012).

The 2D Pc takes the relative motion as a straight line through the whole encounter. That
holds when the encounter (the time the relative-position Gaussian needs to sweep past the
hard-body sphere) is short beside the orbits. Coppola (2012b, "Evaluating the short encounter
assumption of the probability of collision formula", AAS 12-248, eqs. 5-16) bounds that time:
outside ``[tau0, tau1]`` around TCA the rate of collision probability is below a fraction
gamma of its total. With the relative velocity as the first axis of an encounter frame,
the combined position covariance A split into ``eta² = A_xx``, ``w = A_(yz)x``,
``P = A_(yz)(yz)``, ``b = P⁻¹ w``::

    tau0 = (-alpha sqrt(2 (eta² - bᵀw)) + bᵀr_yz - R sqrt(1 + bᵀb)) / |v|
    tau1 = (+alpha sqrt(2 (eta² - bᵀw)) + bᵀr_yz + R sqrt(bᵀb)) / |v|,  alpha = erfcinv(gamma)

`usage_warnings` compares the bounds with the shorter osculating orbital period, as CARA
flags its 2D Pc: an encounter longer than `EXTENDED_CUTOFF` of it, or reaching further than
`OFFSET_CUTOFF` of it from TCA, breaks the assumption.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy import special

from ssa_fusion.core.conjunction.result import EXTENDED_CUTOFF, OFFSET_CUTOFF, PcWarning

Array = NDArray[np.float64]

__all__ = ["GAMMA", "encounter_bounds", "usage_warnings"]

GAMMA = 1e-16
"""Fraction of the collision probability rate left outside the bounds (CARA's default)."""


def encounter_bounds(r: ArrayLike, v: ArrayLike, cov: ArrayLike, hbr: ArrayLike,
                     gamma: float = GAMMA) -> tuple[Array, Array]:
    """Coppola (2012b) time bounds (tau0, tau1) of n linear encounters (module docstring).

    Parameters
    ----------
    r, v : array_like (n, 3)
        Relative position (km) and velocity (km/s) at TCA, inertial.
    cov : array_like (n, 3, 3)
        Combined relative position covariance, inertial, km².
    hbr : float or array_like (n,)
        Combined hard-body radius, km.
    gamma : float
        Fraction of the probability rate left outside.

    Returns
    -------
    tau0, tau1 : ndarray (n,)
        Start and end of the encounter relative to TCA, s (-inf, inf for zero speed).
    """
    rr = np.asarray(r, dtype=float).reshape(-1, 3)
    vv = np.asarray(v, dtype=float).reshape(-1, 3)
    a = np.asarray(cov, dtype=float).reshape(-1, 3, 3)
    rad = np.broadcast_to(np.asarray(hbr, dtype=float).reshape(-1), (len(rr),))
    speed = np.linalg.norm(vv, axis=1)
    moving = speed > 0
    x = vv / np.where(moving, speed, 1.0)[:, None]
    y = rr - np.einsum("ni,ni->n", rr, x)[:, None] * x
    ny = np.linalg.norm(y, axis=1)
    pick = np.eye(3)[np.argmin(np.abs(x), axis=1)]
    y = np.where((ny > 0)[:, None], y, pick - np.einsum("ni,ni->n", pick, x)[:, None] * x)
    y /= np.linalg.norm(y, axis=1, keepdims=True)
    rot = np.stack([x, y, np.cross(x, y)], axis=1)
    ae = rot @ a @ np.swapaxes(rot, 1, 2)
    re = np.einsum("nij,nj->ni", rot, rr)
    eta2, w, p = ae[:, 0, 0], ae[:, 1:, 0], ae[:, 1:, 1:]
    b = np.linalg.solve(p, w[:, :, None])[:, :, 0]
    sv2 = np.sqrt(np.maximum(0.0, 2.0 * (eta2 - np.einsum("ni,ni->n", b, w))))
    q0 = np.einsum("ni,ni->n", b, re[:, 1:])
    btb = np.einsum("ni,ni->n", b, b)
    spread = special.erfcinv(gamma) * sv2
    s = np.where(moving, speed, 1.0)
    tau0 = np.where(moving, (-spread + q0 - rad * np.sqrt(1.0 + btb)) / s, -np.inf)
    tau1 = np.where(moving, (spread + q0 + rad * np.sqrt(btb)) / s, np.inf)
    return tau0, tau1


def usage_warnings(tau0: float, tau1: float, period_s: float) -> frozenset[PcWarning]:
    """Return the 2D Pc's usage warnings of one encounter (module docstring).

    Parameters
    ----------
    tau0, tau1 : float
        The encounter's bounds around TCA, s (`encounter_bounds`).
    period_s : float
        The shorter orbital period of the two objects, s.
    """
    out: set[PcWarning] = set()
    if not np.isfinite(tau1 - tau0) or (tau1 - tau0) > EXTENDED_CUTOFF * period_s:
        out.add(PcWarning.EXTENDED_ENCOUNTER)
    if not np.isfinite(tau1 - tau0) or max(abs(tau0), abs(tau1)) > OFFSET_CUTOFF * period_s:
        out.add(PcWarning.OFFSET_ENCOUNTER)
    return frozenset(out)

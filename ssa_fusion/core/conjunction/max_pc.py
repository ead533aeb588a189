"""The largest 2D Pc a missing covariance allows: upper bounds when a covariance is missing.

* One covariance missing (Frisbee 2015): the unknown one is taken along the miss direction
  û with the variance that maximises the Pc. With the known combined covariance C and
  ``K² = mᵀC⁻¹m``, adding ``V ûûᵀ`` gives (Sherman-Morrison) a quadratic form ``K²/s`` and a
  determinant ``det C · s``, ``s = 1 + V K²/|m|²``; the Gaussian's density at the miss is
  largest at ``s = K²``, i.e. ``V = |m|² (K² - 1)/K²`` when K > 1 (else V = 0: the known
  covariance alone). The Pc is then the 2D Pc with ``C + V ûûᵀ`` (`pc2d`).
* Both missing (Alfano 2003's maximum probability in its degenerate limit): any Gaussian
  centred on the miss puts at most ``P(|d + σ Z| < R)`` in the circle, σ² = ûᵀCû, and that is
  largest at ``σ² = 2 d R / ln((d + R)/(d - R))`` (1 when d <= R). A bound over every
  covariance, reached by a covariance flattened along the miss.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy import special

from ssa_fusion.core.conjunction.pc2d import CircleIntegral, log10_pc_circle

Array = NDArray[np.float64]

__all__ = ["frisbee_max_cov", "log10_max_pc_frisbee", "log10_max_pc_no_covariance"]


def frisbee_max_cov(miss: ArrayLike, cov_known: ArrayLike) -> Array:
    """Return the combined covariance (2, 2) that maximises the Pc over one unknown covariance.

    Parameters
    ----------
    miss : array_like (2,)
        Miss vector in the encounter plane, km.
    cov_known : array_like (2, 2)
        The known object's position covariance in the plane, km².

    Returns
    -------
    ndarray (2, 2)
        ``cov_known + V ûûᵀ`` (module docstring), km².
    """
    m = np.asarray(miss, dtype=float).reshape(2)
    c = np.asarray(cov_known, dtype=float).reshape(2, 2)
    d2 = float(m @ m)
    if d2 == 0.0:
        return c.copy()
    k2 = float(m @ np.linalg.solve(c, m))
    var = d2 * (k2 - 1.0) / k2 if k2 > 1.0 else 0.0
    out: Array = c + var * np.outer(m, m) / d2
    return out


def log10_max_pc_frisbee(miss: ArrayLike, cov_known: ArrayLike, hbr: float) -> CircleIntegral:
    """Return the 2D Pc maximised over one missing covariance, as `log10_pc_circle`.

    Parameters
    ----------
    miss : array_like (2,)
        Miss vector in the encounter plane, km.
    cov_known : array_like (2, 2)
        The known object's position covariance in the plane, km².
    hbr : float
        Combined hard-body radius, km.
    """
    return log10_pc_circle(miss, frisbee_max_cov(miss, cov_known), hbr)


def log10_max_pc_no_covariance(miss_km: float, hbr_km: float) -> float:
    """log10 of the largest Pc any Gaussian centred on the miss gives (module docstring).

    Parameters
    ----------
    miss_km : float
        Miss distance, km.
    hbr_km : float
        Combined hard-body radius, km.
    """
    d, r = abs(float(miss_km)), float(hbr_km)
    if d <= r:
        return 0.0
    sigma = math.sqrt(2.0 * d * r / math.log((d + r) / (d - r)))
    a, b = (-r - d) / sigma, (r - d) / sigma  # both negative: the lower tail, in logs
    lb, la = float(special.log_ndtr(b)), float(special.log_ndtr(a))
    return (lb + math.log(-math.expm1(la - lb))) / math.log(10.0)

"""Solar radiation pressure on a cannonball, with the Earth's conical shadow, compiled.

Acceleration (GCRF, km/s^2) of an object at r with the Sun at r_s (geocentric)::

    a = nu k (r - r_s) / |r - r_s|^3,   k = P Cr (A/m) AU^2 1e-3

(``P`` = 4.56e-6 N/m^2 the pressure at 1 AU, A/m m^2/kg, AU km: `force_spec`). ``nu`` is the
fraction of the Sun's disc seen past the Earth (`shadow_fraction`; Montenbruck & Gill 2000,
§3.4.2): the Sun's apparent radius ``a = asin(R_sun / |r_s - r|)``, the Earth's
``b = asin(R_E / |r|)`` (a sphere of the equatorial radius), and their apparent separation
``c`` (the angle between the directions to the Sun and to the Earth's centre)::

    c >= a + b:            nu = 1                                  (sunlight)
    c <= b - a:            nu = 0                                  (umbra)
    c <  a - b:            nu = 1 - b^2 / a^2                      (annular; never for the Earth)
    otherwise (penumbra):  nu = 1 - (a^2 acos(x / a) + b^2 acos((c - x) / b) - c y) / (pi a^2)
                           x = (c^2 + a^2 - b^2) / (2 c),  y = sqrt(a^2 - x^2)

The gradient of the acceleration (for the variational equations) holds nu fixed:
``k nu (I / d^3 - 3 d d^T / d^5)``, ``d = r - r_s``; the change of nu with r (only in the
penumbra, a few seconds per eclipse) is left out.

Units: km, rad, km/s^2.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ssa_fusion.core.base.jit import jit

__all__ = ["shadow_fraction", "shadow_fractions"]


@jit
def shadow_fraction(x: float, y: float, z: float, sx: float, sy: float, sz: float,
                    r_sun: float, r_body: float) -> float:
    """Fraction (0..1) of the Sun's disc seen from (x, y, z) km past a sphere at the origin.

    ``(sx, sy, sz)`` the Sun's position km, ``r_sun`` its radius km, ``r_body`` the
    occulting sphere's radius km (module docstring).
    """
    dx, dy, dz = sx - x, sy - y, sz - z
    ds = math.sqrt(dx * dx + dy * dy + dz * dz)
    r = math.sqrt(x * x + y * y + z * z)
    if r <= r_body:
        return 0.0
    a = math.asin(min(1.0, r_sun / ds))
    b = math.asin(r_body / r)
    cosc = -(x * dx + y * dy + z * dz) / (r * ds)
    c = math.acos(min(1.0, max(-1.0, cosc)))
    if c >= a + b:
        return 1.0
    if c <= b - a:
        return 0.0
    if c < a - b:
        return 1.0 - b * b / (a * a)
    xx = (c * c + a * a - b * b) / (2.0 * c)
    yy = math.sqrt(max(a * a - xx * xx, 0.0))
    area = (a * a * math.acos(min(1.0, max(-1.0, xx / a)))
            + b * b * math.acos(min(1.0, max(-1.0, (c - xx) / b))) - c * yy)
    return 1.0 - area / (math.pi * a * a)


def shadow_fractions(r_km: ArrayLike, r_sun_km: ArrayLike, sun_radius_km: float,
                     body_radius_km: float) -> NDArray[np.float64]:
    """`shadow_fraction` of positions (..., 3) with the Sun at (..., 3) (broadcast), km."""
    r = np.asarray(r_km, dtype=float)
    s = np.asarray(r_sun_km, dtype=float)
    shape = np.broadcast_shapes(r.shape, s.shape)
    rb = np.broadcast_to(r, shape).reshape(-1, 3)
    sb = np.broadcast_to(s, shape).reshape(-1, 3)
    out = np.array([shadow_fraction(p[0], p[1], p[2], q[0], q[1], q[2], sun_radius_km,
                                    body_radius_km)
                    for p, q in zip(rb.tolist(), sb.tolist(), strict=True)])
    return out.reshape(shape[:-1])

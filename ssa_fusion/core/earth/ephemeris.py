"""The Sun and the Moon from the JPL ephemeris DE421, for compiled code: `sun_moon_span`.

DE421 (Folkner, Williams & Boggs 2009, JPL IPN Progress Report 42-178; 1900-2050) as the
``de421`` package distributes it (MIT; the JPL's Chebyshev series as numpy arrays, read by
``jplephem.ephem``): the Sun's and the Earth-Moon barycentre's positions about the solar
system barycentre and the Moon's about the Earth, each a Chebyshev series in time per
interval (the Sun and the barycentre 16 days, the Moon 4 days), in the ICRF axes (the GCRF's).
Geocentric::

    moon = M,   sun = S - B + M / (1 + EMRAT)

(``S``, ``B`` the Sun and the barycentre about the solar system barycentre, ``M`` the
Moon about the Earth, EMRAT the Earth/Moon mass ratio).

`sun_moon_span` takes the intervals that cover a span of epochs once and re-bases their
times on the span's origin; `body_position`, compiled, evaluates one series at a time
(Clenshaw's recurrence) and `sun_moon_position` the two bodies, so a force model's kernel
evaluates the JPL ephemeris itself at every step with no Python call (~0.3 us).

Time: the series' argument is TDB; the origin's TDB is its TT plus `erfa.dtdb` there, and
TDB - TT is continued linearly from there with its rate over the next day (the rate is up to
3.3e-10: 28 us a day, 3 cm of the Moon's motion, if it were left out; the curvature left
is ~2 us over three days, 2 mm of the Moon). The gravitational parameters are DE421's:
GM_sun = GMS and GM_moon = GMB / (1 + EMRAT), converted with its AU to km^3/s^2.

Units: km, s; GCRF; epochs Unix s UTC.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass
from typing import Any

import erfa
import numpy as np
from numpy.typing import ArrayLike, NDArray

from ssa_fusion.core.base.jit import f64, jit
from ssa_fusion.core.earth.timescales import jd_tt

__all__ = [
    "SunMoonSpan",
    "body_position",
    "sun_moon_position",
    "sun_moon_positions",
    "sun_moon_span",
]

Array = NDArray[np.float64]

DAY_S = 86400.0

_BODIES = ("sun", "earthmoon", "moon")
"""The series of `SunMoonSpan.coefficients`, in this order."""


@dataclass(frozen=True)
class SunMoonSpan:
    """DE421's series of the Sun, the Earth-Moon barycentre and the Moon over a span.

    Attributes
    ----------
    t0_unix : float
        The origin, Unix s UTC: the series' times are seconds from it.
    coefficients : tuple of 3 ndarrays (K_i, 3, C_i)
        Chebyshev coefficients (km) per interval of the Sun, barycentre and Moon.
    starts : ndarray (3,)
        Start of each series' first interval, s from the origin (TDB).
    lengths : ndarray (3,)
        Interval length of each series, s.
    earth_share : float
        1 / (1 + EMRAT).
    gm_sun, gm_moon : float
        km^3/s^2.
    """

    t0_unix: float
    coefficients: tuple[Array, Array, Array]
    starts: Array
    lengths: Array
    earth_share: float
    gm_sun: float
    gm_moon: float


@functools.cache
def _ephemeris() -> Any:  # noqa: ANN401 (jplephem's untyped class)
    """DE421 as ``jplephem.ephem.Ephemeris`` of the ``de421`` package (loaded once)."""
    import de421
    from jplephem.ephem import Ephemeris

    return Ephemeris(de421)


def sun_moon_span(t0_unix: float, t_min_s: float, t_max_s: float) -> SunMoonSpan:
    """Return the series that cover ``t0_unix + [t_min_s, t_max_s]``, timed from ``t0_unix``.

    Parameters
    ----------
    t0_unix : float
        Origin, Unix s UTC.
    t_min_s, t_max_s : float
        The span, s from the origin (t_min_s <= t_max_s).

    Returns
    -------
    SunMoonSpan
    """
    eph = _ephemeris()
    jd1, jd2 = jd_tt(np.array([float(t0_unix), float(t0_unix) + DAY_S]))
    tdb_tt = erfa.dtdb(jd1, jd2, 0.0, 0.0, 0.0, 0.0)
    rate = float(tdb_tt[1] - tdb_tt[0]) / DAY_S  # d(TDB - TT)/dt, |rate| < 3.3e-10
    # origin relative to the ephemeris' start, in days, two parts kept apart
    org_days = (float(jd1[0]) - float(eph.jalpha)) + float(jd2[0]) + float(tdb_tt[0]) / DAY_S
    coefs, starts, lengths = [], [], []
    for name in _BODIES:
        sets = eph.load(name)
        per = (float(eph.jomega) - float(eph.jalpha)) / sets.shape[0]
        lo = math.floor((org_days + t_min_s / DAY_S) / per) - 1
        hi = math.floor((org_days + t_max_s / DAY_S) / per) + 1
        lo, hi = max(lo, 0), min(hi, sets.shape[0] - 1)
        if lo > hi or org_days + t_min_s / DAY_S < 0.0 or \
                org_days + t_max_s / DAY_S > sets.shape[0] * per:
            raise ValueError(f"DE421 covers JD {eph.jalpha}..{eph.jomega}: span outside it")
        coefs.append(f64(np.ascontiguousarray(sets[lo:hi + 1], dtype=float)))
        # TDB seconds from the origin are (1 + rate) t: the series read in t instead
        starts.append((lo * per - org_days) * DAY_S / (1.0 + rate))
        lengths.append(per * DAY_S / (1.0 + rate))
    au = float(eph.AU)
    k = au ** 3 / DAY_S ** 2
    return SunMoonSpan(float(t0_unix), (coefs[0], coefs[1], coefs[2]), np.array(starts),
                       np.array(lengths), float(eph.earth_share), float(eph.GMS) * k,
                       float(eph.GMB) / (1.0 + float(eph.EMRAT)) * k)


@jit
def body_position(coef: Array, start: float, length: float,
                  t: float) -> tuple[float, float, float]:
    """Position (km) of one series (`SunMoonSpan.coefficients`) at ``t`` s from the origin.

    The interval is clamped to the series' first and last (a time outside the span is
    extrapolated by them).
    """
    k = math.floor((t - start) / length)
    k = min(max(k, 0), coef.shape[0] - 1)
    s = 2.0 * (t - start - k * length) / length - 1.0
    out = [0.0, 0.0, 0.0]
    nc = coef.shape[2]
    for i in range(3):
        b1 = b2 = 0.0
        for j in range(nc - 1, 0, -1):
            b1, b2 = 2.0 * s * b1 - b2 + coef[k, i, j], b1
        out[i] = s * b1 - b2 + coef[k, i, 0]
    return out[0], out[1], out[2]


@jit
def sun_moon_position(sun: Array, emb: Array, moon: Array, starts: Array, lengths: Array,
                      earth_share: float, t: float, out: Array) -> None:
    """Geocentric GCRF Sun (``out[0:3]``) and Moon (``out[3:6]``), km, at ``t`` s (module doc)."""
    sx, sy, sz = body_position(sun, starts[0], lengths[0], t)
    bx, by, bz = body_position(emb, starts[1], lengths[1], t)
    mx, my, mz = body_position(moon, starts[2], lengths[2], t)
    out[0] = sx - bx + earth_share * mx
    out[1] = sy - by + earth_share * my
    out[2] = sz - bz + earth_share * mz
    out[3], out[4], out[5] = mx, my, mz


def sun_moon_positions(t_unix: ArrayLike) -> tuple[Array, Array]:
    """Return the geocentric GCRF Sun and Moon (..., 3) km at Unix (UTC) epochs (DE421)."""
    t = np.asarray(t_unix, dtype=float)
    flat = t.ravel()
    if not flat.size:
        return np.zeros((*t.shape, 3)), np.zeros((*t.shape, 3))
    t0 = float(flat[0])
    span = sun_moon_span(t0, float(flat.min() - t0), float(flat.max() - t0))
    out = np.empty(6)
    sun, moon = np.empty((flat.size, 3)), np.empty((flat.size, 3))
    for i, ti in enumerate(flat - t0):
        sun_moon_position(*span.coefficients, span.starts, span.lengths, span.earth_share,
                          float(ti), out)
        sun[i], moon[i] = out[:3], out[3:]
    return sun.reshape(*t.shape, 3), moon.reshape(*t.shape, 3)

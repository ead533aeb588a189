"""Solar and geomagnetic activity of the simulated world: F10.7 and ap, as NRLMSISE-00 reads them.

The air density above 200 km follows the Sun's extreme-ultraviolet output (its proxy, the
10.7 cm radio flux F10.7, solar flux units) and geomagnetic storms (the 3-hourly ap index).
`SpaceWeather` holds a span of them; `msis_inputs` returns, per epoch, what NRLMSISE-00
takes (Picone et al. 2002): the previous day's F10.7, its 81-day mean, and the ap array
(daily Ap; ap now, 3, 6, 9 h before; the mean of the eight 3-hourly values 12-33 h before,
and 36-57 h before).

`synthetic_weather` draws a span from a seed: F10.7 about a level (the Sun's 27-day
rotation, day-to-day noise), a quiet ap background (log-normal, median 7) and storms at
random (on average one every `STORM_EVERY_DAYS` days: ap jumps to 50-200 and decays with
a 9 h e-folding). What a catalog running a cheap atmosphere cannot know in advance:
the storms' epochs and sizes.

Units: sfu (1e-22 W m^-2 Hz^-1) for F10.7; ap in its own 2 nT units; times Unix s UTC.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = ["STORM_EVERY_DAYS", "SpaceWeather", "synthetic_weather"]

Array = NDArray[np.float64]

DAY_S = 86400.0
STEP_S = 10800.0
"""ap is 3-hourly."""
LEAD_DAYS = 3
"""Days of activity before a span's first epoch (ap's means reach 57 h back)."""
STORM_EVERY_DAYS = 9.0
"""Mean days between storms of the synthetic activity (a Poisson process)."""
STORM_DECAY_H = 9.0
"""e-folding time of a storm's ap, h."""
QUIET_AP = 7.0
"""Median of the quiet ap background."""


@dataclass(frozen=True)
class SpaceWeather:
    """Daily F10.7, its 81-day mean and 3-hourly ap from 00:00 UTC of ``day0_unix``.

    Attributes
    ----------
    day0_unix : float
        00:00 UTC of the first day, Unix s.
    f107 : ndarray (D,)
        Each day's F10.7, sfu.
    f107a : ndarray (D,)
        The 81-day mean of F10.7 centred on each day, sfu.
    ap : ndarray (8 D,)
        The 3-hourly ap from ``day0_unix``.
    """

    day0_unix: float
    f107: Array
    f107a: Array
    ap: Array

    def msis_inputs(self, t_unix: ArrayLike) -> tuple[Array, Array, Array]:
        """Return NRLMSISE-00's (F10.7 of the day before, 81-day mean, ap (n, 7)) at ``t_unix``.

        ValueError when an epoch needs activity outside the span (57 h before to its end).
        """
        t = np.atleast_1d(np.asarray(t_unix, dtype=float))
        day = np.floor((t - self.day0_unix) / DAY_S).astype(int)
        k = np.floor((t - self.day0_unix) / STEP_S).astype(int)
        if (k - 19).min(initial=0) < 0 or day.max(initial=0) >= len(self.f107) \
                or k.max(initial=0) >= len(self.ap) or (day - 1).min(initial=0) < 0:
            raise ValueError("epochs outside the space weather's span")
        ap = np.empty((t.size, 7))
        daily = self.ap.reshape(-1, 8).mean(axis=1)
        ap[:, 0] = daily[day]
        for j in range(4):
            ap[:, 1 + j] = self.ap[k - j]
        ap[:, 5] = np.mean([self.ap[k - 4 - j] for j in range(8)], axis=0)
        ap[:, 6] = np.mean([self.ap[k - 12 - j] for j in range(8)], axis=0)
        return self.f107[day - 1], self.f107a[day], ap

    def covers(self, t0_unix: float, t1_unix: float) -> bool:
        """Whether activity is given for every epoch from ``t0_unix`` to ``t1_unix``."""
        return (t0_unix - self.day0_unix >= LEAD_DAYS * DAY_S
                and t1_unix < self.day0_unix + len(self.f107) * DAY_S)


def synthetic_weather(t0_unix: float, t1_unix: float, seed: int,
                      f107_level: float = 150.0,
                      storm_every_days: float = STORM_EVERY_DAYS) -> SpaceWeather:
    """Return activity drawn from ``seed`` covering ``t0_unix`` .. ``t1_unix`` (module docstring).

    F10.7 = level + 20 sin(2 pi d / 27 + phase) + an AR(1) day-to-day term (sigma 6 sfu),
    at least 65 sfu; its 81-day mean the level (the rotation and the noise average out over
    three rotations); ap: the quiet background (log-normal about `QUIET_AP`, sigma 0.5 in
    its log) plus storms, a Poisson process of rate 1 / ``storm_every_days`` per day, each
    a jump to 50-200 decaying with `STORM_DECAY_H` (0: no storm).
    """
    rng = np.random.default_rng([seed, 4217])
    day0 = DAY_S * (math.floor(t0_unix / DAY_S) - LEAD_DAYS)
    days = math.ceil((t1_unix - day0) / DAY_S) + 1
    d = np.arange(days, dtype=float)
    noise = np.zeros(days)
    for i in range(1, days):
        noise[i] = 0.7 * noise[i - 1] + rng.normal(0.0, 6.0 * math.sqrt(1 - 0.49))
    f107 = np.maximum(65.0, f107_level + 20.0 * np.sin(2 * math.pi * d / 27.0
                                                        + rng.uniform(0, 2 * math.pi)) + noise)
    f107a = np.full(days, float(f107_level))
    n = 8 * days
    ap = QUIET_AP * np.exp(rng.normal(0.0, 0.5, n))
    if storm_every_days > 0:
        count = rng.poisson(days / storm_every_days)
        hours = np.arange(n) * STEP_S / 3600.0
        for start, peak in zip(rng.uniform(0, 24.0 * days, count),
                               rng.uniform(50.0, 200.0, count), strict=True):
            after = hours - start
            ap += np.where(after >= 0, peak * np.exp(-np.maximum(after, 0) / STORM_DECAY_H), 0.0)
    return SpaceWeather(day0, f107, f107a, np.minimum(ap, 400.0))

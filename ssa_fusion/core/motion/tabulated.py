"""An orbit given as a table of positions (a CPF, an ephemeris), interpolated.

`TabulatedOrbit` holds epochs and positions (and optionally velocities) in one frame and
gives the state at any epoch inside the table by Lagrange interpolation over the `degree`
+ 1 nodes around it (scipy's `BarycentricInterpolator`, on the epochs scaled to the step):
the position by the polynomial, the velocity by its derivative, or by the same
interpolation of the tabulated velocities when the table has them. Degree 9 over 5-minute
nodes (the ILRS's advice for CPF) reproduces a LAGEOS orbit to well under a millimetre.

The frame is the table's own: an ITRF table gives ITRF states (`frames.itrs_to_gcrs` turns
them to the GCRF). Units: km, km/s, Unix s.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.interpolate import BarycentricInterpolator

Array = NDArray[np.float64]

DEGREE = 9
"""Degree of the interpolating polynomials (10 nodes)."""


@dataclass(frozen=True)
class TabulatedOrbit:
    """A table of epochs (n,) (Unix s, increasing), positions (n, 3) km, velocities or None."""

    t: Array
    position_km: Array
    velocity_km_s: Array | None = None
    degree: int = DEGREE

    def __post_init__(self) -> None:
        """Check the table: increasing epochs, one position each, enough nodes."""
        if len(self.t) < self.degree + 1:
            raise ValueError(f"a table of {len(self.t)} epochs: degree {self.degree} "
                             f"interpolation needs {self.degree + 1}")
        if np.any(np.diff(self.t) <= 0):
            raise ValueError("the table's epochs do not increase")
        if self.position_km.shape != (len(self.t), 3):
            raise ValueError(f"positions of shape {self.position_km.shape}, want "
                             f"({len(self.t)}, 3)")

    def covers(self, t: ArrayLike) -> NDArray[np.bool_]:
        """Return where epochs `t` lie within the table's span."""
        q = np.asarray(t, dtype=float)
        out: NDArray[np.bool_] = (q >= self.t[0]) & (q <= self.t[-1])
        return out

    def states(self, t: ArrayLike) -> Array:
        """Return the states (..., 6) (km, km/s) at epochs `t` (ValueError outside the table)."""
        q = np.asarray(t, dtype=float)
        flat = q.ravel()
        if not self.covers(flat).all():
            raise ValueError(f"epochs outside the table's span {self.t[0]:.3f} .. "
                             f"{self.t[-1]:.3f} s")
        k = self.degree + 1
        i0 = np.clip(np.searchsorted(self.t, flat) - k // 2, 0, len(self.t) - k)
        out = np.empty((len(flat), 6))
        for start in np.unique(i0):
            mine = i0 == start
            nodes = slice(int(start), int(start) + k)
            t0, step = self.t[start], self.t[start + 1] - self.t[start]
            x = (self.t[nodes] - t0) / step
            xq = (flat[mine] - t0) / step
            p = BarycentricInterpolator(x, self.position_km[nodes], axis=0)
            out[mine, :3] = p(xq)
            if self.velocity_km_s is None:
                out[mine, 3:] = p.derivative(xq) / step
            else:
                out[mine, 3:] = BarycentricInterpolator(
                    x, self.velocity_km_s[nodes], axis=0)(xq)
        return out.reshape(*q.shape, 6)

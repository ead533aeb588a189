"""Scores of laser-ranging orbit determination without a truth of one's own.

What a laser-ranging analyst looks at (`ssa-fusion report` on a bag of `import crd`):

* `pass_rows`: per station and pass (ranges no more than `PASS_BREAK_S` apart: a LAGEOS
  pass lasts 30-60 min, its normal points minutes apart), the fit's residuals: count, span,
  mean and RMS (cm);
* `nis_coverage`: the filter's NIS of each fused range against the two-sided 95 % band of
  chi-square(1);
* `against_reference`: an orbit's difference from an independent one (a CPF, an OEM) in the
  reference's radial, along-track and cross-track axes (m): at the reference's epochs, or
  at the orbit's own epochs inside the reference's span (the reference interpolated:
  `tabulated.TabulatedOrbit`).

Units: inputs in the core's (km, s); the scores in cm (residuals) and m (orbits).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ssa_fusion.core.base.metrics import chi2_bounds
from ssa_fusion.core.base.types import Measurement
from ssa_fusion.core.earth.frames import rtn_axes
from ssa_fusion.core.measure.pass_windows import passes
from ssa_fusion.core.motion.tabulated import TabulatedOrbit

__all__ = ["PASS_BREAK_S", "NisCoverage", "OrbitDifference", "PassRow", "against_reference",
           "nis_coverage", "pass_rows"]

Array = NDArray[np.float64]

PASS_BREAK_S = 1800.0
"""Ranges of one station further apart than this (s) are of different passes."""
CM_PER_KM = 1e5
M_PER_KM = 1e3


@dataclass(frozen=True)
class PassRow:
    """One station's pass: its ranges' residuals (cm)."""

    station: str
    first: float
    last: float
    count: int
    mean_cm: float
    rms_cm: float


@dataclass(frozen=True)
class NisCoverage:
    """The NIS of the fused ranges against the 95 % band of chi-square(1)."""

    count: int
    inside: float
    below: int
    above: int
    mean: float
    band: tuple[float, float]


@dataclass(frozen=True)
class OrbitDifference:
    """An orbit minus a reference at ``count`` epochs: RMS in R, T, N, 3D; largest 3D (m)."""

    count: int
    rtn_rms_m: tuple[float, float, float]
    rms_3d_m: float
    max_3d_m: float


def pass_rows(measurements: Sequence[Measurement], residuals_km: ArrayLike,
              gap_s: float = PASS_BREAK_S) -> list[PassRow]:
    """Return the passes of every station (in time order) with their residuals' mean and RMS."""
    res = np.asarray(residuals_km, dtype=float).reshape(-1)
    rows = []
    for sid in dict.fromkeys(m.frame_id for m in measurements):
        idx = [i for i, m in enumerate(measurements) if m.frame_id == sid]
        mine = [measurements[i] for i in idx]
        for a, b in passes(mine, gap_s):
            r = res[[idx[k] for k in range(a, b + 1)]]
            rows.append(PassRow(sid, mine[a].t, mine[b].t, b - a + 1,
                                float(r.mean()) * CM_PER_KM,
                                float(np.sqrt(np.mean(r * r))) * CM_PER_KM))
    return sorted(rows, key=lambda p: p.first)


def nis_coverage(nis: ArrayLike) -> NisCoverage:
    """Return the NIS values' coverage of the two-sided 95 % band of chi-square(1)."""
    v = np.asarray(nis, dtype=float).reshape(-1)
    lo, hi = chi2_bounds(1)
    inside = float(np.mean((v >= lo) & (v <= hi))) if v.size else float("nan")
    return NisCoverage(int(v.size), inside, int(np.sum(v < lo)), int(np.sum(v > hi)),
                       float(v.mean()) if v.size else float("nan"), (lo, hi))


def against_reference(t: ArrayLike, x: ArrayLike, t_ref: ArrayLike,
                      x_ref: ArrayLike) -> OrbitDifference:
    """Return the orbit ``x`` (K, 6) at epochs ``t`` minus the reference (RTN of the reference).

    Epochs outside the reference's span are left out; the reference (GCRF km, km/s at
    ``t_ref``) is interpolated at the others.
    """
    tt = np.asarray(t, dtype=float)
    xx = np.asarray(x, dtype=float).reshape(-1, 6)
    ref = TabulatedOrbit(np.asarray(t_ref, dtype=float), np.asarray(x_ref, dtype=float)[:, :3])
    keep = ref.covers(tt)
    if not keep.any():
        nan = float("nan")
        return OrbitDifference(0, (nan, nan, nan), nan, nan)
    xr = ref.states(tt[keep])
    d = np.einsum("kij,kj->ki", rtn_axes(xr), xx[keep, :3] - xr[:, :3]) * M_PER_KM
    n3 = np.linalg.norm(d, axis=1)
    rms = np.sqrt(np.mean(d * d, axis=0))
    return OrbitDifference(int(keep.sum()), (float(rms[0]), float(rms[1]), float(rms[2])),
                           float(np.sqrt(np.mean(n3 * n3))), float(n3.max()))

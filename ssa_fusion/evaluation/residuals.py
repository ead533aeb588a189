"""Residuals, NIS and passes of a filter run on measurements without a truth (your own data).

What an orbit-determination engineer checks when there is nothing to compare against:

* `residuals`: per fused real measurement, its pre-fit residual (innovation) y = z - h(x⁻):
  the measurement minus the filter's predicted measurement *before* the update, x⁻ being the
  filter's previous fused estimate predicted to the measurement's epoch with the filter's own
  motion model and process noise (`Tracker.predict_from`), h the station's measurement model
  of the run's settings. With it S = H P⁻ Hᵀ + R, the innovation covariance, and the NIS
  yᵀ S⁻¹ y, which must reproduce the NIS the filter published (`Residual.nis_filter`).
* `published_nis`, `nis_summary`: the NIS the filter published with each fused real
  measurement against the two-sided 95 % χ² band of the measurement's dimension.
* `pass_rows`: per station pass (measurements no more than `PASS_BREAK_S` apart): its span,
  measurements fused and not, the largest elevation (a radar's measured one), and the RMS of
  the residuals normalised by their innovation σ (√diag S): near 1 for a consistent filter.
* `position_sigma`: the 1-σ position uncertainty √trace(P_rr) (km) of estimates;
  `gaps`: the spans between passes of the whole network.

Units: the core's (km, km/s, rad, s); times are Unix seconds (UTC).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from ssa_fusion.core.base.metrics import chi2_bounds
from ssa_fusion.core.base.types import Kind, Measurement, Source, StateEstimate, UpdateSource
from ssa_fusion.core.earth.frames import wrap_angle
from ssa_fusion.core.gaps.estimator import EstimatorConfig, make_tracker
from ssa_fusion.core.measure.laser_model import LaserModels
from ssa_fusion.core.measure.measurement import StationModels
from ssa_fusion.core.measure.pass_windows import PASS_BREAK_S, passes
from ssa_fusion.core.measure.validation import OK, measurement_problem

__all__ = [
    "PASS_BREAK_S",
    "Nis",
    "NisSummary",
    "PassRow",
    "Residual",
    "gaps",
    "nis_summary",
    "pass_rows",
    "position_sigma",
    "published_nis",
    "residuals",
]


@dataclass
class Residual:
    """The pre-fit residual of one fused real measurement (core units: km, rad)."""

    t: float
    station: str
    kind: int
    y: np.ndarray
    """z - h(x⁻) per channel, angles wrapped to (-π, π]."""
    sigma: np.ndarray
    """√diag S: the innovation's 1-σ per channel (prior covariance and R)."""
    sigma_r: np.ndarray
    """√diag R: the measurement's own 1-σ per channel."""
    nis: float
    """yᵀ S⁻¹ y recomputed here."""
    nis_filter: float
    """The NIS the filter published with the estimate of this measurement."""

    @property
    def normalised(self) -> np.ndarray:
        """Return y / σ per channel (dimensionless)."""
        return np.asarray(self.y / self.sigma)


def _angle_mask(model: object, m: int) -> tuple[bool, ...]:
    mask = getattr(model, "angle_mask", None)
    return tuple(mask) if mask is not None else (False,) * m


def residuals(c: EstimatorConfig, estimates: Sequence[StateEstimate],
              measurements: Sequence[Measurement]) -> list[Residual]:
    """Return the pre-fit residual of every real measurement the filter fused (module doc).

    `estimates`: what the filter published (any order; predictions, update source NONE, are
    ignored); `measurements`: the real ones it was given. A measurement counts as fused when
    an estimate of update source SENSOR has its epoch; the first estimate of a track (NIS 0:
    the initial orbit determination) has no prior and no residual; nor has a measurement of a
    station the settings `c` do not know.
    """
    tracker = make_tracker(c)
    model = tracker.model
    fused = sorted((e for e in estimates if e.update_source != UpdateSource.NONE),
                   key=lambda e: e.t)
    t_fused = np.array([e.t for e in fused])
    out = []
    for m in sorted((m for m in measurements if m.source == Source.SENSOR), key=lambda m: m.t):
        k = int(np.searchsorted(t_fused, m.t))
        if k >= len(fused) or fused[k].t != m.t or k == 0:
            continue
        e = fused[k]
        if e.update_source != UpdateSource.SENSOR or not e.nis > 0.0:
            continue  # the initial orbit determination: no innovation
        if measurement_problem(m, tracker.kind, tracker.frame_id) != OK:
            continue  # a kind or a station the settings do not take
        one = model.get(m.kind, m.frame_id) if isinstance(model, StationModels) else model
        if isinstance(one, LaserModels):
            continue  # the published orbit holds no range biases: `laser_report`'s
        if one is None:
            continue
        prior = tracker.predict_from(fused[k - 1], m.t)
        zp, H = one.h_and_H(prior.x, m.t)
        y = np.asarray(m.z, dtype=float) - zp
        for i, angle in enumerate(_angle_mask(one, len(y))):
            if angle:
                y[i] = wrap_angle(float(y[i]))
        S = H @ prior.P @ H.T + m.R
        nis = float(y @ np.linalg.solve(S, y))
        out.append(Residual(m.t, m.frame_id, int(m.kind), y, np.sqrt(np.diag(S)),
                            np.sqrt(np.diag(m.R)), nis, float(e.nis)))
    return out


@dataclass
class Nis:
    """The NIS the filter published with the estimate of one fused real measurement."""

    t: float
    station: str
    dof: int
    """The measurement's dimension."""
    nis: float


def published_nis(estimates: Sequence[StateEstimate],
                  measurements: Sequence[Measurement]) -> list[Nis]:
    """Return the published NIS of every real measurement the filter fused, in epoch order.

    Fused: an estimate of update source SENSOR at its epoch, with a NIS (not 0: the initial
    orbit determination has no innovation). Needs no station position: the filter's own
    number.
    """
    nis = {e.t: e.nis for e in estimates
           if e.update_source == UpdateSource.SENSOR and e.nis > 0.0}
    return [Nis(m.t, m.frame_id, len(m.z), nis[m.t])
            for m in sorted(measurements, key=lambda m: m.t)
            if m.source == Source.SENSOR and m.t in nis]


@dataclass
class NisSummary:
    """The filter's NIS of its fused real measurements against the 95 % χ² band."""

    n: int
    inside: int
    band: dict[int, tuple[float, float]]
    """Per measurement dimension (the χ² dof), the two-sided 95 % band."""

    @property
    def fraction(self) -> float:
        """Fraction inside the band (NaN without any)."""
        return self.inside / self.n if self.n else math.nan


def nis_summary(values: Sequence[Nis], alpha: float = 0.05) -> NisSummary:
    """Count the NIS `values` inside the 95 % χ² band of their dimension.

    Two-sided, (1 - alpha), per measurement dimension (`metrics.chi2_bounds`,
    scipy.stats.chi2).
    """
    band: dict[int, tuple[float, float]] = {}
    inside = 0
    for v in values:
        lo, hi = band.setdefault(v.dof, chi2_bounds(v.dof, alpha=alpha))
        inside += int(lo <= v.nis <= hi)
    return NisSummary(len(values), inside, band)


@dataclass
class PassRow:
    """One pass of one station."""

    station: str
    t_start: float
    t_end: float
    fused: int
    """Real measurements the filter fused (an estimate of update source SENSOR at the epoch,
    the initial orbit determination's included)."""
    not_fused: int
    """The others: refused by the filter, or buffered for its initial orbit determination."""
    max_elevation_deg: float
    """The largest measured elevation (a radar's), NaN when the kind has none."""
    rms_normalised: float
    """RMS over the pass's residuals and channels of y/σ (NaN without residuals)."""
    residuals: int


def pass_rows(measurements: Sequence[Measurement], fused_epochs: Sequence[float],
              res: Sequence[Residual], gap_s: float = PASS_BREAK_S) -> list[PassRow]:
    """Return the passes of each station's real `measurements` (`PassRow`), in start order.

    A pass: the station's measurements no two consecutive more than `gap_s` apart.
    `fused_epochs`: the epochs of the filter's SENSOR estimates; `res`: the residuals
    (`residuals`).
    """
    fused = set(fused_epochs)
    by_station: dict[str, list[Measurement]] = {}
    for m in measurements:
        if m.source == Source.SENSOR:
            by_station.setdefault(m.frame_id, []).append(m)
    res_at = {(r.station, r.t): r for r in res}
    rows = []
    for station, ms in by_station.items():
        ms.sort(key=lambda m: m.t)
        for first, last in passes(ms, gap_s):
            p = ms[first:last + 1]
            n_fused = sum(m.t in fused for m in p)
            el = [float(m.z[2]) for m in p if m.kind == Kind.RANGE_AZ_EL]
            mine = [res_at[(station, m.t)] for m in p if (station, m.t) in res_at]
            norm = np.concatenate([r.normalised for r in mine]) if mine else np.zeros(0)
            rows.append(PassRow(station, p[0].t, p[-1].t, n_fused, len(p) - n_fused,
                                math.degrees(max(el)) if el else math.nan,
                                float(np.sqrt(np.mean(norm ** 2))) if len(norm) else math.nan,
                                len(mine)))
    return sorted(rows, key=lambda r: (r.t_start, r.station))


def gaps(measurements: Sequence[Measurement], gap_s: float = PASS_BREAK_S
         ) -> list[tuple[float, float]]:
    """Return the spans (start, end; s) between the passes of all stations together.

    Where consecutive real measurements of the network are more than `gap_s` apart.
    """
    t = np.sort(np.array([m.t for m in measurements if m.source == Source.SENSOR]))
    k = np.flatnonzero(np.diff(t) > gap_s)
    return [(float(t[i]), float(t[i + 1])) for i in k]


def position_sigma(estimates: Sequence[StateEstimate]) -> tuple[np.ndarray, np.ndarray]:
    """Return (epochs s, 1-σ position km) of `estimates`, in epoch order.

    The 1-σ is √trace(P_rr): the root-sum-square of the three position σ (at least the
    largest eigenvalue's σ, at most √3 times it).
    """
    es = sorted(estimates, key=lambda e: e.t)
    t = np.array([e.t for e in es])
    sig = np.array([math.sqrt(max(float(np.trace(e.P[:3, :3])), 0.0)) for e in es])
    return t, sig

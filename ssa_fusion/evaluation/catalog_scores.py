"""Per-object scores of a catalog run: many objects' rows, never mixed, without a row loop.

A catalog bag holds the rows of thousands of objects (a 30,000-object day: tens of millions
of measurement and estimate rows). Every object (or, for unlabelled detections, every
track) is scored on its own rows only, with numpy grouping over integer object codes
(`Codes`) and exact (object, epoch) matches (`Matcher`):

* `truth_errors`: per estimate row, its position error ‖r̂ − r‖ (km) against the truth of
  its object at the same epoch, and its NEES (x̂ − x)ᵀ P⁻¹ (x̂ − x) (6 dof) where its
  covariance is positive definite; NaN where the truth has no row at that epoch;
* `postfit_residuals`: per range/azimuth/elevation measurement of an object, z − h(x̂), x̂
  the same object's fused (SENSOR) estimate at the measurement's epoch (the last one, after
  every measurement of that epoch), h the station's measurement model
  (`batch_ekf.BatchEKF.measure`); azimuth wrapped to (−π, π]; in units of the measurement's
  own σ (√diag R). Post-fit: a consistent filter gives an RMS somewhat below 1; another
  object's measurements give thousands;
* `object_scores`: per object, counts, error median and 95th percentile (linear
  interpolation, as `numpy.percentile`), NEES and the filter's published NIS against their
  two-sided 95 % χ² bands, residual RMS per channel; `summary` over all objects and
  `worst` objects.

Units: the core's (km, km/s, rad, s); epochs Unix s (UTC).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ssa_fusion.core.base.metrics import chi2_bounds
from ssa_fusion.core.catalog.batch_ekf import BatchEKF

Floats = NDArray[np.float64]
Ints = NDArray[np.int64]

STATE_DOF = 6
"""The dimension of a state (the NEES's χ² dof)."""
RAZEL_DOF = 3
"""The dimension of a range/az/el measurement (the NIS's χ² dof)."""
AZIMUTH = 1
"""The channel of a range/az/el measurement that wraps at 2π."""
CHUNK = 1_000_000
"""Rows through the measurement model at once (bounds its temporary (rows, 3, 3) arrays)."""


class Codes:
    """Object (or track) ids as integer codes 0, 1, ... in order of first sight."""

    def __init__(self) -> None:
        self.ids: list[str] = []
        self._code: dict[str, int] = {}

    def __len__(self) -> int:
        """Return how many ids have a code."""
        return len(self.ids)

    def code(self, object_id: str) -> int:
        """Return the code of `object_id` (a new one for an id not seen before)."""
        c = self._code.get(object_id)
        if c is None:
            c = self._code[object_id] = len(self.ids)
            self.ids.append(object_id)
        return c

    def encode(self, object_ids: Sequence[str]) -> Ints:
        """Return the codes of `object_ids`: one dictionary look-up per distinct id."""
        if not len(object_ids):
            return np.zeros(0, np.int64)
        uniq, inv = np.unique(np.asarray(object_ids, dtype=str), return_inverse=True)
        return np.array([self.code(str(u)) for u in uniq], np.int64)[inv.reshape(-1)]

    def find(self, object_id: str) -> int:
        """Return the code of `object_id`, or -1 for an id without one."""
        return self._code.get(object_id, -1)


class Matcher:
    """Exact (object code, epoch) look-up into reference rows (the last row of a pair wins).

    The reference epochs are ranked among their distinct values, so that (code, rank) is
    one int64 key; a query epoch that no reference row has finds nothing.
    """

    def __init__(self, code: Ints, t: Floats) -> None:
        self.epochs = np.unique(t)
        rank = np.searchsorted(self.epochs, t)
        key = code.astype(np.int64) * max(len(self.epochs), 1) + rank
        self.order = np.argsort(key, kind="stable")
        self.keys = key[self.order]

    def find(self, code: Ints, t: Floats) -> Ints:
        """Return per query row the index of its reference row, -1 where there is none."""
        out = np.full(len(t), -1, np.int64)
        if not len(self.keys) or not len(t):
            return out
        rank = np.minimum(np.searchsorted(self.epochs, t), len(self.epochs) - 1)
        ok = (self.epochs[rank] == t) & (code >= 0)
        key = code.astype(np.int64) * len(self.epochs) + rank
        at = np.searchsorted(self.keys, key, side="right") - 1
        ok &= at >= 0
        ok[ok] &= self.keys[at[ok]] == key[ok]
        out[ok] = self.order[at[ok]]
        return out


def nees(err: Floats, P: Floats) -> Floats:
    """Return eᵀ P⁻¹ e per row of `err` (M, 6) and `P` (M, 6, 6).

    NaN where P is not positive definite (a zero covariance: no covariance published).
    """
    out = np.full(len(err), np.nan)
    if not len(err):
        return out
    w, V = np.linalg.eigh(0.5 * (P + np.swapaxes(P, 1, 2)))
    ok = np.all(w > 0.0, axis=1) & np.all(np.isfinite(err), axis=1)
    proj = np.einsum("mji,mj->mi", V[ok], err[ok])
    out[ok] = np.sum(proj * proj / w[ok], axis=1)
    return out


@dataclass
class TruthErrors:
    """Estimate rows scored against the truth (NaN where the truth has no row)."""

    position_km: Floats
    nees: Floats


def truth_errors(truth: Matcher, truth_x: Floats, code: Ints, t: Floats, x: Floats,
                 P: Floats) -> TruthErrors:
    """Score estimate rows (`code` of their truth object, `t`, `x`, `P`) against the truth.

    `truth`: a `Matcher` of the truth rows, whose states are `truth_x` (N, 6) GCRF km,
    km/s. A row whose code is -1 (a track of no object) has no truth.
    """
    at = truth.find(code, t)
    err = np.full(len(t), np.nan)
    ne = np.full(len(t), np.nan)
    k = np.flatnonzero(at >= 0)
    d = x[k] - truth_x[at[k]]
    err[k] = np.linalg.norm(d[:, :3], axis=1)
    ne[k] = nees(d, P[k])
    return TruthErrors(err, ne)


def postfit_residuals(ekf: BatchEKF, estimates: Matcher, est_r: Floats, code: Ints, t: Floats,
                      station: Ints, z: Floats, sigma: Floats) -> Floats:
    """Return the normalised post-fit residual (M, 3) of range/az/el measurement rows.

    `estimates`: a `Matcher` of the fused estimates, whose positions are `est_r` (N, 3)
    GCRF km; per measurement row its object `code`, epoch `t`, station index of `ekf`
    (`station`, -1 for one the settings do not know), `z` (km, rad) and `sigma` (√diag R).
    NaN rows where there is no estimate of the object at the epoch, or no station.
    """
    out = np.full((len(t), RAZEL_DOF), np.nan)
    at = estimates.find(code, t)
    k = np.flatnonzero((at >= 0) & (station >= 0))
    for part in np.array_split(k, max(1, -(-len(k) // CHUNK))):
        if not len(part):
            continue
        x = np.zeros((len(part), STATE_DOF))
        x[:, :3] = est_r[at[part]]
        zp, _ = ekf.measure(x, t[part], station[part].astype(np.intp))
        y = z[part] - zp
        y[:, AZIMUTH] = np.angle(np.exp(1j * y[:, AZIMUTH]))
        out[part] = y / sigma[part]
    return out


def group_percentiles(code: Ints, values: Floats, n: int, qs: Sequence[float]
                      ) -> tuple[Ints, list[Floats]]:
    """Return per group 0..n-1 its count of finite `values` and their percentiles `qs`.

    Linear interpolation between order statistics, as `numpy.percentile` (NaN for an empty
    group); one sort for all groups.
    """
    keep = np.isfinite(values)
    c, v = code[keep], values[keep]
    order = np.lexsort((v, c))
    c, v = c[order], v[order]
    count = np.bincount(c, minlength=n).astype(np.int64)
    start = np.concatenate(([0], np.cumsum(count)[:-1]))
    out = []
    has = count > 0
    for q in qs:
        pos = (q / 100.0) * (count[has] - 1)
        lo = np.floor(pos).astype(np.int64)
        hi = np.minimum(lo + 1, count[has] - 1)
        a, b = v[start[has] + lo], v[start[has] + hi]
        p = np.full(n, np.nan)
        p[has] = a + (pos - lo) * (b - a)
        out.append(p)
    return count, out


def _fraction_in(code: Ints, values: Floats, band: tuple[float, float], n: int
                 ) -> tuple[Ints, Floats, Floats]:
    """Per group: finite values, the fraction inside `band`, and their mean (NaN if none)."""
    keep = np.isfinite(values)
    c, v = code[keep], values[keep]
    count = np.bincount(c, minlength=n)
    inside = np.bincount(c, weights=(v >= band[0]) & (v <= band[1]), minlength=n)
    total = np.bincount(c, weights=v, minlength=n)
    with np.errstate(invalid="ignore", divide="ignore"):
        return count.astype(np.int64), inside / count, total / count


@dataclass
class ObjectScores:
    """Per object (or track) 0..n-1 (`ids`), what `object_scores` computes.

    Counts are ints; NaN where an object has nothing to score.
    """

    ids: list[str]
    measurements: Ints
    estimates: Ints
    with_truth: Ints
    error_median_km: Floats
    error_p95_km: Floats
    nees_count: Ints
    nees_inside: Floats
    nees_mean: Floats
    nis_count: Ints
    nis_inside: Floats
    residual_count: Ints
    residual_rms: Floats
    """(n, 3): RMS of the normalised post-fit residuals per channel (range, az, el)."""
    residual_rms_all: Floats
    """RMS over all three channels."""
    truth_object: list[str]
    """The object whose truth each is scored against ('' for none)."""


def object_scores(ids: list[str], meas_code: Ints, est_code: Ints, err: TruthErrors,
                  nis_code: Ints, nis: Floats, res: Floats, truth_object: list[str]
                  ) -> ObjectScores:
    """Return per object of `ids` its scores (module docstring).

    `meas_code`: the object of each measurement row; `est_code`: of each estimate row,
    whose truth scores are `err`; `nis_code`, `nis`: the fused estimates with a published
    NIS (> 0); `res`: the normalised residual (M, 3) of each measurement row (NaN: none).
    """
    n = len(ids)
    with_truth, (med, p95) = group_percentiles(est_code, err.position_km, n, (50.0, 95.0))
    nees_n, nees_in, nees_mean = _fraction_in(est_code, err.nees, chi2_bounds(STATE_DOF), n)
    nis_n, nis_in, _ = _fraction_in(nis_code, nis, chi2_bounds(RAZEL_DOF), n)
    has = np.all(np.isfinite(res), axis=1)
    rc = meas_code[has]
    r_n = np.bincount(rc, minlength=n).astype(np.int64)
    with np.errstate(invalid="ignore", divide="ignore"):
        sq = np.stack([np.bincount(rc, weights=res[has, i] ** 2, minlength=n)
                       for i in range(RAZEL_DOF)], axis=1)
        rms = np.sqrt(sq / r_n[:, None])
        rms_all = np.sqrt(sq.sum(axis=1) / (RAZEL_DOF * r_n))
    return ObjectScores(
        ids, np.bincount(meas_code, minlength=n).astype(np.int64),
        np.bincount(est_code, minlength=n).astype(np.int64), with_truth, med, p95,
        nees_n, nees_in, nees_mean, nis_n, nis_in, r_n, rms, rms_all, truth_object)


def _num(v: float) -> float | None:
    return None if math.isnan(v) else float(v)


def _pooled(values: Floats) -> dict[str, float | int | None]:
    v = values[np.isfinite(values)]
    return {"median": _num(float(np.median(v))) if v.size else None,
            "p95": _num(float(np.percentile(v, 95))) if v.size else None, "rows": int(v.size)}


def summary(s: ObjectScores, err: TruthErrors, nis: Floats, res: Floats) -> dict[str, Any]:
    """Return the catalog's summary: objects, estimates, pooled error, bands, residuals."""
    lo, hi = chi2_bounds(STATE_DOF)
    nlo, nhi = chi2_bounds(RAZEL_DOF)
    ne = err.nees[np.isfinite(err.nees)]
    ok = np.all(np.isfinite(res), axis=1)
    per_object = s.error_median_km[np.isfinite(s.error_median_km)]
    return {
        "objects": len(s.ids),
        "objects_with_estimates": int(np.count_nonzero(s.estimates)),
        "objects_with_truth": int(np.count_nonzero(s.with_truth)),
        "measurements": int(s.measurements.sum()), "estimates": int(s.estimates.sum()),
        "position_error_km": _pooled(err.position_km),
        "median_of_object_medians_km": (float(np.median(per_object)) if per_object.size
                                        else None),
        "nees": {"band_95": [lo, hi], "rows": int(ne.size),
                 "inside": float(np.mean((ne >= lo) & (ne <= hi))) if ne.size else None,
                 "mean": float(np.mean(ne)) if ne.size else None},
        "nis": {"band_95": [nlo, nhi], "rows": int(nis.size),
                "inside": (float(np.mean((nis >= nlo) & (nis <= nhi))) if nis.size
                           else None)},
        "postfit_residual_rms_sigma": (float(np.sqrt(np.mean(res[ok] ** 2))) if ok.any()
                                       else None),
        "residual_rows": int(ok.sum()),
    }


def worst(s: ObjectScores, n: int) -> tuple[Ints, str]:
    """Return the indices of the `n` worst objects and what ranks them.

    By 95th-percentile position error where any object has a truth, else by post-fit
    residual RMS, else by the fraction of NIS outside its band; objects without the number
    last.
    """
    for values, what in ((s.error_p95_km, "95 % position error"),
                         (s.residual_rms_all, "post-fit residual RMS"),
                         (1.0 - s.nis_inside, "fraction of NIS outside the 95 % band")):
        if np.isfinite(values).any():
            key = np.where(np.isfinite(values), -values, np.inf)
            return np.argsort(key, kind="stable")[:n], what
    return np.arange(min(n, len(s.ids))), "object order"


def object_row(s: ObjectScores, i: int) -> dict[str, Any]:
    """Return object `i`'s scores as JSON-ready values (None for NaN)."""
    return {"object": s.ids[i], "truth_object": s.truth_object[i] or None,
            "measurements": int(s.measurements[i]), "estimates": int(s.estimates[i]),
            "estimates_with_truth": int(s.with_truth[i]),
            "position_error_median_km": _num(s.error_median_km[i]),
            "position_error_p95_km": _num(s.error_p95_km[i]),
            "nees_rows": int(s.nees_count[i]), "nees_inside_95": _num(s.nees_inside[i]),
            "nees_mean": _num(s.nees_mean[i]),
            "nis_rows": int(s.nis_count[i]), "nis_inside_95": _num(s.nis_inside[i]),
            "residual_rows": int(s.residual_count[i]),
            "postfit_residual_rms_sigma": _num(s.residual_rms_all[i]),
            "postfit_residual_rms_sigma_range_az_el": [_num(v) for v in s.residual_rms[i]]}

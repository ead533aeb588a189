"""Residual learning: forecast what a motion model gets wrong through the gaps between passes.

A station sees a low orbit in passes of minutes separated by hours, so the samples are
irregular and a delay embedding (Hankel-DMD) has nothing contiguous to learn from. This
module learns instead the *residual* of the filter's motion model (the placeholder: two-body
or two-body + J2) from the filter's estimates at the ends of past passes, and adds it to the
placeholder's prediction through the next gap.

The residual is expressed in the curvilinear frame of the placeholder's own trajectory
(`curvilinear`): radial distance difference, along-track arc and cross-track arc, km, at the
placeholder's predicted radius. A perturbation that the placeholder leaves out and that
depends on where the object is in its orbit (J2 for a two-body placeholder; drag, J3, higher
harmonics for a J2 placeholder) shows up there as

* harmonics of the argument of latitude u (J2's acceleration in the radial/along/cross frame
  is exactly 1, cos 2u, sin 2u and sin u, cos u terms for a near-circular orbit),
* secular terms in time: an along-track drift linear (mean-motion error) and quadratic (a
  constant along-track acceleration f gives -3/2 f t^2), a cross-track oscillation whose
  amplitude grows linearly (a nodal-rate error: t cos u, t sin u),

so the fit is a weighted linear least squares on that small basis, per component
(`basis`), over the irregular epochs of the training window, position and velocity
residuals together. Its anchor is the filter's estimate at the gap start; the training data
lie before it (the placeholder propagated backwards), the forecast after it. The residual
also absorbs the error of the anchor itself (a two-body error of a state is a 1, t, cos u,
sin u term), so the forecast is a small batch fit on past passes as well.

The forecast covariance is the fit's formal covariance, scaled by what held-out data say
(`ResidualSurrogate`): each fit, once made, is scored at the later anchors as they arrive
(out of sample: they were not in its training window), and the mean of those normalised
errors (NEES / 6) scales every later forecast's covariance (never below 1).

When a live filter fits and what it publishes in a gap is `gap_forecaster`'s policy. The
other variant evaluated, optimized DMD with bagging on the same irregular residual series,
is `studies.bopdmd` (a study, not part of the core).

Frames and units: GCRF km, km/s; times s (any clock, e.g. Unix s); residual coordinates km and
km/s in the placeholder trajectory's radial / along-track / cross-track (RTN) frame.

Here: the settings (`ResidualConfig`), the fit (`fit_residual`, `ResidualFit`) and the
held-out calibration over a stream of pass ends (`ResidualSurrogate`); the frame and the
placeholder's trajectory are `residual_frame`'s, the designs `residual_design`'s.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ssa_fusion.core.earth.timescales import DAY_S
from ssa_fusion.core.gaps.residual_design import basis, hill_design
from ssa_fusion.core.gaps.residual_frame import (
    Propagator,
    apply_residual,
    argument_of_latitude,
    period_of,
    residual_sigmas,
    state_residual,
    to_eci_covariance,
)

__all__ = ["LIVE_RESIDUAL", "PHYSICS_ACCEL_SIGMA", "PHYSICS_RESIDUAL", "ResidualConfig",
           "ResidualFit", "ResidualSurrogate", "basis_design", "design", "fit_residual",
           "fit_window"]

Array = NDArray[np.float64]


@dataclass(frozen=True)
class ResidualConfig:
    """Settings of the residual surrogate.

    Attributes
    ----------
    model : str
        "hill": the residual obeys Hill's equations about the placeholder's orbit, forced by
        empirical accelerations (`hill_design`); "basis": a free basis per component
        (`basis_design`).
    accel_components : tuple of bool
        Hill model: which axes (radial, along, cross) carry an empirical acceleration.
    window_s : float
        Training window before the gap start, s: the anchors (pass-end estimates) in it.
    min_anchors : int
        Fewest anchors in the window (the gap start's included) for a fit.
    min_span_s : float
        The window's anchors must span at least this, s.
    degrees : tuple of int
        Basis model: polynomial degree in time of the radial, along-track and cross-track residuals
        (-1: none).
    harmonics : int
        Harmonics of the argument of latitude (cos ju, sin ju, j = 1..harmonics): of the
        residual itself (basis) or of the empirical accelerations (hill).
    secular_harmonics : bool
        Basis model: also t cos u, t sin u (a once-per-revolution term whose amplitude
        drifts: a nodal or inclination rate the placeholder lacks).
    ridge : float
        Tikhonov weight on the coefficients of the column-normalised design (dimensionless).
    max_horizon_s : float
        No forecast further than this from the gap start, s.
    max_residual_km : float
        A fit whose position residual exceeds this anywhere in its window or forecast is
        refused (km).
    heldout_fits : int
        At each new anchor only the newest this many fits are scored (0: every fit within
        `max_horizon_s`). Each score propagates the placeholder from the fit's anchor, so a
        catalog bounds the cost with 1: the fit is scored where its gap ended.
    calibration_samples : int
        Held-out NEES values (the newest) the covariance scale averages.
    min_calibration : int
        Fewer held-out values than this: the scale is `prior_scale`.
    prior_scale : float
        Covariance scale before enough held-out data.
    horizon_scale : bool
        The held-out scale grows linearly with the horizon (a line through the held-out
        values) instead of being their mean.
    model_error : float
        Relative error of the linear residual model itself (the Hill equations about a
        circular orbit, the curvilinear map): each residual component's variance gets
        (model_error * residual)^2. 0.01: the Hill fit of a noise-free two-body + constant
        along-track acceleration truth misses by 0.5 % of the residual after 16 h
        (`test_residual`), doubled; not tuned on gaps.
    sigma_floor : tuple of float
        Floor of an anchor's standard deviations (km, km/s) in the fit's weights.
    accel_sigma : float
        Hill model: a priori standard deviation (km/s^2) of each empirical acceleration
        coefficient (a zero-mean Gaussian prior in the fit; 0: none, only `ridge`). With it
        a window of few anchors, even one, gives a fit whose covariance carries what the
        placeholder may leave out, grown through the gap (`PHYSICS_RESIDUAL`).
    """

    model: str = "hill"
    accel_components: tuple[bool, bool, bool] = (True, True, True)
    window_s: float = 2 * DAY_S
    min_anchors: int = 5
    min_span_s: float = DAY_S
    degrees: tuple[int, int, int] = (1, 2, 0)
    harmonics: int = 2
    secular_harmonics: bool = True
    ridge: float = 1e-6
    max_horizon_s: float = DAY_S
    max_residual_km: float = 2000.0
    heldout_fits: int = 0
    calibration_samples: int = 30
    min_calibration: int = 3
    prior_scale: float = 10.0
    sigma_floor: tuple[float, float] = (1e-3, 1e-6)
    horizon_scale: bool = False
    model_error: float = 0.01
    accel_sigma: float = 0.0

    def __post_init__(self) -> None:
        """Check `accel_sigma` (ValueError): finite, >= 0, and only for the Hill model."""
        if not (math.isfinite(self.accel_sigma) and self.accel_sigma >= 0.0):
            raise ValueError(f"accel_sigma must be a finite number >= 0, got {self.accel_sigma}")
        if self.accel_sigma and self.model != "hill":
            raise ValueError("accel_sigma is a prior of the Hill model's accelerations")


def basis_design(tau: ArrayLike, u: ArrayLike, udot: ArrayLike, cfg: ResidualConfig,
                 period_s: float) -> Array:
    """Return the design of the free-basis residual model.

    Design (k, 6, m) of the free-basis residual model: each position component its own
    `basis` (rows 0-2), the velocity rows their derivatives (rows 3-5), block-diagonal.
    """
    parts = [basis(tau, u, udot, d, cfg.harmonics, cfg.secular_harmonics, period_s)
             for d in cfg.degrees]
    m = sum(B.shape[1] for B, _ in parts)
    out = np.zeros((len(np.atleast_1d(tau)), 6, m))
    col = 0
    for i, (B, dB) in enumerate(parts):
        out[:, i, col:col + B.shape[1]] = B
        out[:, 3 + i, col:col + B.shape[1]] = dB
        col += B.shape[1]
    return out


@dataclass
class ResidualFit:
    """One fitted residual model, anchored at the gap start (t0, x0).

    coef (m,), cov (m, m): the parameters and their formal covariance (scaled by the
    in-sample reduced chi-square when above 1); scale: the held-out covariance scale
    applied by `predict`; period_s: the anchor's orbital period, s; u0: its argument of
    latitude, rad; max_residual_km: the largest training position residual, km.
    """

    cfg: ResidualConfig
    propagate: Propagator
    t0: float
    x0: Array
    coef: Array
    cov: Array
    period_s: float
    u0: float
    scale: tuple[float, float] = (1.0, 0.0)
    max_residual_km: float = 0.0
    n_anchors: int = 0

    def scale_at(self, t: ArrayLike) -> Array:
        """Return the covariance scale at epochs t.

        The covariance scale at epochs t (s): max(1, a + b * horizon in days).
        """
        h = (np.atleast_1d(np.asarray(t, float)) - self.t0) / DAY_S
        return np.maximum(1.0, self.scale[0] + self.scale[1] * h)

    def design(self, tau: Array, x_ref: Array) -> Array:
        """Return the model's design.

        The model's design (k, 6, m) at times tau (s from t0) on the reference x_ref.
        """
        return design(self.cfg, tau, x_ref, self.period_s, self.u0)

    def residual(self, t: ArrayLike) -> tuple[Array, Array, Array]:
        """Return the reference, the residual and its formal covariance.

        The placeholder trajectory x_ref (k, 6), the residual (k, 6) and its formal
        covariance (k, 6, 6) in the residual frame (unscaled; the fit's parameter covariance
        plus the relative `model_error`), at epochs t (s).
        """
        t = np.atleast_1d(np.asarray(t, float))
        x_ref = self.propagate(self.x0, self.t0, t)
        D = self.design(t - self.t0, x_ref)
        res = D @ self.coef
        cov = np.einsum("kam,mn,kbn->kab", D, self.cov, D)
        idx = np.arange(6)
        cov[:, idx, idx] += (self.cfg.model_error * res) ** 2
        return x_ref, res, cov

    def predict(self, t: ArrayLike) -> tuple[Array, Array]:
        """Forecast states and covariances.

        Forecast states (k, 6) and covariances (k, 6, 6), GCRF km, km/s, at epochs t (s):
        the placeholder from the anchor plus the learned residual, covariance = scale x
        formal (`scale_at`; mapped from the residual frame by its axes).
        """
        x_ref, res, cov = self.residual(t)
        return (apply_residual(x_ref, res),
                self.scale_at(t)[:, None, None] * to_eci_covariance(x_ref, cov))

    def along_track_acceleration(self) -> float:
        """Return the constant along-track acceleration the fit found.

        The constant along-track acceleration (km/s^2) the fit found: the Hill model's
        constant along-track term, or, for the free basis, the one its along-track t^2 term
        implies (Hill: -3/2 f t^2); 0 if the model has neither.
        """
        c = self.cfg
        if c.model == "hill":
            if not c.accel_components[1]:
                return 0.0
            q = 1 + 2 * c.harmonics
            return float(self.coef[6 + q * sum(c.accel_components[:1])])
        if c.degrees[1] < 2:
            return 0.0
        col = (c.degrees[0] + 1 + 2 * c.harmonics + 2 * c.secular_harmonics) + 2
        return float(-2.0 / 3.0 * self.coef[col] / self.period_s ** 2)


def design(cfg: ResidualConfig, tau: ArrayLike, x_ref: ArrayLike, period_s: float,
           u0: float) -> Array:
    """Return the design of `cfg.model`.

    The design (k, 6, m) of `cfg.model` ("hill" or "basis") at times tau (s from the
    anchor) along the placeholder trajectory x_ref (k, 6).
    """
    if cfg.model == "hill":
        return hill_design(tau, 2 * math.pi / period_s, u0, cfg.harmonics,
                           cfg.accel_components)
    u, ud = argument_of_latitude(x_ref)
    return basis_design(tau, u, ud, cfg, period_s)


class _Window(NamedTuple):
    t: Array
    x: Array
    P: Array
    t0: float
    period: float
    x_ref: Array
    res: Array


def fit_window(cfg: ResidualConfig, propagate: Propagator, t: ArrayLike, x: ArrayLike,
               P: ArrayLike) -> _Window | None:
    """Return the training window of the anchors that end at the gap start t0.

    Its anchors, the placeholder from the last one (x_ref) and their residual against it;
    None when the window holds fewer than `min_anchors` or spans less than `min_span_s`,
    or the orbit is unbound.
    """
    ta, xa, Pa = np.asarray(t, float), np.asarray(x, float), np.asarray(P, float)
    t0 = float(ta[-1])
    keep = ta >= t0 - cfg.window_s
    ta, xa, Pa = ta[keep], xa[keep], Pa[keep]
    if len(ta) < cfg.min_anchors or t0 - ta[0] < cfg.min_span_s:
        return None
    period = period_of(xa[-1])
    if not math.isfinite(period):
        return None
    x_ref = propagate(xa[-1], t0, ta)
    return _Window(ta, xa, Pa, t0, period, x_ref, state_residual(x_ref, xa))


def fit_residual(cfg: ResidualConfig, propagate: Propagator, t: ArrayLike, x: ArrayLike,
                 P: ArrayLike) -> ResidualFit | None:
    """Fit the residual model to the anchors of its window.

    Fit the residual model to anchors (epochs t (k,) s, GCRF states x (k, 6), covariances
    P (k, 6, 6)); the last anchor is the gap start. None when the window holds too little
    (fewer than `min_anchors` anchors or a span below `min_span_s`) or the fit is refused
    (a residual beyond `max_residual_km`, an unbound orbit).
    """
    w = fit_window(cfg, propagate, t, x, P)
    if w is None:
        return None
    t, x, P, t0, period, x_ref, res = w
    if not np.all(np.isfinite(res)) or np.abs(res[:, :3]).max() > cfg.max_residual_km:
        return None
    sig = residual_sigmas(x_ref, P, cfg.sigma_floor)
    u0 = float(argument_of_latitude(x[-1:])[0][0])
    D = design(cfg, t - t0, x_ref, period, u0)
    A = (D / sig[:, :, None]).reshape(-1, D.shape[2])
    y = (res / sig).reshape(-1)
    norm = np.linalg.norm(A, axis=0)
    norm[norm == 0.0] = 1.0
    An = A / norm
    prior = np.zeros(A.shape[1])  # information of each normalised coefficient's prior
    if cfg.accel_sigma:  # the accelerations (columns after the 6 of the anchor's residual)
        prior[6:] = 1.0 / (cfg.accel_sigma * norm[6:]) ** 2
    Gi = np.linalg.inv(An.T @ An + np.diag(prior + cfg.ridge))
    c = Gi @ (An.T @ y)
    dof = A.shape[0] - int(np.count_nonzero(prior == 0.0))  # a prior determines its own
    chi2 = float(np.sum((An @ c - y) ** 2))
    inflate = max(1.0, chi2 / dof) if dof > 0 else 1.0
    return ResidualFit(cfg, propagate, t0, x[-1].copy(), c / norm,
                       inflate * Gi / np.outer(norm, norm), period, u0,
                       max_residual_km=float(np.abs(res[:, :3]).max()), n_anchors=len(t))


@dataclass
class ResidualSurrogate:
    """The residual surrogate over one object's stream of pass-end estimates.

    `add_anchor` takes the filter's estimate at the end of each pass (epoch order); it also
    scores the earlier fits there, out of sample (`heldout`: NEES / 6 of the fit's forecast
    against the estimate, with both covariances). `fit` fits at the newest anchor (the gap
    start) and scales its covariance by the held-out mean (`scale`).
    """

    cfg: ResidualConfig
    propagate: Propagator
    t: list[float] = field(default_factory=list)
    x: list[Array] = field(default_factory=list)
    P: list[Array] = field(default_factory=list)
    fits: list[ResidualFit] = field(default_factory=list)
    heldout: list[tuple[float, float]] = field(default_factory=list)

    def add_anchor(self, t: float, x: ArrayLike, P: ArrayLike) -> None:
        """Add the estimate (GCRF x (6,), P (6, 6)) at epoch t (s) at the end of a pass."""
        if self.t and t <= self.t[-1]:
            raise ValueError(f"anchor at t={t} not after the last one (t={self.t[-1]})")
        xa, Pa = np.asarray(x, float), np.asarray(P, float)
        k = self.cfg.heldout_fits
        for f in self.fits[-k:] if k else self.fits:
            if 0.0 < t - f.t0 <= self.cfg.max_horizon_s:
                x_ref, res, cov = f.residual(np.array([t]))
                e = xa - apply_residual(x_ref, res)[0]
                S = to_eci_covariance(x_ref, cov)[0] + Pa
                try:
                    self.heldout.append((float(e @ np.linalg.solve(S, e)) / 6.0,
                                         (t - f.t0) / DAY_S))
                except np.linalg.LinAlgError:
                    continue
        self.fits = [f for f in self.fits if t - f.t0 <= self.cfg.max_horizon_s]
        if k:
            self.fits = self.fits[-k:]  # the others are never scored again
        self.t.append(float(t))
        self.x.append(xa.copy())
        self.P.append(Pa.copy())
        # what no later fit or scale can use: bounded memory on a stream of any length
        old = sum(1 for ta in self.t if ta < t - self.cfg.window_s)
        del self.t[:old], self.x[:old], self.P[:old]
        del self.heldout[:-self.cfg.calibration_samples]

    @property
    def scale(self) -> tuple[float, float]:
        """Return the covariance scale (a, b) of the next fit.

        The covariance scale (a, b) of the next fit: the least-squares line a + b * h
        through the newest `calibration_samples` held-out (NEES / 6, horizon h in days),
        b >= 0 (the mean, b = 0, when the horizons do not spread); (`prior_scale`, 0)
        before `min_calibration` samples.
        """
        h = np.array(self.heldout[-self.cfg.calibration_samples:]).reshape(-1, 2)
        if len(h) < self.cfg.min_calibration:
            return self.cfg.prior_scale, 0.0
        v, d = h[:, 0], h[:, 1]
        if self.cfg.horizon_scale and np.ptp(d) > 0.05:
            b, a = np.polyfit(d, v, 1)
            if b > 0.0:
                return float(a), float(b)
        return float(np.mean(v)), 0.0

    def fit(self) -> ResidualFit | None:
        """Fit at the newest anchor (None: too little data, or refused)."""
        if not self.t:
            return None
        keep = np.asarray(self.t) >= self.t[-1] - self.cfg.window_s
        first = int(np.argmax(keep))
        f = fit_residual(self.cfg, self.propagate, np.array(self.t[first:]),
                         np.array(self.x[first:]), np.array(self.P[first:]))
        if f is None:
            return None
        f.scale = self.scale
        self.fits.append(f)
        return f


LIVE_RESIDUAL = ResidualConfig(model="hill", harmonics=1, model_error=0.2)
"""The residual setting a live filter uses: ``hill_h1_me20`` (empirical accelerations,
constant + once per revolution, 2-day window, relative model error 0.2), chosen on the
tuning seeds 1-3 by `studies.gap_study.tune` (docs/HISTORY.md, 2026-11-25: a surrogate
through the gaps between passes)."""

PHYSICS_ACCEL_SIGMA = 1e-8
"""A priori standard deviation (km/s^2) of the constant radial, along- and cross-track
accelerations of `PHYSICS_RESIDUAL`: what the placeholder may leave out (drag, J3 and
beyond), grown through the gap (as t^2 along track). The smallest of {1e-8, 3e-8} whose
forecasts' position NEES lies within chi2(3)'s 95 % bound at >= 90 % of them against the SGP4
truth on each of the tuning seeds 1-3 (`bench/bench_physics_fit.py --tuning --window-h 0`:
20 LEO objects of the radar network, 30 h): 90.1 / 90.2 / 91.1 %, median NEES 1.92 / 2.22 /
2.01, median error 365 / 384 / 358 m (3e-8: 95.5 / 95.5 / 95.9 %, median NEES 1.24 / 1.39 /
1.25). The forecast's state does not depend on it."""

PHYSICS_RESIDUAL = ResidualConfig(model="hill", harmonics=0, window_s=0.0, min_anchors=1,
                                  min_span_s=0.0, model_error=0.2, heldout_fits=1,
                                  prior_scale=1.0, accel_sigma=PHYSICS_ACCEL_SIGMA)
"""The physics-only forecast of a gap before the learned residual has its day of pass ends
(or when it refuses its fit): the placeholder (two-body + J2) from the pass-end estimate
alone (``window_s`` 0: from the object's first pass end on), with constant R, T, N
accelerations under the Gaussian prior `PHYSICS_ACCEL_SIGMA` (no harmonics) in its
covariance, which grows through the gap with what the placeholder leaves out; scaled by its
own held-out NEES once there are `min_calibration` of them (1 before: the prior carries the
model error). A window of pass ends is no better: on tuning seed 1 a 6 h window (the same
fit of the placeholder and the constant accelerations to every pass end in it) erred less,
200 m median against 365, but its covariance was overconfident: 50.3 % within the bound at
1e-8 km/s^2, 55.1 % at 3e-8 (24 h: 48.5 %, seed 1, 30 objects); what the constant
accelerations leave out of the pass ends (once per revolution, J3) is not in its formal
covariance."""

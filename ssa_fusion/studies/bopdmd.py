"""BOP-DMD on the irregular residual series: the variant of the gap surrogate that lost.

Optimized DMD with bagging (PyDMD's `BOPDMD`, which accepts any time vector) fitted on the
residual series of `core.gaps.residual` (the same window and frame), forecast through the gap with
the bagging's variance. `studies.gap_study` compares it with the residual fit of the core;
docs/RESULTS.md ("Between passes") has the numbers. PyDMD is a test/study dependency only.

Frames and units: GCRF km, km/s; times s; residual coordinates as `core.gaps.residual`.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ssa_fusion.core.gaps.residual import ResidualConfig, fit_window
from ssa_fusion.core.gaps.residual_frame import (
    Propagator,
    apply_residual,
    to_eci_covariance,
)

Array = NDArray[np.float64]


@dataclass(frozen=True)
class BopConfig:
    """Settings of the BOP-DMD residual variant.

    rank : number of DMD eigenvalues (<= 6, the residual's dimension); trials, trial_size :
    bagging (PyDMD's num_trials, trial_size); seed : the bagging's random draws.
    """

    rank: int = 6
    trials: int = 20
    trial_size: float = 0.8
    seed: int = 0


def bopdmd_fit(t: ArrayLike, y: ArrayLike, cfg: BopConfig,
               init_alpha: ArrayLike | None = None) -> Callable[[Array], tuple[Array, Array]]:
    """Fit BOP-DMD to irregular samples and return its forecast.

    Fit BOP-DMD to samples y (k, d) at irregular times t (k,) s; return a forecast
    function t (j,) -> (mean (j, d), variance (j, d)) from the bagging (PyDMD `BOPDMD`).

    Raises ImportError if PyDMD is not installed, RuntimeError if the fit fails.
    """
    import contextlib
    import io
    import warnings

    from pydmd import BOPDMD  # type: ignore[import-untyped]

    t = np.asarray(t, float)
    y = np.asarray(y, float)
    scale = np.maximum(np.abs(y).max(axis=0), 1e-12)
    opts = {"maxiter": 60, "tol": 1e-8, "verbose": False}
    state = np.random.get_state()
    np.random.seed(cfg.seed)
    try:
        with warnings.catch_warnings(), contextlib.redirect_stdout(io.StringIO()):
            warnings.simplefilter("ignore")
            dmd = BOPDMD(svd_rank=min(cfg.rank, y.shape[1]), num_trials=cfg.trials,
                         trial_size=cfg.trial_size, use_proj=False,
                         init_alpha=None if init_alpha is None else np.asarray(init_alpha),
                         eig_constraints={"conjugate_pairs"}, varpro_opts_dict=opts)
            dmd.fit((y / scale).T, t)
    except Exception as exc:
        raise RuntimeError(f"BOP-DMD fit failed: {exc}") from exc
    finally:
        np.random.set_state(state)

    def forecast(tt: Array) -> tuple[Array, Array]:
        tt = np.atleast_1d(np.asarray(tt, float))
        # the mean from the bag-averaged eigenvalues and amplitudes (PyDMD's own mean is
        # that of random draws); the variance of the draws, with a fixed seed
        mean = np.linalg.multi_dot([dmd.modes, np.diag(dmd.amplitudes),
                                    np.exp(np.outer(dmd.eigs, tt))])
        saved = np.random.get_state()
        np.random.seed(cfg.seed)
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                out = dmd.forecast(tt)
        finally:
            np.random.set_state(saved)
        var = np.real(np.asarray(out[1])).T if isinstance(out, tuple) else np.zeros(
            (len(tt), len(scale)))
        return np.real(mean).T * scale, np.abs(var) * scale ** 2

    return forecast


def bopdmd_residual_forecast(cfg: ResidualConfig, bop: BopConfig, propagate: Propagator,
                             t: ArrayLike, x: ArrayLike, P: ArrayLike,
                             t_out: ArrayLike) -> tuple[Array, Array] | None:
    """Forecast the residual with BOP-DMD (variant (a)).

    Variant (a): BOP-DMD fitted on the residual series of the anchors (t, x, P as in
    `fit_residual`, the same window rules) and forecast at t_out: states (j, 6) and
    covariances (j, 6, 6) (bagging variance, diagonal in the residual frame, plus the gap
    start's own covariance). None when the window holds too little or the fit fails.
    """
    w = fit_window(cfg, propagate, t, x, P)
    if w is None:
        return None
    t, x, P, t0, period, _, res = w
    n = 2 * math.pi / period
    alpha = np.array([1j * n, -1j * n, 2j * n, -2j * n, 1e-3 * n + 0j, -1e-3 * n + 0j])
    try:
        forecast = bopdmd_fit((t - t0) / period, res, bop, alpha[:bop.rank] * period)
    except RuntimeError:
        return None
    t_out = np.asarray(t_out, float)
    mean, var = forecast((t_out - t0) / period)
    if not (np.all(np.isfinite(mean)) and np.all(np.isfinite(var))):
        return None
    if np.abs(mean[:, :3]).max() > cfg.max_residual_km:
        return None
    ref_out = propagate(x[-1], t0, t_out)
    cov = np.zeros((len(t_out), 6, 6))
    cov[:, range(6), range(6)] = var
    P0 = np.asarray(P, float)[-1]
    return apply_residual(ref_out, mean), to_eci_covariance(ref_out, cov) + P0

"""Damped Gauss-Newton least squares with outlier editing: the solver under `batch_ls.fit`.

`gauss_newton` minimises the weighted sum of squares of whitened residuals returned by a
caller's ``evaluate(x)`` (a `Linearization`: residuals, their Jacobian, which rows belong to
which measurement), with optional a-priori information on ``x``:

* outlier editing, as Orekit's ``OutlierFilter`` and GMAT's batch estimator do: a measurement
  whose whitened residual exceeds ``k`` in any channel is left out of the next correction
  (``first_edit_sigma`` during the first ``warmup`` linearisations, then
  ``edit_sigma * max(1, previous weighted RMS)``), re-decided every iteration, never more than
  ``max_reject_fraction`` of the measurements;
* the correction from a column-scaled SVD of the whitened normal equations;
* a correction that does not reduce the cost is halved up to ``max_halvings`` times;
* convergence, divergence and under-determination end as a `FitStatus` with a reason, never
  an exception (the rules: `batch_ls`'s module docstring).

Units are the caller's; residuals are whitened (dimensionless).
"""

from __future__ import annotations

import enum
import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = ["FitStatus", "Linearization", "Solution", "SolverOptions", "gauss_newton"]

Array = NDArray[np.float64]
IntArray = NDArray[np.int64]
BoolArray = NDArray[np.bool_]

_ROUND_OFF = 1e-8
"""Weighted RMS (sigma units) below which residuals are round-off: the fit has converged
(noise-free data), and cost changes below it do not judge a step."""


class FitStatus(enum.StrEnum):
    """How a fit ended."""

    CONVERGED = "converged"
    """Converged (module docstring): the estimate and its covariance can be used."""
    MAX_ITERATIONS = "max_iterations"
    """Not converged within the iteration cap (the last iterate is returned)."""
    DIVERGED = "diverged"
    """Non-finite values, no Earth orbit, or residuals that grow along every step: no
    estimate."""
    UNDERDETERMINED = "underdetermined"
    """Too few accepted measurements, or singular normal equations."""


@dataclass(frozen=True)
class SolverOptions:
    """Iterations, editing and convergence of `gauss_newton` (module docstring).

    Attributes
    ----------
    max_iterations : int
        Corrections at most.
    edit_sigma : float
        Editing threshold after the warm-up, whitened residual units (times the previous
        weighted RMS when above 1).
    first_edit_sigma : float
        Editing threshold during the warm-up (GMAT's initial RMS sigma is 3000).
    warmup : int
        Linearisations edited with ``first_edit_sigma`` (at least 1: the first guess).
    max_reject_fraction : float
        Largest fraction of the measurements edited out at once (the worst ones).
    rms_rtol : float
        Relative change of the weighted RMS below which the fit has converged.
    correction_tol : float
        Size of the last correction, in its formal sigma, below which the fit has converged.
    max_halvings : int
        Halvings of a correction that does not reduce the weighted residuals (or leads where
        they cannot be computed) before the fit is declared diverged.
    """

    max_iterations: int = 12
    edit_sigma: float = 3.5
    first_edit_sigma: float = 3000.0
    warmup: int = 1
    max_reject_fraction: float = 0.2
    rms_rtol: float = 1e-4
    correction_tol: float = 1e-2
    max_halvings: int = 6


@dataclass
class Linearization:
    """Whitened residuals and partials of every measurement at one solve-for vector.

    Attributes
    ----------
    r : ndarray (rows,)
        Whitened residuals ``L^-1 (z - h(x))`` (angles wrapped), one row per channel.
    J : ndarray (rows, n)
        Whitened partials ``L^-1 dh/dx``: ``r`` is linearly ``J dx`` plus noise.
    group : ndarray (rows,) of int
        The measurement of each row (0 .. n_groups - 1).
    n_groups : int
        Number of measurements.
    """

    r: Array
    J: Array
    group: IntArray
    n_groups: int


@dataclass
class Solution:
    """What `gauss_newton` found.

    Attributes
    ----------
    x : ndarray (n,)
        The solve-for vector (the last correction, below the tolerance, applied).
    P : ndarray (n, n)
        Its formal covariance at the last linearisation (NaN if there was none).
    status : FitStatus
        How it ended; ``reason`` says why in words.
    iterations : int
        Linearisations made (halved steps included).
    rms : float
        Weighted RMS of the accepted residuals at the last linearisation.
    rms_history : list of float
        The weighted RMS of every linearisation.
    accepted : ndarray (n_groups,) of bool
        Measurements used by the last correction.
    score : ndarray (n_groups,)
        Largest whitened residual channel of each measurement (absolute).
    lin : Linearization or None
        The last linearisation.
    """

    x: Array
    P: Array
    status: FitStatus
    reason: str
    iterations: int
    rms: float
    rms_history: list[float]
    accepted: BoolArray
    score: Array
    lin: Linearization | None


def _edit(score: Array, threshold: float, max_fraction: float) -> BoolArray:
    """Return the accepted measurements: score <= threshold, at most a fraction edited."""
    reject = score > threshold
    cap = math.floor(max_fraction * score.size)
    if int(reject.sum()) > cap:
        worst = np.argsort(-score, kind="stable")[:cap]
        reject = np.zeros(score.size, dtype=bool)
        reject[worst] = True
    accepted: BoolArray = ~reject
    return accepted


def _sqrt_information(info: Array) -> Array:
    """Rows ``Rp`` with ``Rp^T Rp = info`` (symmetric positive semi-definite, any rank)."""
    lam, v = np.linalg.eigh(0.5 * (info + info.T))
    keep = lam > lam.max(initial=0.0) * 1e-15
    rows: Array = np.sqrt(lam[keep])[:, None] * v[:, keep].T
    return rows


def gauss_newton(evaluate: Callable[[Array], Linearization | str], x0: ArrayLike,
                 options: SolverOptions | None = None, prior_mean: ArrayLike | None = None,
                 prior_information: ArrayLike | None = None) -> Solution:
    """Weighted least squares by Gauss-Newton with outlier editing (module docstring).

    A correction that does not reduce the weighted sum of squares (over the measurements it
    was computed from, prior included) or leads where ``evaluate`` fails is halved, up to
    ``max_halvings`` times, before the fit is declared diverged.

    Parameters
    ----------
    evaluate : callable
        ``evaluate(x) -> Linearization`` at the solve-for vector ``x`` (n,), or a string
        saying why it cannot be evaluated there.
    x0 : array_like (n,)
        First guess.
    options : SolverOptions, optional
        Iterations, editing, convergence.
    prior_mean, prior_information : array_like (n,), (n, n), optional
        A-priori mean and information matrix (inverse covariance; singular allowed: zero
        rows and columns for unconstrained components).

    Returns
    -------
    Solution
    """
    return _Solver(evaluate, x0, options or SolverOptions(), prior_mean,
                   prior_information).run()


def _svd_step(A: Array, b: Array, n: int) -> tuple[Array, Array, float] | None:
    """Return the correction, its covariance and size (in its sigma) from ``A dx = b``.

    From a column-scaled SVD of the whitened system; None when it is singular.
    """
    d = 1.0 / np.maximum(np.linalg.norm(A, axis=0), 1e-300)
    u, s, vt = np.linalg.svd(A * d, full_matrices=False)
    if not s.size or s[-1] <= s[0] * 1e-13:
        return None
    ub = u.T @ b
    delta = d * (vt.T @ (ub / s))
    P = (d[:, None] * vt.T / (s * s)) @ (vt * d[None, :])
    P = 0.5 * (P + P.T)
    return delta, P, float(np.sqrt(ub @ ub / n))


class _Solver:
    """The iteration of `gauss_newton`, and its state from one linearisation to the next."""

    def __init__(self, evaluate: Callable[[Array], Linearization | str], x0: ArrayLike,
                 options: SolverOptions, prior_mean: ArrayLike | None,
                 prior_information: ArrayLike | None) -> None:
        self.evaluate = evaluate
        self.o = options
        self.x = np.array(x0, dtype=float).reshape(-1)
        n = self.n = self.x.size
        self.rp: Array | None = None
        self.mean = np.zeros(n) if prior_mean is None else np.asarray(prior_mean, float).reshape(n)
        if prior_information is not None:
            self.rp = _sqrt_information(np.asarray(prior_information, dtype=float))
        self.history: list[float] = []
        self.nan_p = np.full((n, n), math.nan)
        self.accepted_prev: BoolArray | None = None
        self.x_prev: Array | None = None
        self.delta_prev = np.zeros(n)
        self.rms_prev = self.corr_prev = self.cost_prev = math.inf
        self.halvings = self.corrections = self.lins = 0
        self.lin: Linearization | None = None
        self.accepted = np.zeros(0, dtype=bool)
        self.score = np.zeros(0)

    def _done(self, status: FitStatus, reason: str, P: Array, rms: float) -> Solution:
        return Solution(self.x, P, status, reason, self.lins, rms, self.history,
                        self.accepted, self.score, self.lin)

    def _prior_cost(self, v: Array) -> float:
        return 0.0 if self.rp is None else float(np.sum((self.rp @ (self.mean - v)) ** 2))

    def run(self) -> Solution:
        """Linearise, correct, halve a failed correction, until the fit ends."""
        while True:
            got = self.evaluate(self.x)
            self.lins += 1
            why = self._why(got)
            if self.x_prev is not None and self.accepted_prev is not None and why:
                if self.halvings < self.o.max_halvings:
                    self.halvings += 1
                    self.x = self.x_prev + self.delta_prev * 0.5**self.halvings
                    continue
                self.x = self.x_prev
                return self._done(FitStatus.DIVERGED, f"correction {self.corrections}: {why}",
                                  self.nan_p, self.rms_prev)
            if why or isinstance(got, str):
                return self._done(FitStatus.DIVERGED, f"first guess: {why}", self.nan_p,
                                  math.nan)
            end = self._correct(got)
            if end is not None:
                return end

    def _why(self, got: Linearization | str) -> str:
        """Return why the linearisation ``got`` cannot be used ("" when it can).

        After a correction above the tolerance, also when it did not reduce the cost (a
        correction below the tolerance is not judged by the cost: round-off).
        """
        why = got if isinstance(got, str) else (
            "" if np.isfinite(got.r).all() and np.isfinite(got.J).all()
            else "non-finite residuals or partials")
        if (self.x_prev is not None and self.accepted_prev is not None and not why
                and not isinstance(got, str) and self.corr_prev > self.o.correction_tol):
            rows = self.accepted_prev[got.group]
            cost = float(np.sum(got.r[rows] ** 2)) + self._prior_cost(self.x)
            if cost > self.cost_prev * (1.0 + 1e-12) + _ROUND_OFF**2 * rows.size:
                why = (f"no step along the correction reduces the weighted residuals "
                       f"({self.o.max_halvings} halvings)")
        return why

    def _correct(self, lin: Linearization) -> Solution | None:
        """Edit, correct from ``lin``: the solution when the fit ends here, else None."""
        o, n, rp = self.o, self.n, self.rp
        self.lin = lin
        self.halvings = 0
        self.score = np.zeros(lin.n_groups)
        np.maximum.at(self.score, lin.group, np.abs(lin.r))
        warm = self.corrections < max(1, o.warmup)
        threshold = o.first_edit_sigma if warm else o.edit_sigma * max(1.0, self.rms_prev)
        self.accepted = _edit(self.score, threshold, o.max_reject_fraction)
        rows = self.accepted[lin.group]
        A, b = lin.J[rows], lin.r[rows]
        rms = float(np.sqrt(np.mean(b * b))) if b.size else math.nan
        self.history.append(rms)
        if b.size < n and rp is None:
            return self._done(FitStatus.UNDERDETERMINED,
                              f"{b.size} accepted measurement channels for {n} unknowns",
                              self.nan_p, rms)
        if rp is not None:
            A = np.vstack([A, rp])
            b = np.concatenate([b, rp @ (self.mean - self.x)])
        step = _svd_step(A, b, n)
        if step is None:
            return self._done(FitStatus.UNDERDETERMINED, "singular normal equations (an "
                              "unobservable combination of the solve-for parameters)",
                              self.nan_p, rms)
        delta, P, corr = step
        same = self.accepted_prev is not None and np.array_equal(self.accepted,
                                                                 self.accepted_prev)
        if same and not warm and (self.corr_prev <= o.correction_tol or rms <= _ROUND_OFF
                                  or abs(rms - self.rms_prev) <= o.rms_rtol * self.rms_prev):
            self.x = self.x + delta
            return self._done(FitStatus.CONVERGED,
                              f"converged after {self.lins} linearisations", P, rms)
        if self.corrections == o.max_iterations:
            return self._done(FitStatus.MAX_ITERATIONS, f"not converged in {o.max_iterations} "
                              f"corrections (the last {corr:.3g} sigma)", P, rms)
        self.cost_prev = float(b @ b)
        self.x_prev, self.delta_prev = self.x, delta
        self.x = self.x + delta
        self.corrections += 1
        self.accepted_prev, self.rms_prev, self.corr_prev = self.accepted, rms, corr
        return None

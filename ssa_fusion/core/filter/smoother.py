"""Rauch-Tung-Striebel smoothing of a filter's estimates: the definitive orbit of a replay.

The fixed-interval smoother runs backwards over what the forward filter recorded at each
fused epoch k: the prior ``x_prior_k, P_prior_k`` (predicted from step k-1), the posterior
``x_post_k, P_post_k``, and the transition ``F_k = d x_prior_k / d x_post_{k-1}``::

    C_k   = P_post_k F_{k+1}^T P_prior_{k+1}^-1
    x_s_k = x_post_k + C_k (x_s_{k+1} - x_prior_{k+1})
    P_s_k = P_post_k + C_k (P_s_{k+1} - P_prior_{k+1}) C_k^T

(`rts`; with linear dynamics it is FilterPy's ``rts_smoother``, which recomputes
``P_prior = F P F^T + Q`` itself; here the filter's own prior is used, so a bounded or
otherwise adjusted prior, and the nonlinear ``x_prior = f(x_post)``, are what the filter had).

What the filter must record (`FilterStep`): the epoch, prior, posterior and F of every
fused step, in epoch order, along the chain of steps the filter finally kept (after
out-of-sequence rollbacks). The per-object `tracker.Tracker` is not changed for it:

* `steps_from_estimates` rebuilds the history from the posteriors alone (the estimates the
  filter published, e.g. a bag's ``/ssa/estimate``), re-predicting each one to the next epoch
  with the filter's motion model, process noise and covariance bound: the filter did exactly
  that (`tracker.Tracker._step`), so the priors and F are the filter's own to round-off;
* `TrackerRecorder` wraps a live `Tracker` and keeps that chain as measurements go in
  (rolled-back steps replaced, a re-initialisation starting a new segment: smoothing never
  crosses an IOD).

Units are the filter's (orbits: GCRF km, km/s; times s).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from ssa_fusion.core.base.types import Measurement, StateEstimate
from ssa_fusion.core.filter.ekf import ExtendedKalmanFilter, bound_covariance
from ssa_fusion.core.filter.initiation import Placeholder
from ssa_fusion.core.filter.tracker import Outcome, Tracker

__all__ = ["FilterStep", "Smoothed", "TrackerRecorder", "rts", "smooth_estimates",
           "steps_from_estimates", "tracker_noise"]

Array = NDArray[np.float64]

NoiseFunction = Callable[[Array, float], Array]
"""Q(x, dt) (n, n): the process noise a filter adds predicting state x over dt s."""


@dataclass
class FilterStep:
    """One fused step of a forward filter, as the smoother needs it.

    Attributes
    ----------
    t : float
        Epoch, s.
    x_prior, P_prior : ndarray (n,), (n, n)
        The prediction to ``t`` from the previous step (the first step of a segment: its
        posterior).
    x_post, P_post : ndarray (n,), (n, n)
        The estimate after the update at ``t``.
    F : ndarray (n, n)
        ``d x_prior / d x_post`` of the previous step (the identity for the first).
    """

    t: float
    x_prior: Array
    P_prior: Array
    x_post: Array
    P_post: Array
    F: Array


@dataclass
class Smoothed:
    """The smoothed estimates of one segment.

    Attributes
    ----------
    t : ndarray (K,)
        Epochs, s.
    x : ndarray (K, n)
        Smoothed states.
    P : ndarray (K, n, n)
        Their covariances.
    C : ndarray (K, n, n)
        Smoother gains (the last one zero).
    """

    t: Array
    x: Array
    P: Array
    C: Array

    def estimates(self, object_id: str = "") -> list[StateEstimate]:
        """Return the smoothed estimates as `types.StateEstimate` (copies)."""
        return [StateEstimate(float(t), x.copy(), P.copy(), object_id)
                for t, x, P in zip(self.t, self.x, self.P, strict=True)]


def rts(steps: Sequence[FilterStep]) -> Smoothed:
    """Rauch-Tung-Striebel smoothing of one segment of fused steps (module docstring).

    Parameters
    ----------
    steps : sequence of FilterStep
        The forward filter's steps, in epoch order, one segment (no re-initialisation).

    Returns
    -------
    Smoothed
    """
    k = len(steps)
    if not k:
        return Smoothed(np.zeros(0), np.zeros((0, 0)), np.zeros((0, 0, 0)),
                        np.zeros((0, 0, 0)))
    n = steps[0].x_post.size
    x = np.array([s.x_post for s in steps], dtype=float)
    P = np.array([s.P_post for s in steps], dtype=float)
    C = np.zeros((k, n, n))
    for i in range(k - 2, -1, -1):
        nxt = steps[i + 1]
        # C = P_post F^T P_prior^-1, by a solve with the symmetric prior
        C[i] = np.linalg.solve(nxt.P_prior, nxt.F @ P[i]).T
        x[i] = x[i] + C[i] @ (x[i + 1] - nxt.x_prior)
        Pi = P[i] + C[i] @ (P[i + 1] - nxt.P_prior) @ C[i].T
        P[i] = 0.5 * (Pi + Pi.T)
    return Smoothed(np.array([s.t for s in steps], dtype=float), x, P, C)


def steps_from_estimates(estimates: Sequence[StateEstimate], f: Placeholder,
                         noise: NoiseFunction, sigma_bound: float = 0.0) -> list[FilterStep]:
    """Rebuild a filter's steps from its posteriors (module docstring).

    Each estimate is predicted to the next one's epoch as the filter predicted it
    (`tracker.Tracker._step`): ``x_prior, F = f(x_post, dt, t)``,
    ``P_prior = F P_post F^T + Q`` symmetrised, then `ekf.bound_covariance`.

    Parameters
    ----------
    estimates : sequence of StateEstimate
        The posteriors of one segment, in epoch order, distinct epochs.
    f : callable
        The filter's motion model ``f(x, dt, t0) -> (x_new, F)`` (`config.motion`).
    noise : callable
        ``noise(x, dt) -> Q`` (`tracker_noise` gives the `Tracker`'s).
    sigma_bound : float
        The filter's covariance bound (`filter_options.NoiseOptions.sigma_bound`).

    Returns
    -------
    list of FilterStep
    """
    out: list[FilterStep] = []
    prev: StateEstimate | None = None
    for e in estimates:
        x_post = np.asarray(e.x, dtype=float)
        P_post = np.asarray(e.P, dtype=float)
        if prev is None:
            out.append(FilterStep(e.t, x_post.copy(), P_post.copy(), x_post.copy(),
                                  P_post.copy(), np.eye(x_post.size)))
        else:
            dt = e.t - prev.t
            xp, F = f(np.asarray(prev.x, dtype=float), dt, prev.t)
            P = F.dot(np.asarray(prev.P, dtype=float)).dot(F.T) + noise(xp, dt)
            P = P + P.T
            P *= 0.5
            if sigma_bound:
                P = bound_covariance(xp, P, sigma_bound)
            out.append(FilterStep(e.t, np.asarray(xp, dtype=float), P, x_post.copy(),
                                  P_post.copy(), np.asarray(F, dtype=float)))
        prev = e
    return out


def tracker_noise(tracker: Tracker) -> NoiseFunction:
    """Return the `Tracker`'s process noise as ``noise(x, dt)`` (`Tracker.process_noise`)."""
    def noise(_x: Array, dt: float) -> Array:
        return tracker.process_noise(dt)

    return noise


class TrackerRecorder:
    """Keeps the chain of a `Tracker`'s fused estimates for smoothing (module docstring).

    Feed measurements through `process` instead of ``tracker.process`` (or tell it what the
    tracker did with `observe`); the tracker's behaviour is unchanged. `segments` are the
    chains between re-initialisations; each ends at the tracker's current estimate.

    Parameters
    ----------
    tracker : Tracker
        The filter to record.
    """

    def __init__(self, tracker: Tracker) -> None:
        self.tracker = tracker
        self.segments: list[list[StateEstimate]] = [[]]
        self._ekf: ExtendedKalmanFilter | None = tracker.ekf

    def process(self, m: Measurement) -> Outcome:
        """``tracker.process(m)``, recording what it fused (and what it undid)."""
        out = self.tracker.process(m)
        self.observe(m, out)
        return out

    def observe(self, m: Measurement, out: Outcome) -> None:
        """Record what the tracker did with `m` (`out`), when something else fed it `m`."""
        if self.tracker.ekf is not self._ekf:  # a new filter: IOD (first or again), reset
            self._ekf = self.tracker.ekf
            if self.segments[-1]:
                self.segments.append([])
        fused = ([out.estimate] if out.estimate is not None else []) + out.fused_again
        if fused or out.rolled_back:
            chain = self.segments[-1]
            chain[:] = [e for e in chain if e.t < m.t]  # steps at or after m.t were undone
            chain.extend(fused)

    def reset(self) -> None:
        """Start a new segment: the tracker was reset (a backwards clock jump)."""
        self._ekf = self.tracker.ekf
        if self.segments[-1]:
            self.segments.append([])

    def steps(self) -> list[list[FilterStep]]:
        """Return the recorded segments as `FilterStep` lists (`steps_from_estimates`)."""
        t = self.tracker
        return [steps_from_estimates(seg, t.f, tracker_noise(t), t.config.noise.sigma_bound)
                for seg in self.segments if seg]

    def smooth(self) -> list[Smoothed]:
        """Return the RTS-smoothed segments (`rts`)."""
        return [rts(s) for s in self.steps()]


def smooth_estimates(estimates: Sequence[StateEstimate], f: Placeholder, noise: NoiseFunction,
                     sigma_bound: float = 0.0) -> Smoothed:
    """Smooth one segment of published estimates: `steps_from_estimates`, then `rts`."""
    return rts(steps_from_estimates(estimates, f, noise, sigma_bound))

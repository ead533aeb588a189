"""The paper's "placeholder model alone" arm: Monte Carlo of the placeholder dynamics.

Over an ensemble drawn from an estimate and its covariance (paper section 3, 200
particles).
"""

from __future__ import annotations

import numpy as np

from ssa_fusion.core.motion import dynamics

N_PARTICLES = 200


def placeholder_ensemble(model: str, x0: np.ndarray, P0: np.ndarray, dt: np.ndarray,
                         seed: int = 0, n_particles: int = N_PARTICLES,
                         pole_frame: np.ndarray | None = None,
                         **params: float) -> tuple[np.ndarray, np.ndarray]:
    """Return the mean (k, n) and covariance (k, n, n) of a propagated ensemble.

    `n_particles` draws from N(x0, P0) propagated by the placeholder `model` ("kepler" =
    two-body) to offsets `dt` (k,) s from the epoch of x0 (dt[0] may be 0); an orbit's J2
    about the pole of `pole_frame` (`dynamics.propagate`). Deterministic for a given `seed`.
    """
    n = len(x0)
    rng = np.random.default_rng([seed, 7])
    L = np.linalg.cholesky(0.5 * (P0 + P0.T) + 1e-30 * np.eye(n))
    parts = np.asarray(x0) + rng.standard_normal((n_particles, n)) @ L.T
    name = "two_body" if model == "kepler" else model
    traj = dynamics.propagate(name, parts, np.asarray(dt, dtype=float), rtol=1e-10,
                              atol=1e-12, pole_frame=pole_frame, **params)  # (k, p, n)
    mean = traj.mean(axis=1)
    dev = traj - mean[:, None, :]
    cov = np.einsum("kpi,kpj->kij", dev, dev) / (n_particles - 1)
    return mean, cov

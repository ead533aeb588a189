"""Simulated truth and measurements of a scenario.

What sensor_sim publishes and what the offline experiments consume.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ssa_fusion.core.base.types import Kind
from ssa_fusion.core.earth.frames import wrap_2pi
from ssa_fusion.sim.scenarios import Scenario, measurement_model, truth_states


@dataclass
class Simulation:
    """Sampled truth and measurements on the scenario's cadence.

    t : (N,) epochs, s; x : (N, n) true states; z_true : (N, m) noise-free measurements;
    z : (N, m) measurements with noise; sigma : (m,) noise standard deviations;
    in_gap : (N,) True where the sensor is out (those measurements are withheld).
    """

    scenario: Scenario
    t: np.ndarray
    x: np.ndarray
    z_true: np.ndarray
    z: np.ndarray
    sigma: np.ndarray
    in_gap: np.ndarray

    @property
    def R(self) -> np.ndarray:
        """The measurement noise covariance (m, m): diag(sigma^2)."""
        return np.diag(self.sigma**2)

    @property
    def gap_index(self) -> np.ndarray:
        """The indices of the epochs in the gap."""
        return np.flatnonzero(self.in_gap)


def epochs(s: Scenario, with_after: bool = True) -> np.ndarray:
    """Measurement epochs: tracking, gap, and (optionally) tracking after the gap."""
    span = s.track_s + s.gap_s + (s.after_s if with_after else 0.0)
    n = round(float(span) / s.cadence_s)
    return s.t0 + s.cadence_s * np.arange(n + 1)


def resolve_noise(s: Scenario, z_true: np.ndarray, t: np.ndarray) -> np.ndarray:
    """Return the noise sigma per channel.

    `noise_sigma`, or `noise_rel` x RMS of the channel over the tracking window (only data
    before the gap is used).
    """
    if s.noise_rel > 0.0:
        track = z_true[t < s.gap_start]
        rms: np.ndarray = np.sqrt(np.mean(track**2, axis=0))
        return s.noise_rel * rms
    return np.asarray(s.noise_sigma, dtype=float)


def simulate(s: Scenario, seed: int = 0, with_after: bool = True) -> Simulation:
    """Truth, noise-free and noisy measurements, and the gap mask, reproducible by `seed`."""
    t = epochs(s, with_after)
    x = truth_states(s, t)
    model = measurement_model(s)
    z_true = np.array([model.h(xi, ti) for xi, ti in zip(x, t, strict=True)])
    sigma = resolve_noise(s, z_true, t)
    rng = np.random.default_rng(seed)
    z = z_true + rng.standard_normal(z_true.shape) * sigma
    if s.kind == Kind.RANGE_AZ_EL:  # azimuth stays in [0, 2pi)
        z[:, 1] = wrap_2pi(z[:, 1])
    in_gap = (t >= s.gap_start) & (t < s.gap_end)
    return Simulation(s, t, x, z_true, z, sigma, in_gap)



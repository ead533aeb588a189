"""Catalogs with planted close approaches, for the conjunction tests (no ROS)."""

from __future__ import annotations

import math

import numpy as np

from ssa_fusion.core.base.constants import R_EARTH
from ssa_fusion.core.conjunction.ephemeris import StateEphemeris
from ssa_fusion.core.motion.dynamics import elements_to_state

T0 = 1.7536e9
"""Epoch of the planted catalogs (2025-07-28 UTC), Unix s."""


def planted(seed: int, n_background: int, n_pairs: int, span_s: float) -> StateEphemeris:
    """A LEO catalog with pairs planted to pass within ~0-14 km of each other (J2)."""
    rng = np.random.default_rng(seed)
    states, epochs = [], []
    for _ in range(n_background):
        states.append(elements_to_state(R_EARTH + rng.uniform(400, 900), rng.uniform(0, 0.01),
                                        rng.uniform(0, math.pi), *rng.uniform(0, 2 * math.pi, 3)))
        epochs.append(T0)
    for _ in range(n_pairs):
        tc = T0 + rng.uniform(0.05, 0.95) * span_s
        a = elements_to_state(R_EARTH + rng.uniform(400, 900), rng.uniform(0, 0.01),
                              rng.uniform(0, math.pi), *rng.uniform(0, 2 * math.pi, 3))
        r_hat = a[:3] / np.linalg.norm(a[:3])
        th = math.radians(rng.choice([rng.uniform(0.5, 5.0), rng.uniform(5.0, 175.0)]))
        v = a[3:] * math.cos(th) + np.cross(r_hat, a[3:]) * math.sin(th)  # turned about r
        offset = rng.normal(size=3)
        b = np.r_[a[:3] + offset / np.linalg.norm(offset) * rng.uniform(0.0, 14.0),
                  v * (1 + rng.uniform(-0.01, 0.01))]
        states += [a, b]
        epochs += [tc, tc]
    ids = [str(k) for k in range(len(states))]
    back = StateEphemeris(ids, states, epochs, model="j2")
    x0 = back.exact(np.arange(len(ids)), np.full(len(ids), T0))
    return StateEphemeris(ids, x0, np.full(len(ids), T0), model="j2")

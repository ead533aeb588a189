"""The BOP-DMD variant of the gap surrogate (`studies.bopdmd`) on an analytic signal."""

import math

import numpy as np
import pytest

from ssa_fusion.studies import bopdmd


def test_bopdmd_on_irregular_samples_recovers_frequency_and_decay():
    pytest.importorskip("pydmd")
    rng = np.random.default_rng(2)
    lam, om = 0.05, 2 * math.pi  # decay 1/time unit, one cycle per time unit
    t = np.sort(np.concatenate([s + rng.uniform(0, 0.1, 6) for s in rng.uniform(0, 6, 12)]))

    def signal(tt: np.ndarray) -> np.ndarray:
        e = np.exp(-lam * tt)
        return np.stack([e * np.cos(om * tt), e * np.sin(om * tt), 0.5 * e * np.cos(om * tt)],
                        axis=1)

    forecast = bopdmd.bopdmd_fit(t, signal(t), bopdmd.BopConfig(rank=2, trials=10),
                                   init_alpha=[-0.1 + 6j, -0.1 - 6j])
    t_out = np.linspace(6.0, 8.0, 30)
    mean, var = forecast(t_out)
    np.testing.assert_allclose(mean, signal(t_out), atol=2e-3)
    assert np.all(var >= 0.0)

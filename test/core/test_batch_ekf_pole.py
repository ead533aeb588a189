"""BatchEKF.propagate moves each object with J2 about the pole of its own epoch's hour
(`frames.pole_frame`), whether the objects' epochs share one hour or not, and with a
non-finite epoch read as 0 (as the per-object path reads it)."""

from __future__ import annotations

from dataclasses import asdict

import numpy as np
import pytest

from ssa_fusion.core.catalog.batch_ekf import BatchEKF
from ssa_fusion.core.earth import frames
from ssa_fusion.core.earth.stations import NETWORKS, SENSORS
from ssa_fusion.core.motion.propagation import integrate_stm
from ssa_fusion.params import settings
from ssa_fusion.params.defaults import CATALOG_FILTER

RADARS = [SENSORS[s] for s in NETWORKS["radar_network"]]
NETWORK = {s.station.name: s.station for s in RADARS}
T0 = 1.75e9 - 1.75e9 % 3600.0  # a whole hour


@pytest.mark.parametrize("epochs", [
    T0 + np.linspace(0.0, 3599.0, 7),  # one hour
    T0 + np.linspace(0.0, 5 * 3600.0, 7),  # six
    np.r_[T0 + np.linspace(0.0, 600.0, 6), np.nan],  # one, and one not finite
])
def test_each_object_takes_the_pole_of_its_hour(epochs):
    options = settings.filter_options({**asdict(CATALOG_FILTER), "station": ",".join(NETWORK)})
    ekf = BatchEKF(options, list(NETWORK.values()))
    n = epochs.size
    rng = np.random.default_rng(4)
    x = np.c_[rng.normal(size=(n, 3)) * 100 + [7000.0, 0, 0], rng.normal(size=(n, 3)) * 0.1
              + [0, 7.5, 0]]
    dt = rng.uniform(30.0, 900.0, n)
    x1, F, ok = ekf.propagate(x, dt, epochs)
    for i in range(n):
        pole = frames.pole_frame(float(np.nan_to_num(epochs[i])))
        want = integrate_stm(options.motion.motion_model, x[i:i + 1], dt[i:i + 1],
                             options.motion.max_step_s, pole_frame=pole)
        assert np.array_equal(x1[i], want[0][0]) and np.array_equal(F[i], want[1][0])
    assert ok.all()

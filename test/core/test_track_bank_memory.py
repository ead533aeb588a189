"""TrackBank's memory follows what it holds: a measurement waiting in an IOD batch keeps its
own few numbers, not the arrays of the batch it came in; an object that never completes an
IOD batch keeps one pass's measurements, whatever the passes; `TrackBank.nbytes` counts them."""

from __future__ import annotations

import gc
import math
import tracemalloc
from dataclasses import asdict

import numpy as np

from ssa_fusion.core.base.types import Cause
from ssa_fusion.core.catalog.track_bank import TrackBank
from ssa_fusion.core.earth.stations import NETWORKS, SENSORS
from ssa_fusion.params import settings
from ssa_fusion.params.defaults import CATALOG_FILTER

RADARS = [SENSORS[s] for s in NETWORKS["radar_network"]]
NETWORK = {s.station.name: s.station for s in RADARS}


def test_a_pending_iod_measurement_does_not_keep_its_batch():
    options = settings.filter_options({**asdict(CATALOG_FILTER),
                                       "station": ",".join(NETWORK)})
    bank = TrackBank(options, NETWORK)
    m = 50_001  # one measurement of a new object, then many the bank refuses (no station)
    t = 1.75e9 + np.arange(m, dtype=float)
    z = np.tile([1000.0, 1.0, 0.5], (m, 1))
    R = np.tile(np.diag([1e-4, 1e-8, 1e-8]), (m, 1, 1))
    frames = [RADARS[0].station.name] + ["nowhere"] * (m - 1)
    tracemalloc.start()
    try:
        res = bank.process(t, ["lonely"] * m, frames, z, R)
        assert res.cause[0] == Cause.IOD_PENDING and res.cause[1] == Cause.REJECTED_FRAME
        del res, t, z, R, frames
        gc.collect()
        held, _ = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    # the batch's own copies of t, z and R are 5.2 MB; the pending measurement ~1 kB
    assert held < 50_000, held


def _bank() -> TrackBank:
    options = settings.filter_options({**asdict(CATALOG_FILTER),
                                       "station": ",".join(NETWORK)})
    return TrackBank(options, NETWORK)


def test_an_object_that_never_initiates_keeps_one_pass_at_most():
    bank = _bank()
    iod = bank.config.iod
    short = iod.iod_samples - 1  # each pass one measurement short of an IOD batch
    assert math.isfinite(iod.iod_max_span_s) and iod.iod_max_span_s < 3600.0
    arrays = bank.nbytes
    station = RADARS[0].station.name
    for k in range(300):  # passes an hour apart: each starts the batch again
        t = 1.75e9 + 3600.0 * k + 10.0 * np.arange(short)
        res = bank.process(t, ["never"] * short, [station] * short,
                           np.tile([1000.0, 1.0, 0.5], (short, 1)),
                           np.tile(np.diag([1e-4, 1e-8, 1e-8]), (short, 1, 1)))
        assert set(res.cause) == {Cause.IOD_PENDING} and not res.fused.size
    assert bank.pending_iod == short
    held = bank.nbytes - arrays
    assert 0 < held < short * 2_000, held  # its own few numbers each (~0.8 kB), no history

"""initiation.finish_razel solves many IOD batches at once as OrbitInitiator.finish solves
each alone: the same states and covariances (to rounding), the same causes when a batch
fails, and other kinds passed to their own initiator."""

from __future__ import annotations

from dataclasses import asdict
from pathlib import Path

import numpy as np

from ssa_fusion.core.base.types import Cause, Kind, Measurement
from ssa_fusion.core.catalog.batch_ekf import BatchEKF
from ssa_fusion.core.earth.stations import NETWORKS, SENSORS
from ssa_fusion.core.earth.timescales import UNIX_EPOCH_JD
from ssa_fusion.core.filter.initiation import InitialState, OrbitInitiator, finish_razel
from ssa_fusion.core.measure import iod
from ssa_fusion.core.measure.measurement import PositionModel, StationModels
from ssa_fusion.formats import element_sets as catalog
from ssa_fusion.params import settings
from ssa_fusion.params.defaults import CATALOG_FILTER
from ssa_fusion.sim import survey

SAMPLE = Path(__file__).resolve().parents[2] / "config" / "catalogs" / "sample.tle"
RADARS = [SENSORS[s] for s in NETWORKS["radar_network"]]
NETWORK = {s.station.name: s.station for s in RADARS}
P0 = (1.0, 1.0, 1.0, 1e-3, 1e-3, 1e-3)


def _ekf() -> BatchEKF:
    options = settings.filter_options({**asdict(CATALOG_FILTER), "station": ",".join(NETWORK)})
    return BatchEKF(options, list(NETWORK.values()))


def _batches(samples: int) -> list[list[Measurement]]:
    """Complete IOD batches of a radar survey of a few LEO objects (`OrbitInitiator.collect`)."""
    base = catalog.read_catalog(SAMPLE)[0]
    obs = survey.observe_catalog(survey.synthetic_catalog(base, 5, seed=2), RADARS,
                                 base.epoch_unix, 4 * 3600.0, seed=3)
    collectors: dict[int, OrbitInitiator] = {}
    out = []
    for t, k, s, z in zip(obs.t.tolist(), obs.obj.tolist(), obs.sensor.tolist(), obs.z,
                          strict=True):
        init = collectors.setdefault(k, OrbitInitiator(None, None, 6))  # type: ignore[arg-type]
        m = Measurement(t, z.copy(), RADARS[s].R.copy(), kind=Kind.RANGE_AZ_EL,
                        frame_id=RADARS[s].station.name)
        got = init.collect(m, samples)
        if isinstance(got, list):
            out.append(got)
    return out


def _initiator(ekf: BatchEKF) -> OrbitInitiator:
    def one(x, dt, t0):
        x1, F, _ = ekf.propagate(np.asarray(x)[None], np.array([dt]), np.array([t0]))
        return x1[0], F[0]

    return OrbitInitiator(one, StationModels(NETWORK, UNIX_EPOCH_JD), 6, iod.itrs_to_gcrs_at)


def test_many_batches_at_once_equal_each_alone():
    ekf = _ekf()

    def many(x, dt, t0):
        x1, F, _ = ekf.propagate(x, dt, t0)
        return x1, F

    batches = _batches(3) + _batches(5)
    assert len(batches) > 40
    # an outlier (a range of 1e6 km): no Earth orbit; a non-finite sample: FloatingPointError
    far = [Measurement(b.t, b.z * [1e3, 1, 1], b.R, kind=b.kind, frame_id=b.frame_id)
           for b in batches[0]]
    nan = [Measurement(b.t, b.z * [1, 1, np.nan], b.R, kind=b.kind, frame_id=b.frame_id)
           for b in batches[1]]
    # a batch of positions: its initiator's own finish (finite differences)
    pos = [Measurement(b.t, b.z, b.R, kind=Kind.POSITION) for b in batches[2]]
    every = [far, nan, pos, *batches[3:]]
    initiators = [_initiator(ekf) for _ in every]
    initiators[2] = OrbitInitiator(initiators[2].f, PositionModel(), 6)
    got = finish_razel(initiators, every, P0, many, iod.itrs_to_gcrs_at)
    want = [init.finish(b, P0) for init, b in zip(initiators, every, strict=True)]
    assert got[0] == want[0] and got[0][0] == Cause.IOD_FAILED and "bound orbit" in got[0][1]
    assert got[1] == want[1] and got[1][0] == Cause.IOD_FAILED
    solved = 0
    for g, w in zip(got[2:], want[2:], strict=True):
        assert isinstance(g, InitialState) and isinstance(w, InitialState)
        assert g.t == w.t
        np.testing.assert_allclose(g.x, w.x, rtol=1e-13)
        np.testing.assert_allclose(g.P, w.P, rtol=1e-10, atol=1e-13 * np.abs(w.P).max())
        solved += 1
    assert solved == len(every) - 2

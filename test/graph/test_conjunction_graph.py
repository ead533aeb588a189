"""Graph test of the conjunction node alone, over DDS: the test process drives sim time on
/clock and publishes a catalog's estimates (EstimateBatch, SENSOR) with planted close
approaches, plus a forecast and a non-finite row. The node refuses the bad row by cause,
never takes the forecast (content filter), and publishes on /ssa/conjunctions exactly the
approaches the in-process screening of the same estimates finds (same pairs, TCAs, misses,
Pc), with both covariances; it writes a CDM of each approach that reads back with its Pc. A
later estimate of one object re-screens that object alone.
"""

from __future__ import annotations

import numpy as np
import pytest
from planted_conjunctions import T0, planted
from rosgraph_msgs.msg import Clock
from ssa_fusion_msgs.msg import ConjunctionBatch, EstimateBatch
from test_faults import Diag, publisher

from ssa_fusion.core.base import types
from ssa_fusion.core.base.rows import EstimateRows
from ssa_fusion.core.conjunction.ephemeris import StateEphemeris
from ssa_fusion.core.conjunction.screening import ScreeningConfig, screen
from ssa_fusion.core.conjunction.watch import WatchConfig
from ssa_fusion.formats.ccsds.cdm import read_cdm
from ssa_fusion.ros import messages
from ssa_fusion.ros.qos import CATALOG_QOS

HORIZON = 6 * 3600.0
P = np.diag([1e-2] * 3 + [1e-8] * 3)  # 100 m, 0.1 m/s


def _batch(ids, t, x, source=types.UpdateSource.SENSOR) -> EstimateBatch:
    n = len(ids)
    rows = EstimateRows(np.asarray(t, dtype=float), list(ids), np.asarray(x),
                        np.broadcast_to(P, (n, 6, 6)).copy(), np.zeros(n), source,
                        messages.shard_keys(list(ids)))
    return messages.estimate_batch_to_msg(rows)


def test_the_node_publishes_the_screenings_approaches_and_their_cdms(ros_graph, tmp_path):
    g = ros_graph
    cdm_dir = tmp_path / "cdm"
    params = {"use_sim_time": True, "distance": 10000.0, "horizon": HORIZON,
              "rescreen_period": 60.0, "hard_body_radius": 20.0, "cdm_dir": str(cdm_dir),
              "cdm_min_pc": 0.0}
    g.start_node("conjunction", params=params)
    diag = Diag(g)
    got: list[ConjunctionBatch] = g.collect(ConjunctionBatch, "/ssa/conjunctions", CATALOG_QOS)
    clock = publisher(g, Clock, "/clock", ("conjunction",))
    est = publisher(g, EstimateBatch, "/ssa/estimate_batch", ("conjunction",))
    eph = planted(seed=9, n_background=30, n_pairs=10, span_s=HORIZON)
    ids = list(eph.object_ids)
    est.publish(_batch(ids, eph.t0, eph.x0))  # before the clock runs: nothing screened
    bad = eph.x0[:1].copy()
    bad[0, 2] = np.nan
    est.publish(_batch(["999"], [T0], bad))
    falling = eph.x0[:1].copy()
    falling[0, 3:] *= 0.3  # at its apogee, its perigee deep inside the Earth
    est.publish(_batch(["998"], [T0], falling))
    est.publish(_batch(ids[:2], eph.t0[:2], eph.x0[:2], types.UpdateSource.FORECAST))
    diag.wait(g, "conjunction", {"received": len(ids), "rejected_nonfinite": 1,
                                 "rejected_implausible": 1})
    clock.publish(Clock(clock=messages.seconds_to_stamp(T0 + 1.0)))
    g.wait_for(lambda: len(got) >= 1, 60.0, "a ConjunctionBatch")
    first = messages.conjunction_batch_from_msg(got[0])
    covs = np.broadcast_to(P, (len(ids), 6, 6))
    want = screen(StateEphemeris(ids, eph.x0, eph.t0, covariance=covs,
                                 max_step_s=WatchConfig().max_step_s), T0 + 1.0,
                  T0 + 1.0 + HORIZON, ScreeningConfig(distance_km=10.0))
    assert len(want) >= 5 and sorted(first.screened) == sorted(ids)
    a = first.approaches
    pairs = sorted(zip(a.primary_ids, a.secondary_ids, strict=True))
    assert pairs == sorted(zip(want.primary_ids, want.secondary_ids, strict=True))
    assert sorted(a.tca) == pytest.approx(sorted(want.tca), abs=1e-6)
    # the node flies from nodes on its fixed grid, this screening from T0 + 1: 150 s DOP853
    # steps from other epochs agree to ~2e-9 relative (0.1 mm at most)
    assert sorted(a.miss_km) == pytest.approx(sorted(want.miss_km), abs=1e-7)
    assert a.p1 is not None and np.isfinite(a.p1).all()
    # the node's covariances take 300 s steps (WatchConfig.covariance_step_s): ~1e-7 relative
    assert sorted(first.log10_pc) == pytest.approx(sorted(want.log10_pc(0.02)), rel=1e-6)
    # a CDM per approach (cdm_min_pc 0), with the Pc the message carries
    diag.wait(g, "conjunction", {"cdms_written": len(a)})
    cdms = sorted(cdm_dir.glob("*.cdm"))
    assert len(cdms) == len(a)
    read = read_cdm(cdms[0])
    k = next(i for i in range(len(a)) if read.message_id.startswith(a.primary_ids[i] + "_conj_"
                                                                   + a.secondary_ids[i]))
    assert read.pc == pytest.approx(10 ** first.log10_pc[k], rel=1e-6)
    # a later estimate of one object: that object alone is re-screened
    one = ids[int(want.primary[0])]
    t1 = T0 + 120.0
    x1 = eph.exact([ids.index(one)], [t1])
    clock.publish(Clock(clock=messages.seconds_to_stamp(t1)))
    est.publish(_batch([one], [t1], x1))
    clock.publish(Clock(clock=messages.seconds_to_stamp(t1 + 61.0)))
    g.wait_for(lambda: len(got) >= 2, 60.0, "a second ConjunctionBatch")
    second = messages.conjunction_batch_from_msg(got[1])
    assert second.screened == [one]
    assert second.approaches.primary_ids == [one] * len(second.approaches)
    assert len(second.approaches) >= 1

"""Graph test of the catalog_surrogate node alone: the test process drives sim time on
/clock and publishes the filter's estimates of two objects (EstimateBatch, a row each), plus
bad ones (non-finite,
negative or enormous covariances, an object beyond `max_objects`). Every bad
estimate is refused by cause on /diagnostics (or never delivered: the content filter), the
node lives on, and the forecast it publishes through the gap that follows equals the
in-process `core.gaps.forecaster.GapForecaster` fed the same estimates (through the same messages).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
from rosgraph_msgs.msg import Clock
from ssa_fusion_msgs.msg import EstimateBatch
from test_faults import Diag, publisher

from ssa_fusion.core.base import types
from ssa_fusion.core.base.rows import EstimateRows
from ssa_fusion.core.catalog.gap_bank import CATALOG_RESIDUAL
from ssa_fusion.core.gaps.forecaster import GapForecaster
from ssa_fusion.core.motion import dynamics
from ssa_fusion.nodes.kit.progress import PROGRESS_QOS, TAKEN_ESTIMATES, TOPIC_PROGRESS
from ssa_fusion.nodes.kit.shards import shard_problem, shard_range
from ssa_fusion.ros import messages
from ssa_fusion.ros.interfaces import DiagnosticStatus
from ssa_fusion.ros.qos import CATALOG_QOS
from ssa_fusion.sim.scenarios import ISS_ELEMENTS

T0 = 1.7e9  # Unix s
PERIOD = 300.0
P = np.diag([1e-4] * 3 + [1e-10] * 3)


def _object_of_shard(shard: int, shards: int, other: bool = False) -> str:
    """An object id of shard `shard` of `shards` (`other`: of another shard) whose key is
    not the last of the range."""
    lo, hi = shard_range(shard, shards)
    return next(o for o in (f"7{k:04d}" for k in range(1000))
                if (lo <= messages.shard_key(o) < hi) != other)


def _estimates(oid: str) -> list[types.StateEstimate]:
    """Pass ends' worth of a J2 orbit: 4 passes of 5 min every 97 min, 60 s apart, as the
    filter's SENSOR estimates (through the message, m <-> km, as the node gets them)."""
    x0 = np.array(dynamics.elements_to_state(**ISS_ELEMENTS))
    t = np.concatenate([s + np.arange(0.0, 300.0, 60.0) for s in 5820.0 * np.arange(4)])
    x = dynamics.propagate("j2", x0, np.r_[-60.0, t])[1:]
    return [messages.estimate_from_msg(messages.estimate_to_msg(types.StateEstimate(
        t=T0 + ti, x=xi, P=P, object_id=oid, update_source=types.UpdateSource.SENSOR)))
        for ti, xi in zip(t, x, strict=True)]


def _batch(e: types.StateEstimate, key: int | None = None) -> EstimateBatch:
    """`e` as a one-row EstimateBatch (its shard_key `key`, default its id's), of the key
    range of the shard (of 2) the key is in."""
    k = messages.shard_key(e.object_id) if key is None else key
    rows = EstimateRows(np.array([e.t]), [e.object_id], np.asarray(e.x)[None],
                        np.asarray(e.P)[None], np.zeros(1), types.UpdateSource(e.update_source),
                        np.array([k], np.uint32))
    return messages.estimate_batch_to_msg(rows, shard_range(int(k > shard_range(0, 2)[1]), 2))


def forecast_sink(g) -> list[types.StateEstimate]:
    """Subscribe the probe to /ssa/estimate_batch; return the list its forecasts join."""
    forecasts: list[types.StateEstimate] = []

    def on_batch(m: EstimateBatch) -> None:
        rows = messages.estimate_batch_from_msg(m)
        if rows.update_source == types.UpdateSource.FORECAST:
            forecasts.extend(types.StateEstimate(t=float(t), x=x, P=P_, object_id=o)
                             for t, x, P_, o in zip(rows.t, rows.x, rows.P, rows.object_id,
                                                    strict=True))

    g.probe.create_subscription(EstimateBatch, "/ssa/estimate_batch", on_batch, CATALOG_QOS)
    return forecasts


def test_bad_estimates_are_refused_and_the_gap_forecast_equals_the_core(ros_graph):
    g = ros_graph
    span = 3 * 5820.0  # first to last pass end: only the last one may fit
    params = {"use_sim_time": True, "shards": 2, "shard": 0, "hold": 0.0,
              "predict_period": PERIOD, "min_anchors": 3, "min_span": span - 1.0,
              "fit_budget": 1.0, "max_objects": 1,
              "physics_fit": False}  # the learned residual alone: the earlier gaps get none
    node = g.start_node("catalog_surrogate", params=params)
    diag = Diag(g)
    forecasts = forecast_sink(g)
    clock = publisher(g, Clock, "/clock", ("catalog_surrogate",))
    est = publisher(g, EstimateBatch, "/ssa/estimate_batch", ("catalog_surrogate",))

    def tick(t: float) -> None:
        clock.publish(Clock(clock=messages.seconds_to_stamp(t)))

    mine, theirs = _object_of_shard(0, 2), _object_of_shard(0, 2, other=True)
    good = _estimates(mine)
    tick(T0)
    # bad input first: each refused by cause (or kept away by the content filter)
    x_nan = good[0].x.copy()
    x_nan[2] = float("nan")
    nan = _batch(replace(good[0], x=x_nan))
    no_id = _batch(replace(good[0], object_id=""))
    wrong_key = _batch(good[0], key=messages.shard_key(mine) + 1)  # in range, not the CRC
    future = _batch(replace(good[0], t=T0 + 1e5))
    forecast = _batch(replace(good[0], update_source=2))
    other = _batch(replace(good[0], object_id=theirs))
    negative = _batch(replace(good[0], P=-P))
    huge = _batch(replace(good[0], P=1e300 * np.eye(6)))
    for m in (nan, no_id, wrong_key, future, forecast, other, negative, huge):
        est.publish(m)
    diag.wait(g, "catalog_surrogate", {"rejected_nonfinite": 1, "rejected_object_id": 1,
                                       "rejected_shard_key": 1, "rejected_future": 1,
                                       "rejected_covariance": 1, "rejected_implausible": 1})
    # then the object's passes, sim time running every minute, and on into the gap after
    # the last: a clock and an estimate arrive on separate topics, so the next minute's
    # clock waits until the node has taken the minute's estimates (its /lockstep progress,
    # as sensor_sim's lockstep does): the same order however loaded the machine
    taken: dict[str, int] = {}
    g.probe.create_subscription(
        DiagnosticStatus, TOPIC_PROGRESS,
        lambda m: taken.update({m.name: int(next(
            (kv.value for kv in m.values if kv.key == TAKEN_ESTIMATES), "0"))}), PROGRESS_QOS)
    g.wait_for(lambda: "catalog_surrogate" in taken, 10.0, "the node's progress")
    base = taken["catalog_surrogate"]  # the bad estimates it took
    end = good[-1].t
    k = 0
    for t in T0 + 60.0 * np.arange(int((end - T0) / 60.0) + 61):
        tick(float(t))
        sent = k
        while k < len(good) and good[k].t <= t:
            est.publish(_batch(good[k]))
            k += 1
        if k > sent:
            g.wait_for(lambda k=k: taken["catalog_surrogate"] >= base + k, 10.0,
                       "the node to take the minute's estimates")
    c = diag.wait(g, "catalog_surrogate", {"received": len(good), "fits_made": 1}, 30.0)
    g.wait_for(lambda: len(forecasts) >= 9, 20.0, "the gap's forecasts")
    assert c.get("ignored_not_sensor", "0") == c.get("ignored_other_shard", "0") == "0"
    # (an earlier pass end the node saw in time was refused: its pass ends span too little)
    ref = GapForecaster.for_model("j2", PERIOD, replace(CATALOG_RESIDUAL, min_anchors=3,
                                                        min_span_s=span - 1.0))
    for e in good:
        ref.on_estimate(e.t, e.x, e.P)
    got = [e for e in forecasts if e.t > T0]
    t = np.array([f.t for f in got])
    assert t[0] - PERIOD < end + 600.0 <= t[0]  # the grid's first epoch past pass_break
    assert np.all(np.diff(t) == PERIOD)
    for f in got:
        assert f.object_id == mine and f.t - end >= 600.0
        want = messages.estimate_from_msg(messages.estimate_to_msg(types.StateEstimate(
            t=f.t, x=ref.forecast(f.t)[0], P=ref.forecast(f.t)[1], object_id=mine)))
        np.testing.assert_allclose(f.x, want.x, rtol=1e-9, atol=1e-9)
        np.testing.assert_allclose(f.P, want.P, rtol=1e-9, atol=1e-15)
    # an object more than max_objects (1): refused by cause, the node lives on
    flood = next(o for o in (f"8{k:04d}" for k in range(1000))
                 if shard_problem(messages.shard_key(o), o, 0, 2) is None)
    est.publish(_batch(replace(good[-1], object_id=flood)))
    diag.wait(g, "catalog_surrogate", {"rejected_bank_full": 1})
    assert node.popen.poll() is None

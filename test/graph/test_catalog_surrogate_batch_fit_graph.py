"""Graph test of the catalog_surrogate with ``gap_forecast`` batch_fit: the test process
drives sim time on /clock and publishes one object's radar measurements (MeasurementBatch)
and the filter's estimates of it (EstimateBatch) over a few passes; the forecasts the node
publishes through the gaps equal the single-object filter's `core.gaps.batch_gap.
BatchGapForecaster` fed the same measurements and estimates (through the same messages)."""

from __future__ import annotations

import numpy as np
from rosgraph_msgs.msg import Clock
from ssa_fusion_msgs.msg import EstimateBatch, MeasurementBatch
from test_catalog_surrogate_graph import forecast_sink
from test_faults import Diag, publisher

from ssa_fusion.core.base import types
from ssa_fusion.core.base.rows import EstimateRows, MeasurementRows
from ssa_fusion.core.catalog.gap_bank import last_passes_forecaster
from ssa_fusion.core.earth.timescales import UNIX_EPOCH_JD
from ssa_fusion.core.measure.measurement import StationModels
from ssa_fusion.core.motion.element_sets import catalog_states
from ssa_fusion.formats import element_sets as catalog_io
from ssa_fusion.nodes.kit.progress import CLOCK, PROGRESS_QOS, TAKEN_ESTIMATES, TOPIC_PROGRESS
from ssa_fusion.ros import messages
from ssa_fusion.ros.interfaces import DiagnosticStatus
from ssa_fusion.sim import survey
from ssa_fusion.sim.sky import SKY_SCENARIOS
from ssa_fusion.studies.catalog_gaps import SAMPLE

PERIOD = 600.0
HOURS = 10.0
P = np.diag([1e-4] * 3 + [1e-8] * 3)


def _stream():
    """One synthetic LEO object seen by iss_network's radars: its measurements as one-row
    batches and its 'estimates' (the SGP4 truth at the measurement epochs, 100 m off), both
    through their messages (as the node gets them), and the radars' ids."""
    radars = SKY_SCENARIOS["iss_network"].radars
    entry = survey.synthetic_catalog(catalog_io.read_catalog(SAMPLE)[0], 1, seed=11)
    t0 = survey.catalog_start(entry)
    obs = survey.observe_catalog(entry, radars, t0, HOURS * 3600.0, seed=11)
    oid = obs.object_ids[0]
    names = [r.station.name for r in radars]
    meas, est = [], []
    x = catalog_states(entry, obs.t).x[0] + np.r_[0.1, 0.0, 0.0, 0.0, 0.0, 0.0]
    for i in range(obs.t.size):
        rows = MeasurementRows(obs.t[i:i + 1], [oid], [names[obs.sensor[i]]], obs.z[i:i + 1],
                               radars[obs.sensor[i]].R[None],
                               kind=np.array([types.Kind.RANGE_AZ_EL], np.uint8),
                               source=np.array([types.Source.SENSOR], np.uint8),
                               shard_key=messages.shard_keys([oid]))
        meas.append(messages.measurement_batch_to_msg(rows))
        erows = EstimateRows(obs.t[i:i + 1], [oid], x[i:i + 1], P[None], np.zeros(1),
                             types.UpdateSource.SENSOR, messages.shard_keys([oid]))
        est.append(messages.estimate_batch_to_msg(erows))
    return oid, meas, est, names


def test_the_batch_fit_forecasts_equal_the_single_object_forecasters(ros_graph):
    g = ros_graph
    oid, meas, est, names = _stream()
    params = {"use_sim_time": True, "hold": 0.0, "predict_period": PERIOD, "fit_budget": 0.0,
              "gap_forecast": "batch_fit", "station": ",".join(names)}
    node = g.start_node("catalog_surrogate", params=params)
    diag = Diag(g)
    forecasts = forecast_sink(g)
    clock = publisher(g, Clock, "/clock", ("catalog_surrogate",))
    est_pub = publisher(g, EstimateBatch, "/ssa/estimate_batch", ("catalog_surrogate",))
    meas_pub = publisher(g, MeasurementBatch, "/ssa/measurement_batch", ("catalog_surrogate",))
    taken: dict[str, int] = {}
    stepped: dict[str, int] = {}

    def on_progress(m: DiagnosticStatus) -> None:
        values = {kv.key: kv.value for kv in m.values}
        taken[m.name] = int(values.get(TAKEN_ESTIMATES, "0"))
        stepped[m.name] = int(values.get(CLOCK, "0"))

    g.probe.create_subscription(DiagnosticStatus, TOPIC_PROGRESS, on_progress, PROGRESS_QOS)
    t_meas = np.array([messages.measurement_batch_from_msg(m).t[0] for m in meas])
    t0, end = float(t_meas[0]), float(t_meas[-1])
    clock.publish(Clock(clock=messages.seconds_to_stamp(t0 - 60.0)))
    g.wait_for(lambda: "catalog_surrogate" in taken, 10.0, "the node's progress")
    k = 0
    # a minute at a time: once the node has stepped at the minute's clock, its measurements
    # and estimates, then (once the node has taken the estimates: lockstep's order) the next
    # minute's clock
    for t in t0 + 60.0 * np.arange(int((end - t0) / 60.0) + 62):
        stamp = messages.seconds_to_stamp(float(t))
        clock.publish(Clock(clock=stamp))
        ns = stamp.sec * 10**9 + stamp.nanosec
        g.wait_for(lambda ns=ns: stepped["catalog_surrogate"] >= ns, 10.0,
                   "the node to step at the minute's clock")
        sent = k
        while k < len(meas) and t_meas[k] <= t:
            meas_pub.publish(meas[k])
            est_pub.publish(est[k])
            k += 1
        if k > sent:
            g.wait_for(lambda k=k: taken["catalog_surrogate"] >= k, 10.0,
                       "the node to take the minute's estimates")
    diag.wait(g, "catalog_surrogate", {"received": len(est)}, 30.0)
    g.wait_for(lambda: any(f.t > end for f in forecasts), 20.0, "the last gap's forecasts")
    g.wait_for(lambda: int(diag.counts("catalog_surrogate").get("fits_made", "0")) >= 7,
               10.0, "seven fits (a gap after each pass)")
    # the reference: the single-object forecaster fed the same messages
    stations = {r.station.name: r.station for r in SKY_SCENARIOS["iss_network"].radars}
    ref = last_passes_forecaster(StationModels(stations, UNIX_EPOCH_JD), PERIOD)
    rows = [messages.measurement_batch_from_msg(m) for m in meas]
    erows = [messages.estimate_batch_from_msg(m) for m in est]
    assert forecasts
    j = 0
    for f in sorted(forecasts, key=lambda f: f.t):
        # the pass before: a forecast's epoch is pass_break (600 s) or more after its pass
        # end (the next pass may start inside the minute the clock ran ahead of the
        # estimates: a forecast it overtakes is from the fit before)
        while j < len(rows) and rows[j].t[0] <= f.t - 600.0:
            r, e = rows[j], erows[j]
            ref.on_measurement(types.Measurement(float(r.t[0]), r.z[0], r.R[0],
                                                 kind=types.Kind.RANGE_AZ_EL, object_id=oid,
                                                 frame_id=r.frame_id[0]))
            ref.on_estimate(float(e.t[0]), e.x[0], e.P[0])
            j += 1
        want = ref.forecast(f.t)
        assert want is not None and f.object_id == oid
        back = messages.estimate_from_msg(messages.estimate_to_msg(types.StateEstimate(
            t=f.t, x=want[0], P=want[1], object_id=oid)))
        np.testing.assert_allclose(f.x, back.x, rtol=1e-9, atol=1e-9)
        np.testing.assert_allclose(f.P, back.P, rtol=1e-9, atol=1e-15)
    assert node.popen.poll() is None

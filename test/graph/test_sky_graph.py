"""Graph test of a real-sky scenario: sensor_sim, surrogate, filter and recorder as separate
processes over DDS on the first 13 h of `iss_radar_columbus` (one radar, 10 deg mask: the
first passes come after 7.7 h, then one every ~1.6 h), with a whole-network outage over the
third pass. The bag must hold only measurements above the mask, in passes; the filter must
initialise from a pass, publish at the truth's cadence through the gaps, and be within 1 km
after each pass."""

import math

import numpy as np
import pytest
from ros_graph import run_object_graph
from ssa_fusion_msgs.msg import StateEstimate

from ssa_fusion.apps import evaluate
from ssa_fusion.core.base.types import Kind, UpdateSource
from ssa_fusion.core.earth import frames
from ssa_fusion.core.earth.stations import SENSORS
from ssa_fusion.evaluation.passes import passes
from ssa_fusion.graphs import node_parameters
from ssa_fusion.ros.topics import TOPIC_ESTIMATE, TOPIC_MEASUREMENT, TOPIC_WITHHELD
from ssa_fusion.sim import sky

SCENARIO = sky.SKY_SCENARIOS["iss_radar_columbus"]
HOURS = 13.0
OUTAGE = (10.2 * 3600.0, 1.2 * 3600.0)  # s after t0: the pass ending 11 h after t0


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    from ssa_fusion.ros.processes import Graph

    tmp = tmp_path_factory.mktemp("sky")
    bag = tmp / "bag"
    params = node_parameters(SCENARIO, time_scale=4000.0, seed=5, bag=bag)
    params["sensor_sim"].update(duration=HOURS * 3600.0, gaps=list(OUTAGE))
    g = Graph(tmp)
    try:
        estimates = g.collect(StateEstimate, TOPIC_ESTIMATE)
        ran = run_object_graph(g, params, 120, lambda: len(estimates))
    finally:
        problems = g.close()
    yield {"bag": bag, **ran, "problems": problems, "estimates": estimates}


def test_all_nodes_exit_0(run):
    assert run["sensor_code"] == 0, run["report"]
    assert run["codes"] == {"recorder": 0, "surrogate": 0, "filter": 0}, run["report"]
    assert not run["problems"]


def test_bag_holds_only_measurements_above_the_mask_in_passes(run):
    data = evaluate.load(run["bag"])
    ms = data.measurements
    assert len(ms) > 40
    assert {m.frame_id for m in ms} == {"columbus"} and {m.kind for m in ms} == {
        Kind.RANGE_AZ_EL}
    t = np.array([m.t for m in ms])
    assert t.min() > SCENARIO.t0 + 7 * 3600.0  # nothing before the first pass
    true_el = frames.razel_gcrs(sky.truth(SCENARIO, t), t, SENSORS["columbus"].station)[:, 2]
    assert true_el.min() >= math.radians(SENSORS["columbus"].min_elevation_deg)
    assert len(passes(ms)) >= 3
    # the outage's pass went to /ssa/withheld, and only there
    w = np.array([m.t for m in data.withheld])
    assert len(w) > 5
    assert np.all((w >= SCENARIO.t0 + OUTAGE[0]) & (w < SCENARIO.t0 + sum(OUTAGE)))
    assert not np.any((t >= SCENARIO.t0 + OUTAGE[0]) & (t < SCENARIO.t0 + sum(OUTAGE)))
    assert data.counts[TOPIC_MEASUREMENT] == len(ms)
    assert data.counts[TOPIC_WITHHELD] == len(w)


def test_filter_publishes_through_the_gaps_and_is_within_a_km_after_each_pass(run):
    data = evaluate.load(run["bag"])
    est = sorted(data.estimates, key=lambda e: e.t)
    sources = {e.update_source for e in est}
    assert UpdateSource.SENSOR in sources and UpdateSource.NONE in sources
    steps = np.diff(np.unique([e.t for e in est]))
    assert steps.max() <= SCENARIO.truth_cadence_s + 1e-6  # an estimate every truth epoch
    ev = evaluate.evaluate(data)
    assert ev.passes is not None and len(ev.passes.passes) >= 2
    err = [p[3] for p in ev.passes.passes]
    assert max(err) < 1.0, ev.passes.table()
    assert np.isfinite(ev.passes.nees).all()
    b = ev.between  # what the live filter published between passes, scored
    assert b is not None and b.gap_epochs > 100 and 0.0 < b.err_median_km < 5.0
    assert 0.0 < b.nees_in_95 <= 1.0
    assert "between passes, what the filter published" in evaluate.table(ev)

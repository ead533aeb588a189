"""The live filter and the offline replay publish the same estimates for the same input.

A graph of node processes over DDS (sensor_sim, surrogate, filter, recorder) runs a short
default scenario with a gap three `predict_period`s long, the surrogate set to forecast
nothing (`max_horizon` 1 s): through the gap the filter publishes its own predictions, as
`core.gaps.publisher.GapPublisher` decides. `ssa-fusion replay --offline` of the recorded bag
must publish the same estimates: every update and every prediction, in the same order, with
the same state and covariance.
"""

from pathlib import Path

import numpy as np
import pytest
from ssa_fusion_msgs.msg import StateEstimate

from ssa_fusion.apps import cli
from ssa_fusion.core.base import types
from ssa_fusion.graphs import node_parameters
from ssa_fusion.ros import bagio, messages
from ssa_fusion.sim import scenarios

RUN = scenarios.DEFAULT_LIVE.with_(track_s=1200.0, gap_s=1830.0, after_s=300.0, delays=5)
PREDICT_PERIOD = 600.0
"""Three predictions fall in the gap; during tracking (30 s cadence) none is due, unless the
filter falls 600 sim s (3 wall s at the time scale below) behind the clock. The gap ends off
the grid: a prediction due at the epoch of the measurement ending it would race that
measurement (the clock of an epoch reaches the filter first, on another topic)."""
TIME_SCALE = 200.0


def estimates(bag: Path) -> list[types.StateEstimate]:
    """The /ssa/estimate messages of `bag` in log-time order."""
    return [messages.estimate_from_msg(m.msg)
            for m in bagio.read_bag(bag, topics=["/ssa/estimate"])]


@pytest.mark.graph
def test_the_offline_replay_publishes_what_the_live_filter_published(ros_graph, tmp_path):
    g = ros_graph
    bag = tmp_path / "live"
    params = node_parameters(RUN, time_scale=TIME_SCALE, seed=4, bag=bag)
    params["surrogate"]["max_horizon"] = 1.0  # no forecast: the gap is the filter's own
    params["filter"]["predict_period"] = PREDICT_PERIOD
    seen = g.collect(StateEstimate, "/ssa/estimate")
    nodes = {n: g.start_node(n, params=params[n]) for n in ("recorder", "surrogate", "filter")}
    sensor = g.start_node("sensor_sim", params=params["sensor_sim"])
    assert g.wait_exit(sensor, timeout=120.0) == 0, sensor.describe()
    g.wait_quiet(lambda: len(seen), quiet_s=1.0, limit_s=20.0)
    for name in ("filter", "surrogate", "recorder"):  # the recorder last: it hears them all
        assert g.stop(nodes[name]) == 0, nodes[name].describe()

    out = tmp_path / "offline"
    assert cli.main(["replay", str(bag), "--offline", "--out", str(out)]) == 0
    live, offline = estimates(bag), estimates(out)

    gap0, gap1 = RUN.t0 + RUN.track_s, RUN.t0 + RUN.track_s + RUN.gap_s
    predicted = [e.t for e in live if e.update_source == types.UpdateSource.NONE]
    assert len(predicted) >= 2 and all(gap0 <= t < gap1 for t in predicted), predicted
    assert all(t % PREDICT_PERIOD == 0 for t in predicted)
    assert not any(e.update_source == types.UpdateSource.FORECAST for e in live)
    assert [(e.t, e.update_source) for e in offline] == [(e.t, e.update_source) for e in live]
    for a, b in zip(live, offline, strict=True):
        np.testing.assert_allclose(b.x, a.x, rtol=1e-12, atol=0.0)
        np.testing.assert_allclose(b.P, a.P, rtol=1e-9, atol=1e-15)
        assert a.object_id == b.object_id == RUN.name

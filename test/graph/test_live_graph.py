"""Graph test of the product: sensor_sim, surrogate, filter and recorder as separate
processes over DDS, on a shortened default scenario (range/az/el of the ISS)."""

import json
from collections import Counter

import numpy as np
import pytest
from diagnostic_msgs.msg import DiagnosticArray
from rclpy.qos import QoSProfile
from ros_graph import run_object_graph
from rosgraph_msgs.msg import Clock
from ssa_fusion_msgs.msg import Measurement, StateEstimate

from ssa_fusion.apps import evaluate
from ssa_fusion.graphs import node_parameters
from ssa_fusion.ros import bagio, messages
from ssa_fusion.sim import scenarios

TOPICS = {
    "/ssa/measurement": Measurement,
    "/ssa/forecast": Measurement,
    "/ssa/estimate": StateEstimate,
    "/ssa/truth": StateEstimate,
    "/ssa/withheld": Measurement,
}
SHORT = scenarios.DEFAULT_LIVE.with_(track_s=3000.0, gap_s=900.0, after_s=600.0, delays=40)


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    """Run the graph once; the tests below check what arrived and what was recorded."""
    from ssa_fusion.ros.processes import Graph

    tmp = tmp_path_factory.mktemp("live")
    bag = tmp / "bag"
    params = node_parameters(SHORT, time_scale=1500.0, seed=3, bag=bag)
    params["sensor_sim"]["wait_for"] = [
        "/ssa/measurement=4", "/ssa/forecast=3", "/ssa/estimate=2", "/ssa/truth=2",
        "/ssa/withheld=2", "/clock=4",
    ]
    g = Graph(tmp)
    try:
        got = {topic: g.collect(t, topic) for topic, t in TOPICS.items()}
        clock = g.collect(Clock, "/clock")
        diagnostics = g.collect(DiagnosticArray, "/diagnostics", QoSProfile(depth=100))
        ran = run_object_graph(  # sensor_sim starts once filter, recorder, probe take forecasts
            g, params, 90, lambda: tuple(len(v) for v in got.values()),
            before_sensor=lambda: g.wait_for_subscriber("/ssa/forecast", 3))
    finally:
        problems = g.close()
    yield {"got": got, "clock": clock, "diagnostics": diagnostics, "bag": bag, **ran,
           "problems": problems}


def test_all_nodes_exit_0(run):
    assert run["sensor_code"] == 0, run["report"]
    assert run["codes"] == {"recorder": 0, "surrogate": 0, "filter": 0}, run["report"]
    assert not run["problems"]


def test_diagnostics_are_stamped_in_sim_time(run):
    """/diagnostics once carried wall time while every other topic carries sim time.
    Every node's reports are stamped within the run's sim time (0 before its first /clock),
    sensor_sim's (it drives sim time) with a time it published on /clock."""
    t0 = SHORT.t0
    t_end = SHORT.t0 + SHORT.track_s + SHORT.gap_s + SHORT.after_s
    stamps: dict[str, list[float]] = {}
    for arr in run["diagnostics"]:
        for st in arr.status:
            stamps.setdefault(st.name, []).append(messages.stamp_to_seconds(arr.header.stamp))
    assert set(stamps) == {"sensor_sim", "surrogate", "filter", "recorder"}, run["report"]
    for node, ts in stamps.items():
        assert all(t == 0.0 or t0 <= t <= t_end for t in ts), (node, ts)
        assert any(t0 <= t for t in ts), (node, ts)  # some after sim time started
    clock = {messages.stamp_to_seconds(m.clock) for m in run["clock"]}
    assert set(stamps["sensor_sim"]) <= clock | {0.0}


def test_estimates_arrive_and_forecasts_only_in_the_gap(run):
    got = run["got"]
    gap0 = SHORT.t0 + SHORT.track_s
    gap1 = gap0 + SHORT.gap_s
    withheld = {messages.stamp_to_seconds(m.header.stamp) for m in got["/ssa/withheld"]}
    assert len(withheld) == round(SHORT.gap_s / SHORT.cadence_s)
    forecasts = [messages.measurement_from_msg(m) for m in got["/ssa/forecast"]]
    assert forecasts, "no forecast arrived"
    assert all(gap0 <= f.t < gap1 and f.source == 1 for f in forecasts)
    assert all(f.horizon > 0 for f in forecasts)
    est = [messages.estimate_from_msg(m) for m in got["/ssa/estimate"]]
    by_source = Counter(e.update_source for e in est)
    assert by_source[1] > 100  # real measurements before and after the gap
    fused_forecast = [e for e in est if e.update_source == 2]
    assert len(fused_forecast) >= 0.9 * len(withheld)  # forecasts were fused
    assert all(gap0 <= e.t < gap1 for e in fused_forecast)
    after = [e for e in est if e.t >= gap1]
    assert after and all(e.update_source == 1 for e in after)  # real ones take over
    # estimates are stamped with measurement epochs on the 30 s grid
    assert all(abs((e.t - SHORT.t0) / 30.0 - round((e.t - SHORT.t0) / 30.0)) < 1e-6
               for e in est if e.update_source)


def test_estimate_tracks_truth(run):
    got = run["got"]
    truth = {messages.stamp_to_seconds(m.header.stamp): np.array(m.state) for m in
             got["/ssa/truth"]}
    last = messages.estimate_from_msg(got["/ssa/estimate"][-1])
    err_km = np.linalg.norm(last.x[:3] - truth[last.t][:3] / 1000.0)
    sigma_km = np.sqrt(np.trace(last.P[:3, :3]))
    assert err_km < 200.0, err_km  # a few hundredths of a radian at ~5000 km range
    assert err_km < 5 * sigma_km, (err_km, sigma_km)


def test_every_published_message_is_in_the_bag(run):
    got = run["got"]
    counts = Counter(m.topic for m in bagio.read_bag(run["bag"]))
    for topic, msgs in got.items():
        assert counts[topic] == len(msgs), topic
    assert counts["/clock"] == len(run["clock"])


def test_bag_starts_at_sim_time_not_at_zero(run):
    """The latched /ssa/config arrives before the first /clock: it is stamped with the
    clock's first time, so `ros2 bag play` does not wait 55 years before the data."""
    import yaml

    msgs = list(bagio.read_bag(run["bag"]))
    first_clock = min(m.t_ns for m in msgs if m.topic == "/clock")
    assert any(m.topic == "/ssa/config" for m in msgs)
    assert min(m.t_ns for m in msgs) >= first_clock - 1e9
    info = yaml.safe_load((run["bag"] / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    sim_s = SHORT.track_s + SHORT.gap_s + SHORT.after_s
    assert info["duration"]["nanoseconds"] <= (sim_s + 600.0) * 1e9


def test_bag_reads_with_rosbags_and_mcap(run):
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory

    bag = run["bag"]
    meta = (bag / "metadata.yaml").read_text()
    assert "version: 9" in meta and "ros_distro: kilted" in meta
    assert "offered_qos_profiles" in meta and "RIHS01_" in meta
    data = evaluate.load(bag)
    assert data.counts["/ssa/estimate"] == len(run["got"]["/ssa/estimate"])
    mcap_file = next(bag.glob("*.mcap"))
    with mcap_file.open("rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        n = 0
        for schema, channel, _message, decoded in reader.iter_decoded_messages(
                topics=["/ssa/estimate"]):
            assert schema.encoding == "ros2msg" and channel.message_encoding == "cdr"
            assert len(decoded.state) == 6 and len(decoded.covariance) == 36
            n += 1
        assert reader.get_header().profile == "ros2"
    assert n == data.counts["/ssa/estimate"]


def test_the_bag_records_the_estimator_settings_in_effect(run):
    """Both estimator nodes publish their settings (latched) on /ssa/config; the recorder,
    started first, still gets them, and they read back as the estimator the run's
    parameters define: what replay and report then use."""
    from ssa_fusion.params import settings

    data = evaluate.load(run["bag"])
    assert data.counts["/ssa/config"] == 2
    nodes = sorted(json.loads(t)["node"] for t in data.config)
    assert nodes == ["filter", "surrogate"]
    params = node_parameters(SHORT, time_scale=1500.0, seed=3, bag=run["bag"])
    expected = settings.estimator_from(params["filter"], params["surrogate"])
    assert settings.recorded_estimator(data.config) == expected
    assert expected.surrogate.delays == 40 and expected.filter.noise.q == pytest.approx(SHORT.q)
    ev = evaluate.evaluate(data)
    assert ev.settings.origin.startswith("recorded")

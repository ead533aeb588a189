"""Graph tests: bad input, faults and shutdown. The graph keeps working and loses nothing.

Every test runs real node processes in a private ROS domain (loopback only). The test
process publishes crafted messages from its probe node straight to a filter or surrogate
process (no sensor_sim unless the case needs one) and asserts on /ssa/estimate,
/ssa/forecast, /diagnostics (counts by cause) and the nodes' logs. The property-based test
of the filter core (arbitrary Measurement fields never raise, never give NaN or a
non-symmetric covariance) is in test/core/test_tracker.py.

Every timeout below is nominal: `Graph` multiplies it by SSA_TEST_TIMEOUT_FACTOR (default 3,
see test/ros_graph.py), and so does `g.scaled` in this file's own deadline loops.

One module of ~850 lines: the tests share the probe helpers at the top (crafted messages,
a /clock driven by the test, /diagnostics counts by cause); its sections (bad input, clock,
surrogate cannot fit, parameters, shutdown) are the faults.
"""

from __future__ import annotations

import contextlib
import math
import signal
import time
from collections import Counter
from itertools import pairwise
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from diagnostic_msgs.msg import DiagnosticArray
from rcl_interfaces.msg import Parameter as ParameterMsg
from rcl_interfaces.msg import ParameterType, ParameterValue
from rcl_interfaces.srv import GetParameters, SetParameters, SetParametersAtomically
from rclpy.qos import QoSProfile
from ros_graph import report_probe_matches
from rosgraph_msgs.msg import Clock
from ssa_fusion_msgs.msg import Measurement, StateEstimate

from ssa_fusion.core.base import types
from ssa_fusion.core.earth.timescales import UNIX_EPOCH_JD
from ssa_fusion.core.filter.options import DEFAULT_GATE, FilterOptions
from ssa_fusion.core.filter.tracker import Tracker
from ssa_fusion.core.gaps.estimator import EstimatorConfig
from ssa_fusion.core.gaps.estimator import motion as config_motion
from ssa_fusion.core.measure.measurement import RazelModel
from ssa_fusion.graphs import node_parameters
from ssa_fusion.ros import bagio, messages
from ssa_fusion.ros.discovery import RANGE_VAR, DiscoveryRange
from ssa_fusion.ros.qos import DATA_QOS
from ssa_fusion.ros.readiness import ReadyNodes
from ssa_fusion.sim import scenarios
from ssa_fusion.sim.simulate import simulate

SHORT = scenarios.DEFAULT_LIVE.with_(track_s=1200.0, gap_s=0.0, after_s=0.0, delays=5)
SIM = simulate(SHORT, seed=1)
T = SIM.t  # 41 epochs 30 s apart, range/az/el of the ISS from Columbus (km, rad)
PARAMS = node_parameters(SHORT, time_scale=1000.0, seed=1, bag=Path("unused"), lockstep=False)
KM = 1000.0


# helpers ---------------------------------------------------------------------------------
def meas(i: int, dt: float = 0.0, z: np.ndarray | None = None, source: int = types.Source.SENSOR,
         R: np.ndarray | None = None) -> Measurement:
    """The simulated measurement of epoch i (optionally moved by dt s or with other z)."""
    m = types.Measurement(t=float(T[i]) + dt, z=SIM.z[i] if z is None else z,
                          R=SIM.R if R is None else R, kind=types.Kind.RANGE_AZ_EL, source=source,
                          object_id="iss", frame_id="columbus",
                          horizon=30.0 if source == types.Source.FORECAST else 0.0)
    return messages.measurement_to_msg(m)


def publisher(g, msg_type, topic: str, readers: tuple[str, ...]):
    """A probe publisher matched with the subscriptions of nodes `readers`, on both sides of
    the match (no fixed sleep)."""
    pub = g.probe.create_publisher(msg_type, topic, DATA_QOS)
    g.wait_for(lambda: pub.get_subscription_count() >= len(readers), 20.0,
               f"{len(readers)} subscription(s) matched on {topic}")
    if topic != "/clock":  # nodes report their own subscriptions, not their time source's
        ready, needs = ReadyNodes(g.probe), [f"{r}:{topic}" for r in readers]
        g.wait_for(lambda: ready.ready(needs), 20.0, f"{needs} to match the probe")
    return pub


class Diag:
    """The latest /diagnostics status of each node."""

    def __init__(self, g) -> None:
        self.msgs: list = g.collect(DiagnosticArray, "/diagnostics", QoSProfile(depth=100))

    def status(self, node: str):
        for arr in reversed(self.msgs):
            for st in arr.status:
                if st.name == node:
                    return st
        return None

    def counts(self, node: str) -> dict[str, str]:
        st = self.status(node)
        return {} if st is None else {kv.key: kv.value for kv in st.values}

    def wait(self, g, node: str, want: dict[str, int], timeout: float = 15.0) -> dict:
        def ok() -> bool:
            c = self.counts(node)
            return all(c.get(k) == str(v) for k, v in want.items())

        g.wait_for(ok, timeout, f"{node} diagnostics {want} (last: {self.counts(node)})")
        return self.counts(node)


def estimates(received: list) -> list[types.StateEstimate]:
    return [messages.estimate_from_msg(m) for m in received]


def assert_sane(est: list[types.StateEstimate]) -> None:
    for e in est:
        assert np.isfinite(e.x).all() and np.isfinite(e.P).all(), e
        assert np.allclose(e.P, e.P.T, rtol=1e-12, atol=0.0), e.t
        assert (np.linalg.eigvalsh(e.P) > -1e-9 * np.abs(e.P).max()).all(), e.t


def offline_tracker() -> Tracker:
    """The filter node's Tracker for SHORT, built from the core alone."""
    model = RazelModel(scenarios.STATIONS["columbus"], UNIX_EPOCH_JD)
    config = FilterOptions().with_(p0_sigma=SHORT.p0_sigma, q=SHORT.q, gate=DEFAULT_GATE)
    return Tracker(config_motion(EstimatorConfig()), model, config, n=6, frame_id="columbus")


def filter_params(**extra) -> dict:
    return {**PARAMS["filter"], **extra}


def surrogate_params(**extra) -> dict:
    return {**PARAMS["surrogate"], **extra}


# bad input -------------------------------------------------------------------------------
def bad_messages(i: int) -> list[tuple[str, Measurement]]:
    """(cause, message) for each kind of bad input, stamped between epochs i and i + 1."""
    out = []
    m = meas(i, 10.0)
    m.z[0] = float("nan")
    out.append(("rejected_nonfinite", m))
    m = meas(i, 11.0)
    m.covariance[4] = float("inf")
    out.append(("rejected_nonfinite", m))
    m = meas(i, 12.0)
    m.z[0] = -1000.0
    out.append(("rejected_negative_range", m))
    m = meas(i, 13.0)
    m.z[2] = 2.0
    out.append(("rejected_elevation", m))
    m = meas(i, 14.0)
    m.z[2] = -1.6
    out.append(("rejected_elevation", m))
    m = meas(i, 15.0)
    m.kind = 7  # unknown kind
    out.append(("rejected_kind", m))
    m = meas(i, 16.0)
    m.kind = Measurement.POSITION  # a kind this filter is not configured for
    m.header.frame_id = "gcrf"
    out.append(("rejected_kind", m))
    m = meas(i, 17.0)
    m.header.frame_id = "goldstone"  # a station this filter is not configured for
    out.append(("rejected_frame", m))
    return out


def test_bad_input_is_never_fused_and_counted_by_cause(ros_graph):
    g = ros_graph
    got = g.collect(StateEstimate, "/ssa/estimate")
    diag = Diag(g)
    filt = g.start_node("filter", params=filter_params())
    surr = g.start_node("surrogate", params=surrogate_params())
    pub = publisher(g, Measurement, "/ssa/measurement", ("filter", "surrogate"))

    def outlier(i: int) -> Measurement:  # 3000 km off in range: beyond the NIS gate
        return meas(i, z=SIM.z[i] + np.array([3000.0, 0.0, 0.0]))

    sequence = [meas(i) for i in range(4)]
    sequence += [m for _, m in bad_messages(3)] + [meas(4)]
    sequence += [meas(2), meas(4), outlier(5), meas(5)]  # stale, duplicate, gate
    sequence += [m for _, m in bad_messages(5)] + [meas(6)]
    sequence += [meas(3), meas(6), outlier(7)]  # again: logged once, counted twice
    sequence += [meas(i) for i in range(7, 10)]
    for m in sequence:
        pub.publish(m)

    want = {k: 2 * v for k, v in Counter(c for c, _ in bad_messages(0)).items()}
    want.update(rejected_stale=2, rejected_duplicate=2, rejected_gate=2, published_sensor=8)
    counts = diag.wait(g, "filter", want)
    assert "internal_error" not in counts and "rejected_numeric" not in counts

    # estimates continue: exactly one per good epoch after IOD, none at a bad stamp
    est = estimates(got)
    assert [e.t for e in est] == [float(T[i]) for i in range(2, 10)]
    assert all(e.update_source == types.UpdateSource.SENSOR for e in est)
    assert_sane(est)
    # and they are what the core gives for the good measurements alone
    tracker = offline_tracker()
    for i in range(10):
        out = tracker.process(messages.measurement_from_msg(meas(i)))
    np.testing.assert_allclose(est[-1].x, out.estimate.x, rtol=1e-9)

    # the surrogate buffers only good measurements and says why it dropped the others
    # (it has no gate: the two outliers replace their epochs' good measurements)
    want_s = {k: 2 * v for k, v in Counter(c for c, _ in bad_messages(0)).items()}
    want_s.update(rejected_stale=6, buffered=10)
    counts_s = diag.wait(g, "surrogate", want_s)
    assert "internal_error" not in counts_s

    # still up, and each cause was logged once although counted more often
    assert filt.returncode is None and surr.returncode is None
    for proc in (filt, surr):  # no /clock here: taken unjudged once the nodes stop waiting
        assert "no /clock after" in proc.stderr(), proc.describe()
    for proc, causes in ((filt, want), (surr, want_s)):
        log = proc.stderr()
        for cause in causes:
            if cause.startswith("rejected"):
                assert log.count(f"{cause}: ") == 1, (proc.name, cause, log)


def test_nodes_report_when_their_subscriptions_have_matched(ros_graph):
    """Both sides of a DDS match, which senders wait for (`ssa_fusion.ros.readiness`)."""
    g = ros_graph
    ready = ReadyNodes(g.probe)
    g.start_node("filter", params=filter_params())
    g.wait_for(lambda: "filter" in ready.reports, 20.0, "a report from the filter")
    assert ready.unmatched(["filter:/ssa/measurement"]) == ["filter:/ssa/measurement"]
    g.probe.create_publisher(Measurement, "/ssa/measurement", DATA_QOS)
    g.wait_for(lambda: ready.ready(["filter:/ssa/measurement"]), 20.0, "filter matched")
    # nothing publishes forecasts or /clock: those inputs are reported, and unmatched;
    # nothing reads its estimates: its output ('>') is reported, and unmatched, until the
    # probe does
    assert ready.reports["filter"] == {"/ssa/measurement": 1, "/ssa/forecast": 0,
                                       "/clock": 0, ">/ssa/estimate": 0}
    g.probe.create_subscription(StateEstimate, "/ssa/estimate", lambda _m: None, DATA_QOS)
    g.wait_for(lambda: ready.ready(["filter:>/ssa/estimate"]), 20.0, "filter's output matched")
    assert ready.reports["filter"][">/ssa/estimate"] == 1


def test_a_real_measurement_beats_a_forecast_for_the_same_epoch(ros_graph):
    g = ros_graph
    got, diag, real, fcst = filter_with_both_inputs(g, float(T[5]))

    def forecast(i: int) -> Measurement:  # a plausible forecast: 2 km off, honest R
        return meas(i, z=SIM.z[i] + np.array([2.0, 0.0, 0.0]), source=types.Source.FORECAST,
                    R=4.0 * SIM.R)

    def wait_estimates(n: int) -> None:
        g.wait_for(lambda: len(got) >= n, 15.0, f"{n} estimates")

    for i in range(4):
        real.publish(meas(i))
    wait_estimates(2)
    fcst.publish(forecast(4))
    fcst.publish(forecast(5))
    wait_estimates(4)
    real.publish(meas(4))  # rolls back both forecasts, fuses it, re-fuses forecast 5
    wait_estimates(6)
    fcst.publish(forecast(4))  # too late: the real one is in
    real.publish(meas(5))  # rolls back forecast 5 again
    wait_estimates(7)
    diag.wait(g, "filter", {"forecast_superseded": 1, "forecasts_rolled_back": 3})

    est = estimates(got)
    assert [(e.t, e.update_source) for e in est[2:]] == [
        (T[4], types.UpdateSource.FORECAST), (T[5], types.UpdateSource.FORECAST),
        (T[4], types.UpdateSource.SENSOR), (T[5], types.UpdateSource.FORECAST),
        (T[5], types.UpdateSource.SENSOR)]
    assert_sane(est)
    # the final estimates are exactly those of the real measurements without any forecast
    tracker = offline_tracker()
    want = {}
    for i in range(6):
        out = tracker.process(messages.measurement_from_msg(meas(i)))
        if out.estimate is not None:
            want[out.estimate.t] = out.estimate
    for e in (est[4], est[6]):
        np.testing.assert_allclose(e.x, want[e.t].x, rtol=1e-9)
        np.testing.assert_allclose(e.P, want[e.t].P, rtol=1e-6, atol=1e-15)


# clock -----------------------------------------------------------------------------------
def clock_msg(t: float) -> Clock:
    return Clock(clock=messages.seconds_to_stamp(t))


def set_clock(g, pub, diag: Diag, t: float, nodes: tuple[str, ...]) -> None:
    """Publish sim time `t` until every node's diagnostics are stamped with it (/clock is
    best effort: republish until taken)."""
    def seen() -> bool:
        return all(abs(_node_stamp(diag, n) - t) < 1e-3 for n in nodes)

    deadline = time.monotonic() + g.scaled(15.0)
    while not seen():
        assert time.monotonic() < deadline, f"nodes did not take /clock {t}\n{g.report()}"
        pub.publish(clock_msg(t))
        until = time.monotonic() + 0.3
        while time.monotonic() < until and not seen():
            g.spin_once(0.05)


def publish_until(g, pub, msg, done, what: str, timeout: float = 10.0) -> None:
    """Publish `msg` (best effort /clock) every 0.2 s until `done()` (`timeout` scaled)."""
    deadline = time.monotonic() + g.scaled(timeout)
    while not done():
        assert time.monotonic() < deadline, f"timed out waiting for {what}\n{g.report()}"
        pub.publish(msg)
        until = time.monotonic() + 0.2
        while time.monotonic() < until and not done():
            g.spin_once(0.02)


def _node_stamp(diag: Diag, node: str) -> float:
    for arr in reversed(diag.msgs):
        if any(st.name == node for st in arr.status):
            return messages.stamp_to_seconds(arr.header.stamp)
    return -1.0


def run_clock_at(g, diag: Diag, t: float, nodes: tuple[str, ...]) -> None:
    """Start the nodes' sim time at `t` (at or after every stamp the test sends, so nothing
    is refused as ahead of the clock and the filter has nothing to predict): measurements
    are then judged on arrival instead of held until the nodes give up waiting for a
    /clock (3 s of wall time; that path is taken by the tests that publish no /clock)."""
    set_clock(g, publisher(g, Clock, "/clock", nodes), diag, t, nodes)


NODES = ("filter", "surrogate")


def filter_and_surrogate(g, filter_extra: dict | None = None,
                         surrogate_extra: dict | None = None) -> tuple[list, Diag, Any, Any]:
    """Start a filter and a surrogate; (estimates received, diagnostics, /clock publisher,
    /ssa/measurement publisher), both publishers matched with both nodes."""
    got = g.collect(StateEstimate, "/ssa/estimate")
    diag = Diag(g)
    g.start_node("filter", params=filter_params(**(filter_extra or {})))
    g.start_node("surrogate", params=surrogate_params(**(surrogate_extra or {})))
    clock = publisher(g, Clock, "/clock", NODES)
    pub = publisher(g, Measurement, "/ssa/measurement", NODES)
    return got, diag, clock, pub


def filter_with_both_inputs(g, t: float) -> tuple[list, Diag, Any, Any]:
    """Start a filter and run its clock at `t`; (estimates received, diagnostics,
    /ssa/measurement publisher, /ssa/forecast publisher), both matched with it."""
    got = g.collect(StateEstimate, "/ssa/estimate")
    diag = Diag(g)
    g.start_node("filter", params=filter_params())
    sensor = publisher(g, Measurement, "/ssa/measurement", ("filter",))
    forecasts = publisher(g, Measurement, "/ssa/forecast", ("filter",))
    run_clock_at(g, diag, t, ("filter",))
    return got, diag, sensor, forecasts


def test_backwards_clock_jump_resets_filter_and_surrogate(ros_graph):
    g = ros_graph
    got, diag, clock, pub = filter_and_surrogate(g)

    set_clock(g, clock, diag, float(T[6]), NODES)
    for i in range(6):
        pub.publish(meas(i))
    g.wait_for(lambda: len(got) >= 4, 15.0, "4 estimates")
    set_clock(g, clock, diag, float(T[0]) - 60.0, NODES)  # the bag loops
    for node in NODES:
        diag.wait(g, node, {"reset_clock_jump": 1})
    for i in range(6):  # the same epochs again: accepted, not stale
        pub.publish(meas(i))
    g.wait_for(lambda: len(got) >= 8, 15.0, "8 estimates")
    c = diag.wait(g, "surrogate", {"buffered": 12, "reset_clock_jump": 1})
    assert "rejected_stale" not in c and "internal_error" not in c
    c = diag.wait(g, "filter", {"published_sensor": 8})
    assert "rejected_stale" not in c and "rejected_duplicate" not in c
    assert "internal_error" not in c
    est = estimates(got)
    assert [e.t for e in est] == [float(T[i]) for i in (2, 3, 4, 5)] * 2
    assert_sane(est)
    for a, b in zip(est[:4], est[4:], strict=True):  # a fresh start gives the same result
        np.testing.assert_allclose(a.x, b.x, rtol=1e-12)


def test_a_stamp_far_ahead_of_the_clock_is_refused_and_nothing_is_lost(ros_graph):
    """A sensor stamping wall time into a sim-time graph: fused, one such message would put
    the filter and the surrogate past every later real measurement."""
    g = ros_graph
    got, diag, clock, pub = filter_and_surrogate(g)
    set_clock(g, clock, diag, float(T[7]), NODES)
    year = 365.25 * 86400.0
    for m in [meas(i) for i in range(4)] + [meas(4, year)] + [meas(i) for i in range(4, 8)]:
        pub.publish(m)
    # held a few wall seconds for the clock to catch up (it does not), then refused
    c = diag.wait(g, "filter", {"held_ahead_of_clock": 1, "rejected_future": 1,
                                "published_sensor": 6})
    assert "rejected_stale" not in c and "internal_error" not in c
    c = diag.wait(g, "surrogate", {"rejected_future": 1, "buffered": 8})
    assert "rejected_stale" not in c and "internal_error" not in c
    est = estimates(got)
    assert [e.t for e in est] == [float(T[i]) for i in range(2, 8)]
    tracker = offline_tracker()
    for i in range(8):
        out = tracker.process(messages.measurement_from_msg(meas(i)))
    np.testing.assert_allclose(est[-1].x, out.estimate.x, rtol=1e-9)


def test_a_burst_ahead_of_the_clock_waits_for_it_and_is_fused(ros_graph):
    """After a stall (a paused simulator, a loaded machine) a burst of measurements can reach
    a node before the /clock messages that cover it: held until the clock catches up, then
    fused, none refused (they were refused as 'future' and lost)."""
    g = ros_graph
    lead = {"max_clock_lead": 60.0}
    got, diag, clock, pub = filter_and_surrogate(g, lead, lead)
    set_clock(g, clock, diag, float(T[0]) - 600.0, NODES)  # 10 lead's worth behind
    for i in range(8):
        pub.publish(meas(i))
    diag.wait(g, "filter", {"held_ahead_of_clock": 8})
    diag.wait(g, "surrogate", {"held_ahead_of_clock": 8})
    assert got == []  # nothing fused ahead of the clock
    set_clock(g, clock, diag, float(T[7]), NODES)
    c = diag.wait(g, "filter", {"published_sensor": 6})
    assert not {"rejected_future", "rejected_stale", "internal_error"} & set(c)
    c = diag.wait(g, "surrogate", {"buffered": 8})
    assert not {"rejected_future", "internal_error"} & set(c)
    assert [e.t for e in estimates(got)] == [float(T[i]) for i in range(2, 8)]


def test_surrogate_learns_only_its_configured_object_and_kind(ros_graph):
    """Strays before the real stream (another object, another kind) used to fix what the
    surrogate's buffer accepted for the whole run."""
    g = ros_graph
    diag = Diag(g)
    g.start_node("surrogate", params=surrogate_params(object_id="iss"))
    pub = publisher(g, Measurement, "/ssa/measurement", ("surrogate",))
    run_clock_at(g, diag, float(T[5]), ("surrogate",))
    other = meas(0, -30.0)
    other.object_id = "debris"
    position = meas(0, -20.0)
    position.kind, position.header.frame_id = Measurement.POSITION, "gcrf"
    for m in [other, position] + [meas(i) for i in range(6)]:
        pub.publish(m)
    c = diag.wait(g, "surrogate", {"ignored_other_object": 1, "rejected_kind": 1,
                                   "buffered": 6})
    assert "rejected_stale" not in c and "internal_error" not in c


# surrogate cannot fit --------------------------------------------------------------------
def test_surrogate_that_cannot_fit_forecasts_nothing_and_filter_keeps_predicting(ros_graph):
    g = ros_graph
    forecasts = g.collect(Measurement, "/ssa/forecast")
    got, diag, clock, pub = filter_and_surrogate(g, {"predict_period": 60.0},
                                                 {"check_period": 0.01})

    def model_status() -> str:
        st = diag.status("surrogate")
        return "" if st is None else {kv.key: kv.value for kv in st.values}.get("model", "")

    def predictions() -> list[types.StateEstimate]:
        return [e for e in estimates(got) if e.update_source == types.UpdateSource.NONE]

    # 1. too few samples (4; the fit needs 2 x delays + 2 = 12)
    set_clock(g, clock, diag, float(T[0]), NODES)
    for i in range(4):
        pub.publish(meas(i))
    g.wait_for(lambda: len(got) >= 2, 15.0, "IOD")
    # sim time moves on through the gap, cadence by cadence; once 60 s passed without an
    # update, the filter predicts at every multiple of 60 s of sim time since its last update
    grid = [60.0 * k for k in range(math.floor(T[3] / 60.0) + 1, math.floor(T[3] / 60.0) + 6)]
    for k in range(3, 9):
        t = float(T[3]) + 30.0 * k
        due = [g_t for g_t in grid if g_t <= t]
        publish_until(g, clock, clock_msg(t),
                      lambda due=due: {e.t for e in predictions()} >= set(due),
                      f"predictions at {due}")
    g.wait_for(lambda: "cannot fit" in model_status(), 10.0, "surrogate status")
    assert "need 12" in model_status()
    pred = predictions()
    assert [e.t for e in pred] == [g_t for g_t in grid if g_t <= float(T[3]) + 240.0]
    assert len(pred) >= 4
    sig = [np.trace(e.P[:3, :3]) for e in pred]
    assert all(b > a for a, b in pairwise(sig)), sig  # covariance grows
    assert_sane(estimates(got))

    # 2. constant (degenerate) data; 3. not at a fixed cadence. A clock jump starts afresh.
    cases = [
        ([meas(0, 30.0 * k, z=SIM.z[0]) for k in range(14)], "constant"),
        ([meas(0, t, z=SIM.z[k]) for k, t in
          enumerate(np.cumsum([0.0, *([30.0, 30.0, 45.0] * 5)]))], "fixed cadence"),
    ]
    for msgs, reason in cases:
        set_clock(g, clock, diag, float(T[0]) - 100.0, NODES)
        set_clock(g, clock, diag, float(T[0]), NODES)
        for m in msgs:
            pub.publish(m)
        t_end = messages.stamp_to_seconds(msgs[-1].header.stamp) + 300.0  # well into a gap
        set_clock(g, clock, diag, t_end, NODES)
        g.wait_for(lambda r=reason: r in model_status(), 10.0, f"status '{reason}'")

    c = diag.counts("surrogate")
    assert c.get("reset_clock_jump") == "2" and "internal_error" not in c
    assert "internal_error" not in diag.counts("filter")
    assert forecasts == []  # nothing was ever forecast


# parameters ------------------------------------------------------------------------------
EXAMPLE_SITES = Path(__file__).resolve().parents[2] / "config" / "sites" / "example.yaml"


def test_invalid_parameters_refuse_to_start(ros_graph, tmp_path):
    g = ros_graph
    existing = tmp_path / "existing_bag"
    existing.mkdir()
    cases = {
        "scenario": ("sensor_sim", {"scenario": "no_such_orbit"}),
        "cadence": ("sensor_sim", {"cadence": -30.0}),
        "time_scale": ("sensor_sim", {"time_scale": "fast"}),
        "wait_for_readers": ("sensor_sim", {"wait_for_readers": ["filter"]}),
        "delays": ("surrogate", {"delays": 200, "buffer_length": 3000.0, "cadence": 30.0}),
        "p0_sigma": ("filter", {"p0_sigma": [1.0, 2.0]}),
        "p0_sigma/empty": ("filter", {"p0_sigma": []}),  # a list of no type: was a traceback
        "topics/empty": ("recorder", {"topics": [], "bag": str(tmp_path / "b")}),
        "kind": ("filter", {"kind": "sonar"}),
        "bag": ("recorder", {"bag": str(existing)}),
        "qq": ("filter", {"qq": 0.1}),  # a misspelt name
        "dealys": ("surrogate", {"dealys": 300}),
        "iod_samples": ("filter", {"iod_samples": 1000000}),  # beyond 1000
        "bag/unwritable": ("recorder", {"bag": "/proc/nope/bag"}),  # cannot be created
        "delays/huge": ("surrogate", {"delays": 1000000000000}),  # cadence 0: inferred
        "catalog": ("sensor_sim", {"scenario": "iss_network", "catalog": "/nope/cat.tle"}),
        "catalog/paper": ("sensor_sim", {"catalog": "config/catalogs/sample.tle"}),
        "start": ("sensor_sim", {"scenario": "iss_network", "start": "June"}),
        "start/paper": ("sensor_sim", {"start": "2025-06-01T00:00:00Z"}),
        "sites": ("sensor_sim", {"scenario": "iss_network", "sites": "/nope/sites.yaml"}),
        "sites/paper": ("sensor_sim", {"sites": str(EXAMPLE_SITES)}),
        "elements": ("sensor_sim", {"scenario": "iss_network", "elements": "/nope/one.tle"}),
        "shard": ("catalog_filter", {"shards": 2, "shard": 2}),
        "station": ("catalog_filter", {"station": "atlantis"}),
        "fit_budget": ("catalog_surrogate", {"fit_budget": 2.0}),
        "shards": ("catalog_surrogate", {"shards": 0}),
    }
    # each on its own (no discovery): ~25 participants starting and leaving at once can
    # deadlock a Fast DDS participant that is still being created (eProsima/Fast-DDS#6502:
    # a writer proxy stopped under the PDP lock while the event thread waits for it)
    alone = {RANGE_VAR: DiscoveryRange.OFF.value}
    procs = {label: g.start_node(node, params=p, name=f"{node}_{label.replace('/', '_')}",
                                 expect_returncode=2, env=alone)
             for label, (node, p) in cases.items()}
    for label, proc in procs.items():
        name = label.split("/")[0]  # the parameter the error must name
        # ~25 interpreters start at once: on a loaded 2-core machine that takes a while
        assert g.wait_exit(proc, timeout=180.0) == 2, proc.describe()
        assert f"parameter '{name}'" in proc.stderr(), proc.describe()
        assert "Traceback" not in proc.stderr(), proc.describe()


def _call(g, client, request, what: str, attempts: int = 3):
    """The reply to `request`, sent again when none came within 10 s (nominal): a service
    can be ready (its request reader matched) before it has matched this client's reply
    reader, and then DDS drops the reply ("failed to send response"). Every request of
    these tests is idempotent."""
    g.wait_for(lambda: client.service_is_ready(), 20.0, f"service {what}")
    for attempt in range(attempts):
        future = client.call_async(request)
        try:
            g.wait_for(future.done, 10.0, f"reply of {what}")
            return future.result()
        except TimeoutError:
            if attempt == attempts - 1:
                raise
            client.remove_pending_request(future)
    raise AssertionError("unreachable")


def test_bad_param_set_at_run_time_is_refused_and_old_value_kept(ros_graph):
    g = ros_graph
    filt = g.start_node("filter", params=filter_params(gate=500.0))
    set_client = g.probe.create_client(SetParameters, "/filter/set_parameters")
    get_client = g.probe.create_client(GetParameters, "/filter/get_parameters")

    def set_param(name: str, value: ParameterValue):
        req = SetParameters.Request(parameters=[ParameterMsg(name=name, value=value)])
        return _call(g, set_client, req, "/filter/set_parameters").results[0]

    def get(name: str) -> ParameterValue:
        req = GetParameters.Request(names=[name])
        return _call(g, get_client, req, "/filter/get_parameters").values[0]

    def double(v: float) -> ParameterValue:
        return ParameterValue(type=ParameterType.PARAMETER_DOUBLE, double_value=v)

    bad = [
        ("gate", double(-5.0)),
        ("gate", ParameterValue(type=ParameterType.PARAMETER_STRING, string_value="wide")),
        ("kind", ParameterValue(type=ParameterType.PARAMETER_STRING, string_value="sonar")),
        ("p0_sigma", ParameterValue(type=ParameterType.PARAMETER_DOUBLE_ARRAY,
                                    double_array_value=[1.0, 2.0])),
        ("predict_period", double(-1.0)),
    ]
    for name, value in bad:
        result = set_param(name, value)
        assert not result.successful, (name, value)
        assert result.reason
    assert get("gate").double_value == 500.0
    assert get("kind").string_value == "range_az_el"
    assert list(get("p0_sigma").double_array_value) == PARAMS["filter"]["p0_sigma"]
    assert get("predict_period").double_value == 300.0
    assert "refused parameter 'gate'" in filt.stderr()
    good = set_param("gate", double(50.0))  # a valid value is still accepted
    assert good.successful and get("gate").double_value == 50.0
    assert filt.returncode is None


def test_a_run_time_set_gets_the_same_cross_check_as_start_up(ros_graph):
    """`ros2 param set /surrogate delays 100000` was once accepted at run time although
    the same value is refused at start (the buffer cannot hold 2 x delays x cadence)."""
    g = ros_graph
    surr = g.start_node("surrogate", params=surrogate_params())
    client = g.probe.create_client(SetParameters, "/surrogate/set_parameters")
    get_client = g.probe.create_client(GetParameters, "/surrogate/get_parameters")
    integer = ParameterValue(type=ParameterType.PARAMETER_INTEGER, integer_value=5000)
    req = SetParameters.Request(parameters=[ParameterMsg(name="delays", value=integer)])
    result = _call(g, client, req, "/surrogate/set_parameters").results[0]
    assert not result.successful and "2 x delays x cadence" in result.reason
    got = _call(g, get_client, GetParameters.Request(names=["delays"]),
                "/surrogate/get_parameters").values[0]
    assert got.integer_value == PARAMS["surrogate"]["delays"]
    small = ParameterValue(type=ParameterType.PARAMETER_DOUBLE, double_value=60.0)
    req = SetParameters.Request(parameters=[ParameterMsg(name="buffer_length", value=small)])
    assert not _call(g, client, req, "/surrogate/set_parameters").results[0].successful
    # an atomic set is judged as a whole (buffer 1200 s, cadence 30 s, delays 5): each value
    # fits with the other's old one, but not together -> refused; the reverse -> accepted
    atomic = g.probe.create_client(SetParametersAtomically,
                                   "/surrogate/set_parameters_atomically")

    def set_both(delays: int, buffer_s: float):
        req = SetParametersAtomically.Request(parameters=[
            ParameterMsg(name="delays", value=ParameterValue(
                type=ParameterType.PARAMETER_INTEGER, integer_value=delays)),
            ParameterMsg(name="buffer_length", value=ParameterValue(
                type=ParameterType.PARAMETER_DOUBLE, double_value=buffer_s))])
        return _call(g, atomic, req, "/surrogate/set_parameters_atomically").result

    result = set_both(15, 800.0)  # 2 x 15 x 30 = 900 s > 800 s
    assert not result.successful and "2 x delays x cadence" in result.reason
    assert set_both(30, 2000.0).successful  # 1800 s <= 2000 s, though 30 alone is refused
    got = _call(g, get_client, GetParameters.Request(names=["delays", "buffer_length"]),
                "/surrogate/get_parameters").values
    assert (got[0].integer_value, got[1].double_value) == (30, 2000.0)
    assert surr.returncode is None



def test_valid_param_set_at_run_time_takes_effect_and_read_only_ones_are_refused(ros_graph):
    g = ros_graph
    diag = Diag(g)
    g.start_node("filter", params=filter_params(predict_period=0.0))
    got = g.collect(StateEstimate, "/ssa/estimate")
    pub = publisher(g, Measurement, "/ssa/measurement", ("filter",))
    run_clock_at(g, diag, float(T[8]), ("filter",))
    set_client = g.probe.create_client(SetParameters, "/filter/set_parameters")

    def set_param(name: str, value: ParameterValue):
        req = SetParameters.Request(parameters=[ParameterMsg(name=name, value=value)])
        return _call(g, set_client, req, "/filter/set_parameters").results[0]

    for i in range(6):  # IOD (3) + 3 fused updates
        pub.publish(meas(i))
    g.wait_for(lambda: len(got) >= 4, 15.0, "4 estimates")
    # a gate of 1e-9 makes every further measurement an outlier: the new value is in effect
    tiny = ParameterValue(type=ParameterType.PARAMETER_DOUBLE, double_value=1e-9)
    assert set_param("gate", tiny).successful
    for i in range(6, 9):
        pub.publish(meas(i))
    diag.wait(g, "filter", {"rejected_gate": 3})
    assert len(got) == 4
    # kind and station are fixed at start-up: refused as read-only, old value kept
    sonar = ParameterValue(type=ParameterType.PARAMETER_STRING, string_value="position")
    result = set_param("kind", sonar)
    assert not result.successful and "read-only" in result.reason

# shutdown --------------------------------------------------------------------------------
TOPICS = {"/ssa/measurement": Measurement, "/ssa/forecast": Measurement,
          "/ssa/estimate": StateEstimate, "/ssa/truth": StateEstimate,
          "/ssa/withheld": Measurement, "/clock": Clock}
RUN = scenarios.DEFAULT_LIVE.with_(track_s=900.0, gap_s=300.0, after_s=600.0, delays=5)


def sensor_params(time_scale: float, **extra) -> dict:
    p = node_parameters(RUN, time_scale=time_scale, seed=2, bag=Path("unused"))["sensor_sim"]
    return {**p, **extra}


def start_graph(g, bag: Path, time_scale: float, wait_for: list[str], stamped=False):
    """Recorder, surrogate, filter, then sensor_sim; the probe collects every topic."""
    params = node_parameters(RUN, time_scale=time_scale, seed=2, bag=bag)
    received: dict[str, list] = {}
    subs = []
    for topic, t in TOPICS.items():
        lst = received.setdefault(topic, [])
        cb = (lambda m, lst=lst: lst.append(time.monotonic())) if stamped else lst.append
        subs.append(g.probe.create_subscription(t, topic, cb, DATA_QOS))
    probe_needs = report_probe_matches(g, subs)  # the probe hears the run from the first
    nodes = {n: g.start_node(n, params=params[n]) for n in ("recorder", "surrogate", "filter")}
    g.wait_for_subscriber("/ssa/forecast", 3)  # filter, recorder, probe
    nodes["sensor_sim"] = g.start_node("sensor_sim", params=sensor_params(
        time_scale, wait_for=wait_for,
        wait_for_readers=[*params["sensor_sim"]["wait_for_readers"], *probe_needs]))
    return nodes, received


def stop_together(g, procs: list) -> None:
    """SIGTERM every process in `procs` at once, then assert that each exits 0 (as
    `g.stop` one by one would, without adding their shutdown times up)."""
    for p in procs:
        p.popen.send_signal(signal.SIGTERM)
    for p in procs:
        assert g.wait_exit(p, timeout=10.0) == 0, p.describe()


ALL_SUBSCRIBED = ["/ssa/measurement=4", "/ssa/forecast=3", "/ssa/estimate=2",
                  "/ssa/truth=2", "/ssa/withheld=2", "/clock=4"]


def test_sigint_and_sigterm_mid_run_even_twice_exit_0_and_bag_holds_everything(ros_graph,
                                                                               tmp_path):
    g = ros_graph
    bag = tmp_path / "bag"
    nodes, received = start_graph(g, bag, time_scale=200.0, wait_for=ALL_SUBSCRIBED)
    g.wait_for(lambda: len(received["/ssa/estimate"]) >= 5, 30.0, "estimates mid-run")
    sensor = nodes["sensor_sim"]
    assert sensor.returncode is None  # really mid-run
    sensor.popen.send_signal(signal.SIGINT)
    sensor.popen.send_signal(signal.SIGINT)  # twice, at once
    nodes["surrogate"].popen.send_signal(signal.SIGTERM)
    nodes["surrogate"].popen.send_signal(signal.SIGTERM)
    nodes["filter"].popen.send_signal(signal.SIGINT)
    nodes["filter"].popen.send_signal(signal.SIGTERM)
    for name in ("sensor_sim", "surrogate", "filter"):
        assert g.wait_exit(nodes[name], timeout=15.0) == 0, nodes[name].describe()
    g.wait_quiet(lambda: tuple(len(v) for v in received.values()), quiet_s=0.5, limit_s=10.0)
    rec = nodes["recorder"]
    rec.popen.send_signal(signal.SIGINT)
    rec.popen.send_signal(signal.SIGINT)
    assert g.wait_exit(rec, timeout=15.0) == 0, rec.describe()

    assert (bag / "metadata.yaml").exists()
    counts = Counter(m.topic for m in bagio.read_bag(bag))
    for topic, msgs in received.items():  # every publisher had stopped: the recorder got
        assert counts[topic] == len(msgs), (topic, counts, {k: len(v) for k, v in
                                                            received.items()})
    assert counts["/ssa/measurement"] > 0


def test_recorder_stopped_during_a_burst_keeps_every_message_it_received(ros_graph, tmp_path):
    g = ros_graph
    bag = tmp_path / "bag"
    nodes, received = start_graph(g, bag, time_scale=600.0, wait_for=ALL_SUBSCRIBED)
    g.wait_for(lambda: len(received["/clock"]) >= 20, 30.0, "data flowing")
    rec = nodes["recorder"]
    rec.popen.send_signal(signal.SIGTERM)
    assert g.wait_exit(rec, timeout=15.0) == 0, rec.describe()
    logged = int(rec.stderr().split("bag closed:")[1].split("(")[1].split()[0])
    total = sum(1 for _ in bagio.read_bag(bag))
    assert total == logged > 0
    stop_together(g, [nodes[name] for name in ("sensor_sim", "surrogate", "filter")])


def test_sigterm_right_after_start_exits_0(ros_graph, tmp_path):
    g = ros_graph
    procs = [g.start_node("filter", params=filter_params()),
             g.start_node("recorder", params={"bag": str(tmp_path / "bag")})]
    for p in procs:  # as soon as the node exists: its parameters are on the graph
        g.wait_for(lambda p=p: any(n == p.name for n in g.probe.get_node_names()), 20.0,
                   f"{p.name} up")
        assert g.stop(p, signal.SIGTERM) == 0, p.describe()
    assert (tmp_path / "bag" / "metadata.yaml").exists()


def test_sigkill_of_the_recorder_leaves_a_bag_readable_up_to_its_last_flush(ros_graph,
                                                                          tmp_path):
    g = ros_graph
    bag = tmp_path / "bag"
    flush = 1.0  # the recorder's default flush_period, wall s
    nodes, received = start_graph(g, bag, time_scale=300.0, wait_for=ALL_SUBSCRIBED,
                                  stamped=True)
    g.wait_for(lambda: len(received["/clock"]) >= 1, 30.0, "data flowing")
    t_first = time.monotonic()
    g.wait_for(lambda: time.monotonic() > t_first + 2.5 * flush, 10.0, "2.5 flush periods")
    rec = nodes["recorder"]
    rec.expect_returncode = None
    t_kill = time.monotonic()
    assert g.stop(rec, signal.SIGKILL) == -signal.SIGKILL

    assert not (bag / "metadata.yaml").exists()  # written at close only
    got = Counter(m.topic for m in bagio.read_bag(bag))
    lost_bound = t_kill - flush - 0.5  # everything received before this was flushed
    for topic, stamps in received.items():
        before = sum(1 for t in stamps if t < lost_bound)
        assert before <= got[topic] <= len(stamps), (topic, before, got[topic], len(stamps))
    assert got["/clock"] > 0 and got["/ssa/measurement"] > 0
    stop_together(g, [nodes[name] for name in ("sensor_sim", "surrogate", "filter")])


def test_sensor_sim_says_what_it_waits_for(ros_graph):
    """... and what it simulates: a real-sky scenario from `start` for `duration`."""
    g = ros_graph
    clock = g.collect(Clock, "/clock")
    sensor = g.start_node("sensor_sim", params={
        "scenario": "iss_radar_columbus", "start": "2025-06-01T06:00:00Z",
        "duration": 21600.0, "wait_for": [""], "wait_for_readers": ["nobody:/ssa/measurement"]})
    g.wait_for(lambda: "waiting for: nobody:/ssa/measurement" in sensor.stderr(), 20.0,
               "sensor_sim to log what it waits for")
    assert "from columbus from 2025-06-01T06:00:00.000Z over 6 h" in sensor.stderr()
    assert clock == []  # nothing published while it waits
    assert g.stop(sensor, signal.SIGTERM) == 0, sensor.describe()


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM])
def test_sensor_sim_interrupted_twice_during_shutdown_exits_0(ros_graph, sig):
    g = ros_graph
    clock = g.collect(Clock, "/clock")
    sensor = g.start_node("sensor_sim", params=sensor_params(
        100.0, wait_for=["/clock=1"], wait_for_readers=[""]))
    g.wait_for(lambda: len(clock) >= 1, 20.0, "sensor_sim running")
    sensor.popen.send_signal(sig)
    time.sleep(0.05)  # a second interrupt while it is already shutting down
    sensor.popen.send_signal(sig)
    assert g.wait_exit(sensor, timeout=15.0) == 0, sensor.describe()


def test_a_negative_or_huge_clock_is_survived_and_no_node_dies(ros_graph, tmp_path):
    """One /clock with negative seconds used to kill filter, surrogate and
    recorder (rclpy raises in its clock handling, outside the nodes' callbacks). Now each
    counts it as rejected_clock and carries on. A clock at the end of time (int32 seconds,
    2038) is taken as a jump ahead; the return to the real clock is a jump back that resets
    filter and surrogate, and the next measurements are fused."""
    from builtin_interfaces.msg import Time

    g = ros_graph
    got, diag, clock, pub = filter_and_surrogate(g)
    rec = g.start_node("recorder", params={"use_sim_time": True, "bag": str(tmp_path / "bag")})
    nodes = (*NODES, "recorder")
    g.wait_for(lambda: diag.status("recorder") is not None, 20.0, "the recorder's diagnostics")
    set_clock(g, clock, diag, float(T[6]), NODES)
    publish_until(g, clock, Clock(clock=Time(sec=-5, nanosec=0)),
                  lambda: all(diag.counts(n).get("rejected_clock") for n in nodes),
                  "rejected_clock on every node")
    huge = float(2**31 - 1)
    set_clock(g, clock, diag, huge, NODES)
    set_clock(g, clock, diag, float(T[7]), NODES)
    for n in NODES:
        diag.wait(g, n, {"reset_clock_jump": 1})
    for i in range(6):
        pub.publish(meas(i))
    g.wait_for(lambda: len(got) >= 4, 15.0, "4 estimates after the bad clock")
    assert all(p.returncode is None for p in g.procs), g.report()
    assert rec.returncode is None
    for n in nodes:
        assert "internal_error" not in diag.counts(n), n


def test_the_forecast_topic_takes_only_forecasts_and_the_measurement_topic_only_sensors(
        ros_graph):
    """A source=SENSOR message on /ssa/forecast was once fused as a real
    measurement (and a forecast on /ssa/measurement as a forecast)."""
    g = ros_graph
    got, diag, sensor, forecasts = filter_with_both_inputs(g, float(T[7]))
    for i in range(3):
        forecasts.publish(meas(i))  # sensor data on the forecast topic
    sensor.publish(meas(3, source=types.Source.FORECAST))
    diag.wait(g, "filter", {"rejected_source": 4})
    for i in range(4, 8):
        sensor.publish(meas(i))
    c = diag.wait(g, "filter", {"rejected_source": 4, "published_sensor": 2})
    assert "internal_error" not in c
    assert [e.t for e in estimates(got)] == [float(T[6]), float(T[7])]


def test_a_payload_that_does_not_decode_is_counted_and_the_stream_goes_on(ros_graph):
    """Malformed bytes were once dropped inside rclpy with no log and no
    count. Filter and surrogate take the bytes and decode them themselves: junk is counted
    as rejected_malformed, and the sender's next messages are fused. (An *empty* payload is
    different: the publishing side never delivers it, and a reliable reader then waits for
    it forever -- DDS's in-order delivery, outside the nodes; see docs/NODES.md.)"""
    g = ros_graph
    got = g.collect(StateEstimate, "/ssa/estimate")
    diag = Diag(g)
    g.start_node("filter", params=filter_params())
    g.start_node("surrogate", params=surrogate_params())
    pub = publisher(g, Measurement, "/ssa/measurement", ("filter", "surrogate"))
    run_clock_at(g, diag, float(T[5]), NODES)
    pub.publish(b"\x00\x01\x00\x00junkjunkjunk")
    diag.wait(g, "filter", {"rejected_malformed": 1})
    diag.wait(g, "surrogate", {"rejected_malformed": 1})
    for i in range(6):
        pub.publish(meas(i))
    c = diag.wait(g, "filter", {"rejected_malformed": 1, "published_sensor": 4})
    assert "internal_error" not in c
    assert len(estimates(got)) == 4


def test_a_future_stamp_before_the_first_clock_does_not_poison_later_ones(ros_graph):
    """Before the first /clock nothing can judge a stamp: once, one
    stamped a year ahead went in and made every later measurement stale. Now measurements
    wait for the clock (held_until_clock), then the year-ahead one is refused."""
    g = ros_graph
    got, diag, clock, pub = filter_and_surrogate(g)
    year = 365.25 * 86400.0
    for m in [meas(0, year)] + [meas(i) for i in range(6)]:
        pub.publish(m)
    # at once (the nodes hold messages for 3 s without a clock, then take them unjudged)
    set_clock(g, clock, diag, float(T[7]), NODES)
    for node in NODES:
        diag.wait(g, node, {"held_until_clock": 7})
    c = diag.wait(g, "filter", {"rejected_future": 1, "published_sensor": 4})
    assert "rejected_stale" not in c and "internal_error" not in c
    c = diag.wait(g, "surrogate", {"rejected_future": 1, "buffered": 6})
    assert "rejected_stale" not in c
    assert [e.t for e in estimates(got)] == [float(T[i]) for i in range(2, 6)]


# disk full --------------------------------------------------------------------------------
@pytest.fixture
def small_disk(tmp_path):
    """A 256 KiB tmpfs mounted for the test (skipped where the machine allows no mount)."""
    import subprocess

    mnt = tmp_path / "disk"
    mnt.mkdir()
    done = subprocess.run(["mount", "-t", "tmpfs", "-o", "size=256k", "tmpfs", str(mnt)],
                          capture_output=True, text=True, check=False)
    if done.returncode:
        pytest.skip(f"cannot mount a small tmpfs here ({done.stderr.strip() or 'mount'}): "
                    "the disk-full test needs one")
    try:
        yield mnt
    finally:
        subprocess.run(["umount", "-l", str(mnt)], check=False)


def test_a_full_disk_ends_the_recorder_with_one_line_and_a_whole_bag(ros_graph, small_disk,
                                                                     tmp_path, capsys):
    """The recorder logged a traceback per message and the run went on; then it left a bag
    torn by ENOSPC that only `bag repair` could read. Now, before the disk gets too full to
    close the bag, it closes the bag whole (readable as it is), says so in one line naming
    the bag and the reason, and exits 1 (so `live` ends the run, saying why). `bag repair`
    onto the full disk itself says it cannot write and leaves nothing there."""
    from ssa_fusion.apps import cli

    g = ros_graph
    bag = small_disk / "bag"
    rec = g.start_node("recorder", params={"bag": str(bag), "flush_period": 0.2},
                       expect_returncode=1)
    pub = publisher(g, Measurement, "/ssa/measurement", ("recorder",))
    rng = np.random.default_rng(0)  # random values: zstd cannot shrink them
    sent = 0
    while rec.popen.poll() is None and sent < 200_000:
        m = types.Measurement(t=1.7e9 + sent, z=rng.standard_normal(3), R=np.diag(rng.random(3)),
                              kind=types.Kind.RANGE_AZ_EL, object_id=f"o{rng.integers(1e9)}",
                              frame_id="columbus")
        pub.publish(messages.measurement_to_msg(m))
        sent += 1
        if sent % 200 == 0:
            g.spin_once(0.01)
    assert g.wait_exit(rec, timeout=30.0) == 1, rec.describe()
    err = rec.stderr()
    assert f"cannot write the bag {bag}: No space left on device" in err, err
    assert "closed, whole, with the" in err and "Traceback" not in err, err
    said = int(err.split("closed, whole, with the ")[1].split()[0])
    recorded = sum(1 for _ in bagio.read_bag(bag))  # no repair needed
    assert 0 < recorded == said < sent
    with contextlib.suppress(OSError), (small_disk / "filler").open("wb", buffering=0) as f:
        while True:  # what the recorder kept free for closing, taken by another writer
            f.write(b"x" * 4096)
    full = small_disk / "repaired"
    assert cli.main(["bag", "repair", str(bag), "--out", str(full)]) == 2
    assert "cannot write: No space left on device" in capsys.readouterr().err
    assert not full.exists()

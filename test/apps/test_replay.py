"""Replay of recorded bags: offline through the core (equal to what was recorded live),
over ROS 2 into real surrogate + filter processes, and clear errors for bad bags."""

import copy
import shutil
from collections import Counter
from pathlib import Path

import numpy as np
import pytest

from ssa_fusion.apps import cli, evaluate, replay
from ssa_fusion.core.base import types
from ssa_fusion.ros import bagio, messages

SAMPLE = Path(__file__).resolve().parents[2] / "bags" / "sample_iss_j2_rae"
"""A recording of `make demo` (frames of the real Earth: states in the GCRF)."""
CLASSES = bagio.rosbags_classes()


def fused(bag: Path) -> dict[float, types.StateEstimate]:
    """Last published fused estimate per epoch (predictions excluded)."""
    return {e.t: e for e in evaluate.load(bag).estimates if e.update_source}


def assert_same_estimates(a: dict, b: dict, rtol: float = 1e-9) -> None:
    assert sorted(a) == sorted(b)
    for t in a:
        scale = np.abs(a[t].x).max()
        assert np.abs(a[t].x - b[t].x).max() <= rtol * scale, t
        assert a[t].update_source == b[t].update_source, t
        np.testing.assert_allclose(a[t].P, b[t].P, rtol=1e-6, atol=1e-12)


def test_sample_bag_is_small_and_complete():
    size = sum(f.stat().st_size for f in SAMPLE.iterdir())
    assert size <= 2 * 1024 * 1024
    counts = evaluate.load(SAMPLE).counts
    for topic in (*replay.PLAYED, "/ssa/estimate", "/ssa/forecast", "/clock"):
        assert counts.get(topic, 0) > 0, topic


def test_offline_replay_reproduces_the_live_estimates(tmp_path):
    out = tmp_path / "offline"
    assert cli.main(["replay", str(SAMPLE), "--offline", "--out", str(out)]) == 0
    assert_same_estimates(fused(SAMPLE), fused(out))
    # the output has the recorded layout: report works on it
    counts = evaluate.load(out).counts
    assert counts["/ssa/measurement"] == evaluate.load(SAMPLE).counts["/ssa/measurement"]
    assert counts["/ssa/forecast"] > 0


def test_offline_smoothing_is_the_definitive_orbit(tmp_path, capsys):
    """`--offline --smooth`: one smoothed estimate per fused epoch on /ssa/estimate_smoothed;
    the last equals the filter's last (nothing after it to smooth with); the others, which
    use the later measurements too, are closer to the truth (median) with smaller position
    covariance everywhere."""
    out = tmp_path / "smoothed"
    assert cli.main(["replay", str(SAMPLE), "--offline", "--smooth", "--out", str(out)]) == 0
    assert "smoothed against filtered" in capsys.readouterr().out
    smoothed = [messages.estimate_from_msg(m.msg)
                for m in bagio.read_bag(out, topics=["/ssa/estimate_smoothed"])]
    filt = fused(out)
    assert [e.t for e in smoothed] == sorted(filt)
    last = smoothed[-1]
    np.testing.assert_array_equal(last.x, filt[last.t].x)
    truth = {e.t: e.x for e in evaluate.load(out).truth}
    scored = [e for e in smoothed if e.t in truth]
    err_s = np.median([np.linalg.norm(e.x[:3] - truth[e.t][:3]) for e in scored])
    err_f = np.median([np.linalg.norm(filt[e.t].x[:3] - truth[e.t][:3]) for e in scored])
    assert len(scored) > 100 and err_s < 0.5 * err_f, (err_s, err_f)
    tr_s = np.array([np.trace(e.P[:3, :3]) for e in smoothed])
    tr_f = np.array([np.trace(filt[e.t].P[:3, :3]) for e in smoothed])
    assert np.all(tr_s <= tr_f * (1 + 1e-9))


def test_smooth_needs_offline(tmp_path, capsys):
    assert cli.main(["replay", str(SAMPLE), "--smooth", "--record", str(tmp_path / "r")]) == 2
    assert "--smooth needs --offline" in capsys.readouterr().err


def test_offline_replay_is_deterministic(tmp_path):
    stream = list(bagio.read_bag(SAMPLE))
    s = replay.settings(stream).estimator
    a = replay.replay_offline(stream, s)
    b = replay.replay_offline(stream, s)
    assert [t for t, _ in a.estimates] == [t for t, _ in b.estimates]
    for (_, ea), (_, eb) in zip(a.estimates, b.estimates, strict=True):
        assert np.array_equal(ea.x, eb.x) and np.array_equal(ea.P, eb.P)


def test_a_measurement_stamped_far_ahead_of_its_log_time_is_not_replayed():
    """A wall-time stamp in a sim-time bag: the nodes refuse it against their clock
    (rejected_future), but a replay's clock follows the stamps, so the replay drops it."""
    stream = list(bagio.read_bag(SAMPLE))
    k = next(i for i, m in enumerate(stream) if m.topic == "/ssa/measurement" and i > 500)

    def moved(seconds: int) -> bagio.BagMessage:
        m = copy.deepcopy(stream[k])
        m.msg.header.stamp.sec += seconds
        return m

    year, minute = 31_557_600, 60
    glitched = [*stream[:k + 1], moved(year), moved(minute), *stream[k + 1:]]
    kept, dropped = replay.drop_ahead_of_clock(glitched)
    assert dropped == 1
    assert kept == [*stream[:k + 1], glitched[k + 2], *stream[k + 1:]]
    # fused, the year-ahead stamp would have cost every later real measurement
    s = replay.settings(stream).estimator
    assert replay.replay_offline(glitched, s).rejected.get("rejected_stale", 0) > 100


def test_bare_mcap_like_ros2_bag_record(tmp_path):
    """A bag written by another tool (the mcap-ros2 writer, as rosbag2 writes MCAP) with
    only the sensor's topics is accepted by replay and gets forecasts by the clock."""
    from mcap_ros2.writer import Writer as Ros2Writer

    msgdefs = {name: (bagio._msg_dir() / f"{name}.msg").read_text()
               for name in bagio.MSG_TYPES}
    path = tmp_path / "recorded.mcap"
    store = bagio.typestore()
    with path.open("wb") as f:
        writer = Ros2Writer(f)
        schemas = {
            "Measurement": writer.register_msgdef(
                "ssa_fusion_msgs/msg/Measurement",
                store.generate_msgdef("ssa_fusion_msgs/msg/Measurement", ros_version=2)[0]),
            "StateEstimate": writer.register_msgdef(
                "ssa_fusion_msgs/msg/StateEstimate",
                store.generate_msgdef("ssa_fusion_msgs/msg/StateEstimate", ros_version=2)[0]),
        }
        assert msgdefs  # the package's own definitions exist
        for m in bagio.read_bag(SAMPLE, topics=replay.PLAYED):
            schema = schemas[m.msgtype.rsplit("/", 1)[1]]
            writer.write_message(m.topic, schema, _as_dict(m.msg), log_time=m.t_ns,
                                 publish_time=m.t_ns)
        writer.finish()
    out = tmp_path / "offline"
    assert cli.main(["replay", str(path), "--offline", "--out", str(out)]) == 0
    got = evaluate.load(out)
    assert got.counts["/ssa/forecast"] > 0.8 * got.counts["/ssa/withheld"]
    ev = evaluate.evaluate(got)
    assert ev.gap.coverage > 0.8
    assert cli.main(["report", str(out), "--out", str(tmp_path / "report")]) == 0
    assert (tmp_path / "report" / "arms.png").exists()


def test_a_bag_at_another_cadence_is_replayed_at_its_own(tmp_path):
    """10 s data under the default settings' 30 s cadence: the replay infers the cadence from
    the stamps (as the surrogate node does with cadence 0), fits at the gap and forecasts
    every missed epoch, the last ones released with the measurement that ends the gap."""
    from ssa_fusion.sim import scenarios, simulate

    s = scenarios.DEFAULT_LIVE.with_(cadence_s=10.0, track_s=9000.0, gap_s=1200.0,
                                     after_s=600.0)
    sim = simulate.simulate(s, seed=4)
    bag = tmp_path / "ten_s"
    writer = bagio.BagWriter(bag)
    writer.add_topic("/ssa/measurement", "ssa_fusion_msgs/msg/Measurement")
    classes = bagio.rosbags_classes()
    for i in np.flatnonzero(~sim.in_gap):
        m = types.Measurement(t=float(sim.t[i]), z=sim.z[i], R=sim.R, kind=s.kind,
                              object_id="iss", frame_id=s.station)
        writer.write_msg("/ssa/measurement", round(float(sim.t[i]) * 1e9),
                         messages.measurement_to_msg(m, classes))
    writer.close()
    stream = list(bagio.read_bag(bag))
    settings = replay.settings(stream).estimator
    assert settings.surrogate.cadence_s == 0.0 and replay.bag_cadence(stream) == 10.0
    own = replay.settings(list(bagio.read_bag(SAMPLE))).estimator
    assert own.surrogate.cadence_s == 30.0  # its own kept
    result = replay.replay_offline(stream, settings)
    gap = sim.t[sim.in_gap]
    np.testing.assert_allclose(sorted(f.t for _, f in result.forecasts), gap, rtol=0,
                               atol=1e-6)
    fused = {round(e.t, 3) for _, e in result.estimates
             if e.update_source == types.UpdateSource.FORECAST}
    assert fused == {round(float(t), 3) for t in gap}


def _as_dict(msg):
    """rosbags message -> nested dict (what the mcap-ros2 writer takes)."""
    if hasattr(msg, "__dataclass_fields__"):
        return {k: _as_dict(getattr(msg, k)) for k in msg.__dataclass_fields__}
    if isinstance(msg, np.ndarray):
        return msg.tolist()
    return msg


def test_unknown_topic_is_named(tmp_path, capsys):
    bag = tmp_path / "odd"
    writer = bagio.BagWriter(bag)
    writer.add_topic("/ssa/measurement", "ssa_fusion_msgs/msg/Measurement")
    writer.add_topic("/radar/raw", "std_msgs/msg/String")
    store = bagio.typestore()
    for m in bagio.read_bag(SAMPLE, topics=["/ssa/measurement"]):
        writer.write_msg("/ssa/measurement", m.t_ns, messages.recode(m.msg, m.msgtype, CLASSES))
        break
    writer.write_msg("/radar/raw", 1, store.types["std_msgs/msg/String"](data="x"))
    writer.close()
    assert cli.main(["replay", str(bag), "--offline"]) == 2
    err = capsys.readouterr().err
    assert "/radar/raw" in err and "unknown topic" in err


def test_truncated_bag_gives_a_clear_error(tmp_path, capsys):
    bag = tmp_path / "cut"
    shutil.copytree(SAMPLE, bag)
    mcap = next(bag.glob("*.mcap"))
    data = mcap.read_bytes()
    mcap.write_bytes(data[: len(data) // 3])
    assert cli.main(["replay", str(bag), "--offline"]) == 2
    err = capsys.readouterr().err
    assert str(bag) in err and "cannot read" in err


def test_missing_bag_gives_a_clear_error(tmp_path, capsys):
    assert cli.main(["replay", str(tmp_path / "nope"), "--offline"]) == 2
    assert "no such bag" in capsys.readouterr().err


LATER_S = 32_000.0
"""Where `later_part` of the sample bag starts (s after its first message): the second half,
which still holds enough measurements before the gap (~800) for the surrogate's 372-delay
fit, so the gap is forecast as in the whole bag."""


def write_bag(path: Path, stream: list[bagio.BagMessage]) -> None:
    """Write `stream` (messages read from a bag) to a new bag at `path`, as it was logged."""
    writer = bagio.BagWriter(path)
    for topic, msgtype in {m.topic: m.msgtype for m in stream}.items():
        writer.add_topic(topic, msgtype)
    for m in stream:
        writer.write_msg(m.topic, m.t_ns, messages.recode(m.msg, m.msgtype, CLASSES))
    writer.close()


@pytest.fixture(scope="module")
def later_part(tmp_path_factory) -> Path:
    """The sample bag from `LATER_S` on, with its recorded settings (/ssa/config)."""
    stream = list(bagio.read_bag(SAMPLE))
    start = stream[0].t_ns + round(LATER_S * 1e9)
    bag = tmp_path_factory.mktemp("later") / "later_part"
    write_bag(bag, [m for m in stream if m.topic == "/ssa/config" or m.t_ns >= start])
    return bag


@pytest.mark.graph
def test_replay_over_ros2_loses_nothing_and_matches_offline(tmp_path, later_part):
    """The second half of the sample bag (`later_part`: the gap and its forecasts, half the
    playback time of the whole) played over ROS 2 into surrogate + filter processes.

    Nothing played is lost, and the offline replay of the recording reproduces every
    estimate up to the gap exactly. In the gap a ROS replay runs open loop: the filter
    decides an epoch at its own wall tick (0.1 s: 200 s of sim time at rate 2000), so
    whether a forecast published near that moment is fused depends on the machine's load
    (the recorder hears it at another instant); both must fuse forecasts there, the
    forecasts the graph fused being ones it recorded. (A run in lockstep is reproduced
    exactly through its gap: test/graph/test_replay_equivalence.py.)
    """
    record = tmp_path / "replayed"
    assert cli.main(["replay", str(later_part), "--rate", "2000", "--record",
                     str(record)]) == 0
    counts = Counter(m.topic for m in bagio.read_bag(record))
    played = Counter(m.topic for m in bagio.read_bag(later_part, topics=replay.PLAYED))
    for topic in replay.PLAYED:
        assert counts[topic] == played[topic], topic  # nothing lost
    assert counts["/ssa/forecast"] > 0 and counts["/ssa/estimate"] > 0
    # what the replayed graph recorded, the offline replay of its bag reproduces
    offline = tmp_path / "offline"
    assert cli.main(["replay", str(record), "--offline", "--out", str(offline)]) == 0
    live, again = fused(record), fused(offline)
    gap = min(t for t, e in [*live.items(), *again.items()]
              if e.update_source == types.UpdateSource.FORECAST)
    assert_same_estimates({t: e for t, e in live.items() if t < gap},
                          {t: e for t, e in again.items() if t < gap})
    assert len([t for t in live if t < gap]) > 500  # the fit's measurements before the gap
    forecast_epochs = {messages.stamp_to_seconds(m.msg.header.stamp)
                       for m in bagio.read_bag(record, topics=["/ssa/forecast"])}
    for estimates in (live, again):
        by_forecast = {t for t, e in estimates.items()
                       if e.update_source == types.UpdateSource.FORECAST}
        assert by_forecast and by_forecast <= forecast_epochs


@pytest.mark.graph
def test_replay_over_ros2_of_a_measurement_only_bag(tmp_path):
    """A bag with nothing but /ssa/measurement (as a sensor's own recording would be) plays:
    the graph starts without /ssa/truth or /ssa/withheld publishers and estimates."""
    bag = tmp_path / "meas_only"
    writer = bagio.BagWriter(bag)
    writer.add_topic("/ssa/measurement", "ssa_fusion_msgs/msg/Measurement")
    played = list(bagio.read_bag(SAMPLE, topics=["/ssa/measurement"]))[:40]
    for m in played:
        writer.write_msg("/ssa/measurement", m.t_ns, messages.recode(m.msg, m.msgtype, CLASSES))
    writer.close()
    record = tmp_path / "replayed"
    assert cli.main(["replay", str(bag), "--rate", "3000", "--record", str(record)]) == 0
    counts = Counter(m.topic for m in bagio.read_bag(record))
    assert counts["/ssa/measurement"] == len(played)
    assert counts["/ssa/estimate"] >= len(played) - 2  # every epoch after IOD


def test_a_huge_range_in_the_iod_batch_neither_crashes_replay_nor_report(tmp_path, capsys):
    """One range >= 1e6 km among the first three measurements once raised
    from the IOD, and `replay --offline` and `report` of such a bag ended in a traceback.
    Now the measurement is refused (rejected_implausible) and both finish."""
    stream = list(bagio.read_bag(SAMPLE))
    first = [i for i, m in enumerate(stream) if m.topic == "/ssa/measurement"][:2]
    for i, r in zip(first, (1e300, 1e9), strict=True):
        stream[i] = copy.deepcopy(stream[i])
        stream[i].msg.z[0] = r * 1000.0  # m
    result = replay.replay_offline(stream, replay.settings(stream).estimator)
    assert result.rejected.get("rejected_implausible") == 2
    assert len(result.estimates) > 1000
    bag = tmp_path / "huge"
    replay.write_offline(bag, stream, result)
    assert cli.main(["report", str(bag), "--out", str(tmp_path / "rep")]) == 0
    assert "dmd_ekf" in capsys.readouterr().out


def test_a_malformed_payload_in_the_bag_is_skipped_and_counted(tmp_path, capsys):
    """The recorder stores what arrives, and one undecodable payload once
    made `report` and `replay` reject the whole bag. Now it is skipped and counted."""
    stream = list(bagio.read_bag(SAMPLE))
    bag = tmp_path / "junk"
    writer = bagio.BagWriter(bag)
    topics = {m.topic: m.msgtype for m in stream}
    for topic, msgtype in topics.items():
        writer.add_topic(topic, msgtype)
    k = next(i for i, m in enumerate(stream) if m.topic == "/ssa/measurement" and i > 100)
    for i, m in enumerate(stream):
        writer.write_msg(m.topic, m.t_ns, messages.recode(m.msg, m.msgtype, CLASSES))
        if i == k:
            writer.write(m.topic, m.t_ns + 1, b"\x00\x01\x00\x00junk")
    writer.close()
    data = evaluate.load(bag)
    assert data.counts["undecodable /ssa/measurement"] == 1
    assert data.counts["/ssa/measurement"] == evaluate.load(SAMPLE).counts["/ssa/measurement"]
    assert cli.main(["report", str(bag), "--out", str(tmp_path / "rep")]) == 0
    assert "1 message(s) on /ssa/measurement do not decode" in capsys.readouterr().err

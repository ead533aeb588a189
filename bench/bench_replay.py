"""Benchmark of replay (issue targets): offline replay of a 24 h bag at 10 s cadence
(8,640 measurements, a two-orbit gap) in <= 10 s, and a replay over ROS 2 at --rate 100
that loses no message.

Usage: .venv/bin/python bench/bench_replay.py [--ros-hours H]   (prints parseable lines)
"""

from __future__ import annotations

import argparse
import statistics
import subprocess
import sys
import tempfile
import time
from collections import Counter
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from ssa_fusion import limit_blas_threads

limit_blas_threads()

from ssa_fusion import bagio, messages, replay  # noqa: E402
from ssa_fusion.core import scenarios, simulate, types  # noqa: E402
from ssa_fusion.qos import TOPIC_MEASUREMENT, TOPIC_TRUTH, TOPIC_WITHHELD  # noqa: E402


def write_day_bag(path: Path, hours: float = 24.0, cadence: float = 10.0) -> int:
    """A bag like sensor_sim + recorder write: measurements, withheld, truth (no ROS)."""
    base = scenarios.DEFAULT_LIVE
    gap = 2 * scenarios.ISS_PERIOD_S // cadence * cadence
    track = 12 * 3600.0
    s = base.with_(cadence_s=cadence, track_s=track, gap_s=gap,
                   after_s=hours * 3600.0 - track - gap)
    sim = simulate.simulate(s, seed=1)
    classes = bagio.rosbags_classes()
    w = bagio.BagWriter(path)
    w.add_topic(TOPIC_MEASUREMENT, "ssa_fusion_msgs/msg/Measurement")
    w.add_topic(TOPIC_WITHHELD, "ssa_fusion_msgs/msg/Measurement")
    w.add_topic(TOPIC_TRUTH, "ssa_fusion_msgs/msg/StateEstimate")
    for i, t in enumerate(sim.t):
        ns = round(float(t) * 1e9)
        m = types.Measurement(t=float(t), z=sim.z[i], R=sim.R, kind=s.kind, object_id="iss",
                              frame_id=s.station)
        topic = TOPIC_WITHHELD if sim.in_gap[i] else TOPIC_MEASUREMENT
        w.write_msg(topic, ns, messages.measurement_to_msg(m, classes))
        w.write_msg(TOPIC_TRUTH, ns, messages.estimate_to_msg(
            types.StateEstimate(t=float(t), x=sim.x[i], object_id="iss"), classes))
    w.close()
    return int((~sim.in_gap).sum())


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--ros-hours", type=float, default=1.0,
                    help="hours of bag replayed over ROS 2 at rate 100 (default 1)")
    ap.add_argument("--repeats", type=int, default=3)
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        bag = Path(tmp) / "day"
        n = write_day_bag(bag)
        print(f"bag_measurements: {n}  withheld: "
              f"{Counter(m.topic for m in bagio.read_bag(bag))[TOPIC_WITHHELD]}")
        times = []
        for _ in range(args.repeats):
            t0 = time.perf_counter()
            stream = list(bagio.read_bag(bag))
            result = replay.replay_offline(stream, replay.settings(stream))
            times.append(time.perf_counter() - t0)
        print(f"offline_replay_24h_s_median: {statistics.median(times):.2f}  "
              f"min: {min(times):.2f}  (read + estimate; target <= 10)")
        print(f"offline_estimates: {len(result.estimates)}  forecasts: {len(result.forecasts)}")

        short = Path(tmp) / "short"
        write_day_bag(short, hours=args.ros_hours, cadence=10.0)
        played = Counter(m.topic for m in bagio.read_bag(short))
        rec = Path(tmp) / "rec"
        t0 = time.perf_counter()
        code = subprocess.call([sys.executable, "-m", "ssa_fusion.cli", "replay", str(short),
                                "--rate", "100", "--record", str(rec)])
        wall = time.perf_counter() - t0
        got = Counter(m.topic for m in bagio.read_bag(rec))
        lost = {t: played[t] - got[t] for t in played}
        print(f"ros_replay_rate100_hours: {args.ros_hours}  exit: {code}  wall_s: {wall:.1f}")
        print(f"ros_replay_rate100_lost: {lost}  (played {dict(played)})")


if __name__ == "__main__":
    main()

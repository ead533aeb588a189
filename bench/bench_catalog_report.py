"""Benchmark of `ssa-fusion report` on a catalog's bag: time and memory per row.

A bag is generated: `--objects` synthetic objects of the sample catalog measured by the
radar network for `--hours` (`survey.observe_catalog`), one estimate per object and
measurement epoch (the SGP4 truth plus a 50 m Gaussian position error, its covariance
50 m per axis), the truth of every estimate on ``/ssa/truth`` (EstimateBatch), and the
catalog_filter's settings on ``/ssa/config``, in batches of `--batch-s` of sim time (a
catalog run's steps). Then ``ssa-fusion report BAG`` runs in a subprocess of its own: its
wall time and peak resident memory, and the rows per second, from which the cost of a
30,000-object day (`DAY_ROWS` measurement rows and as many estimates) is extrapolated
linearly (said so: it is not measured).

The benchmark asserts that the report scored every object, every estimate against its
truth and every measurement's residual, and that the pooled position error is the
generated one's (median of a 3-D Gaussian's norm: 1.538 σ, within 5 %).

Usage: .venv/bin/python bench/bench_catalog_report.py [--objects 200] [--hours 48]
       [--batch-s 60] [--keep DIR]
(prints parseable lines; the last one is JSON)
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from ssa_fusion.core.base.rows import EstimateRows, MeasurementRows  # noqa: E402
from ssa_fusion.core.base.types import UpdateSource  # noqa: E402
from ssa_fusion.core.earth.stations import NETWORKS, SENSORS  # noqa: E402
from ssa_fusion.core.motion.element_sets import catalog_states  # noqa: E402
from ssa_fusion.formats import element_sets as catalog  # noqa: E402
from ssa_fusion.params import settings  # noqa: E402
from ssa_fusion.params.defaults import CATALOG_FILTER  # noqa: E402
from ssa_fusion.ros import bagio, messages  # noqa: E402
from ssa_fusion.ros.topics import (  # noqa: E402
    TOPIC_CONFIG,
    TOPIC_ESTIMATE_BATCH,
    TOPIC_MEASUREMENT_BATCH,
    TOPIC_TRUTH,
)
from ssa_fusion.sim import survey  # noqa: E402

SAMPLE = ROOT / "config" / "catalogs" / "sample.tle"
SIGMA_KM = 0.05
"""1-σ per axis of the generated estimates' position error (km)."""
MEDIAN_NORM = 1.5382
"""Median of the norm of a 3-D standard Gaussian (χ with 3 dof)."""
DAY_ROWS = 45_000_000
"""Measurement rows of a 30,000-object day of the radar network (as many estimates)."""


def write_bag(bag: Path, objects: int, hours: float, batch_s: float) -> tuple[int, int]:
    """Write the benchmark's bag (module docstring); return (measurement, estimate) rows."""
    radars = [SENSORS[s] for s in NETWORKS["radar_network"]]
    base = catalog.read_catalog(SAMPLE)[0]
    entries = survey.synthetic_catalog(base, objects, seed=1)
    obs = survey.observe_catalog(entries, radars, base.epoch_unix, hours * 3600.0, seed=1)
    ids = np.asarray(obs.object_ids, dtype=object)
    meas = MeasurementRows(obs.t, ids[obs.obj].tolist(),
                           [radars[j].station.name for j in obs.sensor], obs.z,
                           np.stack([r.R for r in radars])[obs.sensor],
                           shard_key=messages.shard_keys(ids[obs.obj].tolist()))
    rng = np.random.default_rng(1)
    c = bagio.rosbags_classes()
    w = bagio.BagWriter(bag)
    w.add_topic(TOPIC_CONFIG, "std_msgs/msg/String")
    params = {**dataclasses.asdict(CATALOG_FILTER),
              "station": ",".join(r.station.name for r in radars)}
    w.write_msg(TOPIC_CONFIG, int(obs.t[0] * 1e9), bagio.typestore().types[
        "std_msgs/msg/String"](data=settings.catalog_config_message(params)))
    for topic, msgtype in ((TOPIC_MEASUREMENT_BATCH, bagio.MEASUREMENT_BATCH),
                           (TOPIC_ESTIMATE_BATCH, bagio.ESTIMATE_BATCH),
                           (TOPIC_TRUTH, bagio.ESTIMATE_BATCH)):
        w.add_topic(topic, msgtype)
    step = np.floor((obs.t - obs.t[0]) / batch_s).astype(np.int64)
    bounds = np.flatnonzero(np.diff(step)) + 1
    n_est = 0
    P = np.diag([SIGMA_KM ** 2] * 3 + [1e-8] * 3)
    for part in np.split(np.arange(len(obs.t)), bounds):
        t_ns = int((obs.t[0] + (step[part[0]] + 1) * batch_s) * 1e9)
        w.write_msg(TOPIC_MEASUREMENT_BATCH, t_ns,
                    messages.measurement_batch_to_msg(meas.take(part), classes=c))
        pairs = np.unique(np.stack([obs.obj[part].astype(float), obs.t[part]]), axis=1)
        obj, t = pairs[0].astype(np.int64), pairs[1]
        epochs = np.unique(t)
        truth = catalog_states(entries, epochs).x[obj, np.searchsorted(epochs, t)]
        x = truth.copy()
        x[:, :3] += rng.normal(scale=SIGMA_KM, size=(len(t), 3))
        oid = ids[obj].tolist()
        keys = messages.shard_keys(oid)
        est = EstimateRows(t, oid, x, np.broadcast_to(P, (len(t), 6, 6)).copy(),
                           rng.chisquare(3, len(t)), UpdateSource.SENSOR, keys)
        tr = EstimateRows(t, oid, truth, np.zeros((len(t), 6, 6)), np.zeros(len(t)),
                          UpdateSource.NONE, keys)
        w.write_msg(TOPIC_ESTIMATE_BATCH, t_ns + 1, messages.estimate_batch_to_msg(est, classes=c))
        w.write_msg(TOPIC_TRUTH, t_ns + 1, messages.estimate_batch_to_msg(tr, classes=c))
        n_est += len(t)
    w.close()
    return len(obs.t), n_est


def _rss_mib() -> float:
    """Peak resident memory of this process so far (MiB)."""
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024


def run_child(bag: Path, out: Path) -> int:
    """Run ``ssa-fusion report BAG --out OUT`` here, timed after its imports; print JSON."""
    t0 = time.perf_counter()
    from ssa_fusion.apps import cli, report_catalog  # noqa: F401  (what the report imports)
    from ssa_fusion.core.catalog import batch_ekf  # noqa: F401

    imported, imported_mib = time.perf_counter() - t0, _rss_mib()
    t0 = time.perf_counter()
    code = cli.main(["report", str(bag), "--out", str(out)])
    took = time.perf_counter() - t0
    print(json.dumps({"code": code, "import_s": imported, "imported_mib": imported_mib,
                      "report_s": took, "peak_mib": _rss_mib()}))
    return code


def main() -> int:
    """Run the benchmark (module docstring); return 0."""
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--objects", type=int, default=200)
    p.add_argument("--hours", type=float, default=48.0)
    p.add_argument("--batch-s", type=float, default=60.0, help="sim s of rows a batch")
    p.add_argument("--keep", type=Path, default=None, help="directory to keep the bag in")
    p.add_argument("--child", nargs=2, type=Path, help=argparse.SUPPRESS)
    args = p.parse_args()
    if args.child:
        return run_child(*args.child)
    with tempfile.TemporaryDirectory() as tmp:
        where = args.keep or Path(tmp)
        where.mkdir(parents=True, exist_ok=True)
        bag, out = where / "bag", where / "bag_report"
        t0 = time.perf_counter()
        n_meas, n_est = write_bag(bag, args.objects, args.hours, args.batch_s)
        made = time.perf_counter() - t0
        mib = sum(f.stat().st_size for f in bag.iterdir()) / 2 ** 20
        print(f"bag: {args.objects} objects, {args.hours:g} h, {n_meas} measurement rows, "
              f"{n_est} estimate rows (and as many truth rows), {mib:.0f} MiB, written in "
              f"{made:.1f} s")
        run = subprocess.run([sys.executable, __file__, "--child", str(bag), str(out)],
                             capture_output=True, text=True, cwd=ROOT, check=False)
        assert run.returncode == 0, run.stderr
        child = json.loads(run.stdout.strip().splitlines()[-1])
        rep = json.loads((out / "report.json").read_text())
    s = rep["summary"]
    assert s["objects"] == s["objects_with_truth"] == args.objects, s
    assert s["measurements"] == s["residual_rows"] == n_meas, s
    assert s["estimates"] == s["position_error_km"]["rows"] == s["nees"]["rows"] == n_est, s
    median = s["position_error_km"]["median"]
    assert abs(median / (MEDIAN_NORM * SIGMA_KM) - 1.0) < 0.05, median
    wall, peak_mib = child["report_s"], child["peak_mib"]
    grew = peak_mib - child["imported_mib"]
    rows_per_s = (n_meas + n_est) / wall
    day_s = 2 * DAY_ROWS / rows_per_s
    day_gib = grew / 1024 * DAY_ROWS / max(n_meas, 1)
    print(f"report: {wall:.1f} s wall after imports ({child['import_s']:.1f} s of imports), "
          f"peak RSS {peak_mib:.0f} MiB ({grew:.0f} MiB over the imports'), "
          f"{rows_per_s:.0f} rows/s (measurements and estimates)")
    print(f"pooled position error: median {median * 1000:.1f} m (generated "
          f"{MEDIAN_NORM * SIGMA_KM * 1000:.1f} m), NEES inside the band "
          f"{100 * s['nees']['inside']:.1f} %, post-fit residual RMS "
          f"{s['postfit_residual_rms_sigma']:.2f} σ")
    print(f"extrapolated linearly (not measured) to a 30,000-object day ({DAY_ROWS} "
          f"measurement rows, as many estimates): {day_s / 60:.0f} min, ~{day_gib:.0f} GiB "
          f"more than the imports if memory scales with rows as here")
    print(json.dumps({"objects": args.objects, "hours": args.hours, "measurement_rows": n_meas,
                      "estimate_rows": n_est, "bag_mib": round(mib, 1),
                      "import_s": round(child["import_s"], 2), "report_s": round(wall, 2),
                      "report_peak_rss_mib": round(peak_mib), "over_imports_mib": round(grew),
                      "rows_per_s": round(rows_per_s),
                      "extrapolated_day_30000_min": round(day_s / 60, 1),
                      "extrapolated_day_30000_gib": round(day_gib, 1)}))
    return 0


if __name__ == "__main__":
    sys.exit(main())

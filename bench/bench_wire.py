"""Benchmark: measurements per second one catalog_filter shard takes over DDS (not a test).

One ``catalog_filter`` process (one shard, the radars of ``iss_network``, a private ROS
domain on loopback) is fed the measurements of ``--objects`` synthetic LEO objects over
``--hours`` (`sim.survey`: real passes, SGP4 truth, the radars' noise) by this process, as
fast as it takes them: at most ``--window`` measurements are in flight (published, not yet
taken), the node's lockstep progress (``/lockstep``: fused, refused or dropped) saying what
it took. Twice, each time with a fresh node:

* batches: ``MeasurementBatch`` on ``/ssa/measurement_batch``, ``--batch`` rows each (the
  first ``--rows`` measurements);
* per message: one ``Measurement`` per measurement on ``/ssa/measurement`` (the first
  ``--messages``), the path catalog runs took before the batches.

Times run from the first publication to the last measurement taken. Prints each path's
measurements, seconds and measurements/s, their ratio and whether one shard takes
``TARGET`` measurements/s; asserts that every measurement published was taken and
received (the node's /diagnostics). The last line is one JSON object.

    nice -n 10 python bench/bench_wire.py [--objects 1000] [--hours 6] [--batch 2000]
"""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import argparse
import json
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # run from a source checkout

from ssa_fusion.core import catalog as catalog_io
from ssa_fusion.core.rows import MeasurementRows
from ssa_fusion.core.types import Kind, Measurement
from ssa_fusion.nodes.diagnostics import Count
from ssa_fusion.nodes.progress import TAKEN, ProgressWatch
from ssa_fusion.ros import messages
from ssa_fusion.ros.interfaces import DiagnosticArray, MeasurementBatch, Message
from ssa_fusion.ros.interfaces import Measurement as MeasurementMsg
from ssa_fusion.ros.processes import Graph
from ssa_fusion.ros.readiness import ReadyNodes
from ssa_fusion.ros.topics import (
    CATALOG_QOS,
    TOPIC_DIAGNOSTICS,
    TOPIC_MEASUREMENT,
    TOPIC_MEASUREMENT_BATCH,
)
from ssa_fusion.sim import sky, survey

TARGET = 100_000
"""Measurements/s one filter shard is to take from batches."""
SAMPLE = Path(__file__).resolve().parents[1] / "config" / "catalogs" / "sample.tle"
NODE = "catalog_filter"


def measurements(objects: int, hours: float) -> MeasurementRows:
    """The radars of iss_network measuring `objects` LEO objects for `hours`, epoch order."""
    radars = sky.SKY_SCENARIOS["iss_network"].radars
    entries = survey.synthetic_catalog(catalog_io.read_catalog(SAMPLE)[0], objects, seed=1)
    obs = survey.observe_catalog(entries, radars, survey.catalog_start(entries),
                                 hours * 3600.0, seed=1)
    ids = list(obs.object_ids)
    oid = np.asarray(ids, dtype=object)[obs.obj].tolist()
    frames = np.asarray([r.station.name for r in radars], dtype=object)[obs.sensor].tolist()
    R = np.array([r.R for r in radars])[obs.sensor]
    return MeasurementRows(obs.t, oid, frames, obs.z, R, shard_key=messages.shard_keys(oid))


def feed(g: Graph, label: str, total: int, window: int,
         publish_next: Callable[[], int]) -> dict[str, float]:
    """Run one path: start a filter node, publish by `publish_next` (returns the rows it
    sent, 0 when all are) keeping at most `window` rows in flight, until it took `total`."""
    node = g.start_node("catalog_filter", "-r", f"__node:={NODE}", name=f"{NODE}_{label}",
                        params={"use_sim_time": True, "station": "millstone,tira,altair"})
    watch = ProgressWatch(g.probe)
    diags = g.collect(DiagnosticArray, TOPIC_DIAGNOSTICS)
    topic = TOPIC_MEASUREMENT_BATCH if label == "batches" else TOPIC_MEASUREMENT
    ready = ReadyNodes(g.probe)
    g.wait_for(lambda: ready.ready([f"{NODE}:{topic}"]), 60.0, f"{NODE} to match {topic}")

    def taken() -> int:
        return int(watch.reports.get(NODE, {}).get(TAKEN, "0"))

    sent = 0
    t0 = time.perf_counter()
    while taken() < total:
        while sent < total and sent - taken() < window:
            sent += publish_next()
        g.spin_once(0.001)
    seconds = time.perf_counter() - t0
    g.wait_for(lambda: any(st.name == NODE and _count(st, Count.RECEIVED) >= total
                           for d in diags[-5:] for st in d.status), 10.0, "a last report")
    received = max(_count(st, Count.RECEIVED) for d in diags for st in d.status
                   if st.name == NODE)
    g.stop(node)
    rate = total / seconds
    print(f"{label}: {total} measurements published, {taken()} taken, {received} received, "
          f"in {seconds:.2f} s = {rate:,.0f} measurements/s")
    assert sent == total == taken() == received, (sent, total, taken(), received)
    return {"measurements": total, "seconds": round(seconds, 3), "per_s": round(rate)}


def _count(status: Message, key: str) -> int:
    for kv in status.values:
        if kv.key == key:
            return int(kv.value)
    return 0


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--objects", type=int, default=1000)
    ap.add_argument("--hours", type=float, default=6.0)
    ap.add_argument("--batch", type=int, default=2000, help="rows per MeasurementBatch")
    ap.add_argument("--rows", type=int, default=150_000, help="measurements sent in batches")
    ap.add_argument("--messages", type=int, default=10_000,
                    help="measurements sent one per message")
    ap.add_argument("--window", type=int, default=20_000, help="most measurements in flight")
    args = ap.parse_args()
    t = time.perf_counter()
    rows = measurements(args.objects, args.hours)
    print(f"simulated: {len(rows)} measurements of {args.objects} objects over {args.hours:g} h "
          f"({time.perf_counter() - t:.1f} s)")
    n_rows, n_msgs = min(args.rows, len(rows)), min(args.messages, len(rows))
    assert n_rows >= 10 * args.batch, "too few measurements for the batch size"
    batches = [messages.measurement_batch_to_msg(rows.take(np.arange(i, min(i + args.batch,
                                                                              n_rows))))
               for i in range(0, n_rows, args.batch)]
    singles = [messages.measurement_to_msg(Measurement(
        float(rows.t[i]), rows.z[i], rows.R[i], kind=Kind.RANGE_AZ_EL,
        object_id=rows.object_id[i], frame_id=rows.frame_id[i])) for i in range(n_msgs)]
    with tempfile.TemporaryDirectory() as tmp:
        g = Graph(Path(tmp) / "logs")
        try:
            pub_b = g.probe.create_publisher(MeasurementBatch, TOPIC_MEASUREMENT_BATCH,
                                             CATALOG_QOS)
            pub_m = g.probe.create_publisher(MeasurementMsg, TOPIC_MEASUREMENT, CATALOG_QOS)
            it_b, it_m = iter(batches), iter(singles)

            def next_batch() -> int:
                msg = next(it_b)
                pub_b.publish(msg)
                return len(msg.object_id)

            def next_message() -> int:
                pub_m.publish(next(it_m))
                return 1

            result = {"batches": feed(g, "batches", n_rows, args.window, next_batch),
                      "per_message": feed(g, "per_message", n_msgs, min(args.window, 2000),
                                          next_message)}
        finally:
            problems = g.close()
    ratio = result["batches"]["per_s"] / result["per_message"]["per_s"]
    met = result["batches"]["per_s"] >= TARGET
    print(f"batches / per message: {ratio:.1f}x; target {TARGET:,} measurements/s through one "
          f"shard: {'met' if met else 'NOT met'}")
    if problems:
        print("graph: " + "; ".join(problems))
    print(json.dumps({"objects": args.objects, "hours": args.hours, "batch_rows": args.batch,
                      **result, "ratio": round(ratio, 1), "target_per_s": TARGET,
                      "target_met": met}))


if __name__ == "__main__":
    main()

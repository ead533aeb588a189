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
  ``--messages``), the path catalog runs took before the batches;
* the wire alone: the batches again, all published at once, to a node whose fusion is put
  off (``batch_period`` an hour): measurements received (through DDS, deserialised, checked
  row by row, vectorised), not fused.

Times run from the first publication to the last measurement taken (received, for the
wire alone): taken includes the fusion (`TrackBank`: IOD and the J2 EKF), which bounds it.
The node's CPU seconds over the same span are read from ``/proc`` (Linux): on a shared
machine the wall rate follows the CPU the node was given, its measurements per CPU second
much less.
The single messages go through the wire alone too (``wire_per_message``). Prints each path's
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

from ssa_fusion.core.base.rows import MeasurementRows
from ssa_fusion.core.base.types import Kind, Measurement
from ssa_fusion.formats import element_sets as catalog_io
from ssa_fusion.nodes.kit.diagnostics import Count
from ssa_fusion.nodes.kit.progress import TAKEN, ProgressWatch
from ssa_fusion.ros import messages
from ssa_fusion.ros.interfaces import Measurement as MeasurementMsg
from ssa_fusion.ros.interfaces import MeasurementBatch
from ssa_fusion.ros.processes import Graph
from ssa_fusion.ros.qos import CATALOG_WRITER_QOS
from ssa_fusion.ros.readiness import ReadyNodes
from ssa_fusion.ros.topics import TOPIC_MEASUREMENT, TOPIC_MEASUREMENT_BATCH
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


def node_cpu_s(pid: int) -> float:
    """Return the CPU seconds (user + system) process `pid` has used (Linux ``/proc``)."""
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def feed(g: Graph, label: str, topic: str, total: int, window: int,
         publish_next: Callable[[], int], until: str = TAKEN,
         params: dict[str, object] | None = None) -> dict[str, float]:
    """Run one path: start a filter node, publish by `publish_next` (returns the rows it
    sent) keeping at most `window` rows in flight, until its progress counter `until`
    (`TAKEN`, or ``received``) reaches `total`."""
    node = g.start_node("catalog_filter", "-r", f"__node:={NODE}", name=f"{NODE}_{label}",
                        params={"use_sim_time": True, "station": "millstone,tira,altair",
                                **(params or {})})
    watch = ProgressWatch(g.probe)
    ready = ReadyNodes(g.probe)
    g.wait_for(lambda: ready.ready([f"{NODE}:{topic}"]), 60.0, f"{NODE} to match {topic}")

    def done(key: str = until) -> int:
        return int(watch.reports.get(NODE, {}).get(key, "0"))

    sent = 0
    cpu0 = node_cpu_s(node.popen.pid)
    t0 = time.perf_counter()
    while done() < total:
        while sent < total and sent - done() < window:
            sent += publish_next()
        g.spin_once(0.001)
    seconds = time.perf_counter() - t0
    cpu = node_cpu_s(node.popen.pid) - cpu0
    per_cpu = round(total / cpu) if cpu > 0.0 else None  # None: less than a clock tick
    received = done(Count.RECEIVED)
    g.stop(node)
    rate = total / seconds
    print(f"{label}: {total} measurements published, {done()} {until}, {received} received, "
          f"in {seconds:.2f} s = {rate:,.0f} measurements/s; the node's CPU {cpu:.2f} s = "
          f"{per_cpu} measurements per CPU s")
    assert sent == total == done() == received, (sent, total, done(), received)
    return {"measurements": total, "seconds": round(seconds, 3), "per_s": round(rate),
            "node_cpu_s": round(cpu, 3), "per_cpu_s": per_cpu}


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
                                             CATALOG_WRITER_QOS)
            pub_m = g.probe.create_publisher(MeasurementMsg, TOPIC_MEASUREMENT,
                                             CATALOG_WRITER_QOS)

            def batch_feeder() -> Callable[[], int]:
                it_b = iter(batches)

                def next_batch() -> int:
                    msg = next(it_b)
                    pub_b.publish(msg)
                    return len(msg.object_id)

                return next_batch

            def message_feeder() -> Callable[[], int]:
                it_m = iter(singles)

                def next_message() -> int:
                    pub_m.publish(next(it_m))
                    return 1

                return next_message

            b, m = TOPIC_MEASUREMENT_BATCH, TOPIC_MEASUREMENT
            result = {
                "batches": feed(g, "batches", b, n_rows, args.window, batch_feeder()),
                "per_message": feed(g, "per_message", m, n_msgs, min(args.window, 2000),
                                    message_feeder()),
                # the wire alone: DDS, deserialization and the vectorised admission, with
                # the fusion put off (batch_period an hour): rows received, all in flight
                "wire_batches": feed(g, "wire_batches", b, n_rows, n_rows, batch_feeder(),
                                     until=Count.RECEIVED, params={"batch_period": 3600.0}),
                "wire_per_message": feed(g, "wire_per_message", m, n_msgs, n_msgs,
                                         message_feeder(), until=Count.RECEIVED,
                                         params={"batch_period": 3600.0})}
        finally:
            problems = g.close()
    ratio = result["batches"]["per_s"] / result["per_message"]["per_s"]
    met = result["batches"]["per_s"] >= TARGET
    wire_met = result["wire_batches"]["per_s"] >= TARGET
    wire_ratio = result["wire_batches"]["per_s"] / result["wire_per_message"]["per_s"]
    print(f"batches / per message (taken, fused included): {ratio:.1f}x; over the wire alone: "
          f"{wire_ratio:.1f}x; target {TARGET:,} "
          f"measurements/s taken by one shard: {'met' if met else 'NOT met'}; received over "
          f"the wire (fusion put off): {'met' if wire_met else 'NOT met'}")
    if problems:
        print("graph: " + "; ".join(problems))
    print(json.dumps({"objects": args.objects, "hours": args.hours, "batch_rows": args.batch,
                      **result, "ratio": round(ratio, 1), "wire_ratio": round(wire_ratio, 1),
                      "target_per_s": TARGET,
                      "target_met": met, "wire_target_met": wire_met}))


if __name__ == "__main__":
    main()

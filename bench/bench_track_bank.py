"""Benchmark: measurements a catalog filter's bank fuses per CPU second, no DDS (not a test).

`TrackBank.process` (the catalog filter's settings: the J2 EKF, Herrick-Gibbs IOD) on the
rows `bench_wire` sends one shard: the radars of ``iss_network`` measuring ``--objects``
synthetic LEO objects for ``--hours`` (`sim.survey`), the first ``--rows`` of them in
batches of ``--batch`` rows, in epoch order, into a fresh bank, ``--repeat`` times. The
compiled kernels are loaded before the clock starts (a bank that is then dropped fuses the
first batch), as the node loads them before its first batch.
Prints each repeat's CPU seconds and measurements per CPU second, and their median; asserts
that the bank started tracks for most objects and fused most rows. The last line is JSON.

    nice -n 10 python bench/bench_track_bank.py [--objects 1000] [--hours 6] [--batch 4000]
"""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import argparse
import json
import statistics
import sys
import time
from dataclasses import asdict
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # run from a source checkout
sys.path.insert(0, str(Path(__file__).resolve().parent))

from bench_wire import measurements

from ssa_fusion.core.catalog.track_bank import TrackBank
from ssa_fusion.core.earth.stations import network_stations
from ssa_fusion.formats.sites import load_station_map
from ssa_fusion.params import settings
from ssa_fusion.params.defaults import CATALOG_FILTER

STATIONS = "millstone,tira,altair"
"""The radars of iss_network, as bench_wire's node has them."""


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--objects", type=int, default=1000)
    ap.add_argument("--hours", type=float, default=6.0)
    ap.add_argument("--rows", type=int, default=150_000)
    ap.add_argument("--batch", type=int, default=4000, help="rows per TrackBank.process call")
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args()
    rows = measurements(args.objects, args.hours)
    n = min(args.rows, len(rows))
    stations = network_stations(STATIONS, load_station_map(""))
    options = settings.filter_options({**asdict(CATALOG_FILTER), "station": STATIONS})
    t, oid, fid, z, R = rows.t[:n], rows.object_id[:n], rows.frame_id[:n], rows.z[:n], rows.R[:n]
    TrackBank(options, stations).process(t[:args.batch], oid[:args.batch], fid[:args.batch],
                                         z[:args.batch], R[:args.batch])
    results = []
    for k in range(args.repeat):
        bank = TrackBank(options, stations)
        fused = 0
        c0 = time.process_time()
        for a in range(0, n, args.batch):
            b = a + args.batch
            fused += bank.process(t[a:b], oid[a:b], fid[a:b], z[a:b], R[a:b]).fused.size
        cpu = time.process_time() - c0
        tracks = int(bank.tracking.sum())
        print(f"repeat {k}: {n} measurements of {len(bank)} objects, {fused} estimates, "
              f"{tracks} tracks, in {cpu:.2f} CPU s = {n / cpu:,.0f} measurements per CPU s")
        assert tracks >= 0.9 * len(bank) and fused >= 0.9 * n, (tracks, len(bank), fused, n)
        results.append({"cpu_s": round(cpu, 3), "per_cpu_s": round(n / cpu),
                        "estimates": fused, "tracks": tracks})
    median = statistics.median(r["per_cpu_s"] for r in results)
    print(f"median: {median:,.0f} measurements per CPU s")
    print(json.dumps({"objects": args.objects, "hours": args.hours, "rows": n,
                      "batch_rows": args.batch, "repeats": results,
                      "median_per_cpu_s": round(median)}))


if __name__ == "__main__":
    main()

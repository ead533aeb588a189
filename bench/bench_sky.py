"""Benchmark of the real-sky scenarios: `studies.sky_study` over the evaluation
seeds and start epochs (the same study as `ssa-fusion reproduce --scenario
iss_radar_columbus ...`), with the time it took.

Asserts what it claims: every scenario ran every seed and start epoch, every run scored
passes after initialisation, and at least half of them all six arms over their outage (a
station's outage can fall where it would have seen nothing; the table says how often).
Prints one markdown table per scenario and, last, one JSON line.

Usage: .venv/bin/python bench/bench_sky.py [--quick] [--workers N] [--scenario NAME ...]
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from ssa_fusion import limit_blas_threads

limit_blas_threads()

from ssa_fusion.sim import sky  # noqa: E402
from ssa_fusion.studies import sky_study  # noqa: E402
from ssa_fusion.studies.distributions import EVALUATION_SEEDS, START_OFFSETS_H  # noqa: E402


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--quick", action="store_true", help="3 seeds, one start epoch")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--scenario", nargs="*", default=list(sky.SKY_SCENARIOS))
    args = ap.parse_args()
    seeds = EVALUATION_SEEDS[:3] if args.quick else EVALUATION_SEEDS
    offsets = (0.0,) if args.quick else START_OFFSETS_H
    t0 = time.perf_counter()
    text, result = sky_study.run_sky_study(args.scenario, seeds, offsets, args.workers)
    wall = time.perf_counter() - t0
    for name in args.scenario:  # it did what it claims: every run, passes, outages scored
        r = result[name]
        assert r["runs"] == r["runs_with_passes"] == len(seeds) * len(offsets), (name, r)
        assert r["runs_with_outage"] >= 0.5 * r["runs"], (name, r)
    print(text + "\n")
    print(f"{len(args.scenario) * len(seeds) * len(offsets)} runs in {wall:.0f} s")
    print(json.dumps({"seeds": list(seeds), "start_offsets_h": list(offsets), "wall_s": wall,
                      **result}))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

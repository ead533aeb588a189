"""Benchmark of the screening (not a test): recall against brute force, and a catalog's cost.

The catalogs are those of ``bench/bench_catalog_scale.py``: every element set of
``config/catalogs/celestrak_active_2025-07.tle`` (306 real objects: 277 LEO, 8 MEO, 18 GEO,
3 HEO) spread into copies of the same orbit shape with the ascending node and mean anomaly
drawn uniformly (`sim.survey.synthetic_catalog`, the seeds of that benchmark); the window
starts at the newest element set's epoch. Crowded: each real LEO shell holds ~100 copies at
one altitude with random phases (real constellations phase theirs), so it has far more
close approaches than the real sky.

* **recall** (``--recall-objects`` 2,000, ``--recall-days`` 3, 10 km): `screening.screen`
  against `evaluation.screening_reference.brute_force_approaches` (every pair at every 1 s
  step with SGP4's own states, a k-d tree per step, local minima refined by Brent on SGP4):
  the fraction of the reference's approaches found (same pair, TCA within 1 s), the
  screening's approaches the reference lacks, the largest TCA and miss differences;
* **scale** (``--objects`` 30,000, ``--days`` 7, 10 km, ``--workers`` 2 threads): wall and
  CPU time, approaches found, and the peak resident memory of that run alone (a process of
  its own).

Each part runs in a child process (``--part``); the load of the machine (``uptime``) is
printed before and after. Asserts that each part screened what it claims (the catalog's
size and window, approaches found, a reference with approaches). Targets (not asserted):
recall 100 %, the scale run <= 10 min. Last line: JSON.

    nice -n 10 python bench/bench_screening.py [--objects 30000] [--days 7]
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

import bench_catalog_scale  # the catalog generator of the catalog benchmarks

from ssa_fusion.core.conjunction.ephemeris import ElementSetEphemeris
from ssa_fusion.core.conjunction.screening import ScreeningConfig, screen
from ssa_fusion.core.motion.element_sets import CatalogEntry
from ssa_fusion.evaluation.screening_reference import brute_force_approaches, match
from ssa_fusion.formats import element_sets as catalog_io
from ssa_fusion.sim import survey

REAL = bench_catalog_scale.REAL
TARGET_RECALL = 1.0
TARGET_WALL_S = 600.0


def catalog(objects: int, seed: int) -> tuple[list[CatalogEntry], dict[str, int]]:
    """Return the spread catalog of ``objects`` and its objects per regime.

    As `bench_catalog_scale.write_catalog` spreads it (the same seeds per real object),
    numbered from 1, in memory.
    """
    bases = catalog_io.read_catalog(REAL)
    per, extra = divmod(objects, len(bases))
    out: list[CatalogEntry] = []
    regimes: dict[str, int] = {}
    for i, base in enumerate(bases):
        n = per + (i < extra)
        if n:
            out += survey.synthetic_catalog(base, n, seed=seed + i, first_id=len(out) + 1)
            name = bench_catalog_scale.regime(base)
            regimes[name] = regimes.get(name, 0) + n
    return out, regimes


def _peak_rss_mib() -> float:
    """Peak resident memory of this process so far, MiB (Linux: ru_maxrss in KiB)."""
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def part_recall(args: argparse.Namespace) -> dict[str, Any]:
    """Screen the small catalog and the brute-force reference; compare."""
    entries, regimes = catalog(args.recall_objects, args.seed)
    eph = ElementSetEphemeris(entries)
    t0 = survey.catalog_start(entries)
    t1 = t0 + args.recall_days * 86400.0
    cfg = ScreeningConfig(distance_km=args.distance, workers=args.workers)
    w = time.perf_counter()
    found = screen(eph, t0, t1, cfg)
    screen_s = time.perf_counter() - w
    w = time.perf_counter()
    ref = brute_force_approaches(eph, t0, t1, args.distance, step_s=args.reference_step)
    ref_s = time.perf_counter() - w
    m = match(found, ref)
    assert len(ref) > 0, "the reference found no close approach: nothing was compared"
    return {"objects": len(entries), "regimes": regimes, "days": args.recall_days,
            "distance_km": args.distance, "reference_step_s": args.reference_step,
            "reference": len(ref), "screened": len(found), "found": int(m.found.sum()),
            "recall": m.recall, "extra": m.extra,
            "max_abs_dt_s": float(np.abs(m.dt_s).max()) if m.dt_s.size else 0.0,
            "max_abs_dmiss_m": 1e3 * float(np.abs(m.dmiss_km).max()) if m.dmiss_km.size
            else 0.0,
            "screen_wall_s": round(screen_s, 1), "reference_wall_s": round(ref_s, 1)}


def part_scale(args: argparse.Namespace) -> dict[str, Any]:
    """Screen the large catalog over the long window; time and memory."""
    w = time.perf_counter()
    entries, regimes = catalog(args.objects, args.seed)
    build_s = time.perf_counter() - w
    rss_catalog = _peak_rss_mib()
    eph = ElementSetEphemeris(entries)
    t0 = survey.catalog_start(entries)
    cfg = ScreeningConfig(distance_km=args.distance, workers=args.workers)
    w, c = time.perf_counter(), time.process_time()
    found = screen(eph, t0, t0 + args.days * 86400.0, cfg)
    wall, cpu = time.perf_counter() - w, time.process_time() - c
    assert len(entries) == args.objects and len(found) > 0, "nothing screened"
    assert found.tca.min() >= t0 and found.tca.max() <= t0 + args.days * 86400.0
    pairs = len({(int(a), int(b)) for a, b in zip(found.primary, found.secondary,
                                                     strict=True)})
    return {"objects": len(entries), "regimes": regimes, "days": args.days,
            "distance_km": args.distance, "workers": args.workers,
            "approaches": len(found), "pairs": pairs,
            "min_miss_m": round(1e3 * float(found.miss_km.min()), 1),
            "wall_s": round(wall, 1), "cpu_s": round(cpu, 1),
            "catalog_build_s": round(build_s, 1), "peak_rss_mib": round(_peak_rss_mib(), 1),
            "rss_after_catalog_mib": round(rss_catalog, 1),
            "config": {"node_step_s": cfg.node_step_s, "fine_step_s": cfg.fine_step_s,
                       "chunk_s": cfg.node_step_s * cfg.chunk_nodes}}


def _uptime() -> str:
    """Return ``uptime``'s line (the machine's load)."""
    return subprocess.run(["uptime"], capture_output=True, text=True, check=False).stdout.strip()


def _child(part: str, argv: list[str]) -> dict[str, Any]:
    """Run one part in a process of its own; return its JSON line."""
    cmd = [sys.executable, __file__, "--part", part, *argv]
    out = subprocess.run(cmd, capture_output=True, text=True, check=False,
                         env={**os.environ, "PYTHONUNBUFFERED": "1"})
    if out.returncode:
        raise SystemExit(f"part {part} failed:\n{out.stderr[-3000:]}")
    result: dict[str, Any] = json.loads(out.stdout.strip().splitlines()[-1])
    return result


def main() -> None:
    """Run the parts (each in a child process), print the summary and the JSON line."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--part", choices=("recall", "scale"), help=argparse.SUPPRESS)
    ap.add_argument("--objects", type=int, default=30_000)
    ap.add_argument("--days", type=float, default=7.0)
    ap.add_argument("--recall-objects", type=int, default=2_000)
    ap.add_argument("--recall-days", type=float, default=3.0)
    ap.add_argument("--reference-step", type=float, default=1.0, help="s")
    ap.add_argument("--distance", type=float, default=10.0, help="screening distance, km")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--skip-recall", action="store_true")
    args = ap.parse_args()
    if args.part:
        run = part_recall if args.part == "recall" else part_scale
        print(json.dumps(run(args)))
        return
    argv = [a for a in sys.argv[1:] if a != "--skip-recall"]
    print(f"load before: {_uptime()}", flush=True)
    scale = _child("scale", argv)
    print(f"scale: {scale['objects']} objects {scale['regimes']}, {scale['days']:g} days at "
          f"{scale['distance_km']:g} km, {scale['workers']} threads: {scale['approaches']} "
          f"approaches ({scale['pairs']} pairs) in {scale['wall_s']:.0f} s wall "
          f"({scale['cpu_s']:.0f} s CPU; target <= {TARGET_WALL_S:.0f} s), peak RSS "
          f"{scale['peak_rss_mib']:.0f} MiB ({scale['rss_after_catalog_mib']:.0f} MiB with "
          f"the catalog read)", flush=True)
    print(f"load after the scale run: {_uptime()}", flush=True)
    recall: dict[str, Any] = {}
    if not args.skip_recall:
        recall = _child("recall", argv)
        print(f"recall: {recall['objects']} objects, {recall['days']:g} days at "
              f"{recall['distance_km']:g} km: reference {recall['reference']} approaches "
              f"({recall['reference_step_s']:g} s grid, {recall['reference_wall_s']:.0f} s), "
              f"screening {recall['screened']} ({recall['screen_wall_s']:.0f} s): found "
              f"{recall['found']}, recall {100 * recall['recall']:.2f} % (target "
              f"{100 * TARGET_RECALL:.0f} %), {recall['extra']} not in the reference; "
              f"largest |dTCA| {recall['max_abs_dt_s']:.2e} s, |dmiss| "
              f"{recall['max_abs_dmiss_m']:.2e} m", flush=True)
        print(f"load after the recall run: {_uptime()}", flush=True)
    print(json.dumps({"scale": scale, "recall": recall, "load": _uptime()}))


if __name__ == "__main__":
    main()

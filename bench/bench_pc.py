"""Benchmark of the collision probability (not a test): ours against NASA CARA's, and its cost.

* CARA's real CDMs (the shared data, `cara_cases.cara_cdm_dir`; skipped when absent): each
  read by `formats.ccsds.cdm`, its Pc computed by `core.conjunction.collision_probability`
  (Foster's 2D Pc) beside CARA's own ``COLLISION_PROBABILITY`` (FOSTER-1992), the relative
  difference from the logs (so the 1e-168 one compares too);
* the Alfano (2009) test cases against the 2D Pc CARA's unit test expects (0.1 %);
* microseconds per Pc: one conjunction with every check (`collision_probability`: encounter
  plane, integral, usage bounds, NPD checks), the vectorised 2D Pc of many conjunctions at
  once (`pc2d_batch`, the 27 CDMs tiled to ``--batch``), and reading a CDM.

It asserts what it claims: every CARA Pc >= 1e-10 within 1 %, the tiny ones within 0.01 in
log10, every Alfano case within 0.1 %. Last line: JSON.
"""

from __future__ import annotations

import argparse
import json
import math
import statistics
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "test"))

import cara_cases

from ssa_fusion.core.conjunction.encounter import rtn_to_inertial
from ssa_fusion.core.conjunction.probability import (
    collision_probability,
    pc2d_batch,
)
from ssa_fusion.formats.ccsds.cdm import read_cdm


def _rel(log10_ours: float, theirs: float) -> float:
    """(ours - theirs) / theirs from ours' log10."""
    return math.expm1((log10_ours - math.log10(theirs)) * math.log(10))


def _cara(files: list[Path]) -> tuple[list[tuple[str, float, float, float, float]], list]:
    """Rows (name, miss m, ours, CARA's, rel) and the inputs of every CARA CDM."""
    rows, inputs = [], []
    for f in files:
        cdm = read_cdm(f)
        assert cdm.pc is not None and cdm.hbr_km is not None
        res = collision_probability(*cdm.inputs(), cdm.hbr_km)
        rel = _rel(res.log10_pc, cdm.pc)
        rows.append((f.stem[:40], res.miss_km * 1e3, res.log10_pc, cdm.pc, rel))
        inputs.append((*cdm.inputs(), cdm.hbr_km))
    return rows, inputs


def _alfano() -> list[tuple[int, float, float, float]]:
    """Rows (case, ours, expected, rel) of the Alfano (2009) cases."""
    rows = []
    for case, expected in sorted(cara_cases.ALFANO_2009_PC2D.items()):
        hbr, x1, c1, x2, c2 = cara_cases.alfano_case(case)
        res = collision_probability(x1, rtn_to_inertial(x1, c1)[0], x2,
                                    rtn_to_inertial(x2, c2)[0], hbr)
        rows.append((case, res.pc, expected, res.pc / expected - 1))
    return rows


def _median_us(fn, repeats: int, per: int) -> float:
    """Median over `repeats` runs of fn(), microseconds per item (per items a run)."""
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return statistics.median(times) / per * 1e6


def _timings(files: list[Path], inputs: list, batch: int, repeats: int) -> dict[str, float]:
    """Microseconds per Pc (scalar, batched) and per CDM read."""
    x1, p1, x2, p2, hbr = (np.stack([np.asarray(v[k]) for v in inputs]) for k in range(5))
    reps = -(-batch // len(inputs))
    big = [np.concatenate([a] * reps)[:batch] for a in (x1, p1, x2, p2, hbr)]
    pc2d_batch(*big)  # warm (caches of the quadrature rule)

    def one_by_one() -> None:
        for v in inputs:
            collision_probability(*v)

    return {"us_per_pc_scalar": _median_us(one_by_one, repeats, len(inputs)),
            "us_per_pc_batch": _median_us(lambda: pc2d_batch(*big), repeats, batch),
            "us_per_cdm_read": _median_us(lambda: [read_cdm(f) for f in files], repeats,
                                          len(files))}


def main(argv: list[str] | None = None) -> int:
    """Run the benchmark; print the tables and the JSON line."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--batch", type=int, default=10_000, help="conjunctions of the batch run")
    ap.add_argument("--repeats", type=int, default=5, help="timed runs (median)")
    args = ap.parse_args(argv)
    out: dict[str, object] = {}
    d = cara_cases.cara_cdm_dir()
    files = sorted(d.glob("*.cdm")) if d is not None else []
    if files:
        rows, inputs = _cara(files)
        print(f"CARA's CDMs ({len(rows)}): ours vs CARA's COLLISION_PROBABILITY (FOSTER-1992)")
        print("| message | miss [m] | ours | CARA | rel diff |\n|---|---:|---:|---:|---:|")
        for name, miss, lp, theirs, rel in rows:
            ours = f"{10 ** lp:.4e}" if lp > -300 else f"1e{lp:.2f}"
            print(f"| {name} | {miss:.1f} | {ours} | {theirs:.4g} | {rel:+.3%} |")
        big = [r for r in rows if r[3] >= 1e-10]
        worst = max(big, key=lambda r: abs(r[4]))
        tiny = max((abs(r[2] - math.log10(r[3])) for r in rows if r[3] < 1e-10), default=0.0)
        assert abs(worst[4]) <= 0.01 and tiny <= 0.01, (worst, tiny)
        print(f"worst (Pc >= 1e-10, {len(big)} messages): {worst[4]:+.3%} ({worst[0]}); "
              f"tiny ones ({len(rows) - len(big)}): |log10 diff| <= {tiny:.2e}\n")
        out |= {"cara_messages": len(rows), "cara_compared": len(big),
                "cara_worst_rel": abs(worst[4]), "cara_tiny_worst_log10": tiny,
                **_timings(files, inputs, args.batch, args.repeats)}
    else:
        print("CARA's CDMs: not present (../shared/conjunction/cara-cdms); skipped\n")
    alf = _alfano()
    print("Alfano (2009) cases: ours vs CARA's unit test (Pc2D_Foster_UnitTest.m)")
    print("| case | ours | expected | rel diff |\n|---:|---:|---:|---:|")
    for case, ours, exp, rel in alf:
        print(f"| {case} | {ours:.9e} | {exp:.9e} | {rel:+.4%} |")
    worst_a = max(abs(r[3]) for r in alf)
    assert worst_a <= 1e-3, worst_a
    print(f"worst: {worst_a:.4%}\n")
    out |= {"alfano_cases": len(alf), "alfano_worst_rel": worst_a}
    if files:
        print(f"cost: {out['us_per_pc_scalar']:.0f} us per Pc with every check (one at a time), "
              f"{out['us_per_pc_batch']:.1f} us per Pc batched ({args.batch:,} at once), "
              f"{out['us_per_cdm_read']:.0f} us per CDM read (median of {args.repeats})")
    print(json.dumps(out))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

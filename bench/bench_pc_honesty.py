"""Benchmark (not a test): is the collision probability of screened approaches honest?

Runs `studies.conjunction_honesty.run_honesty`: ``--pairs`` simulated close approaches of
LEO objects whose truth is a draw from the covariance each estimate reports, screened from
the estimates (`core.conjunction.screening`, covariances carried to TCA by the state
transition matrix); prints the chi-square(2) coverage of the miss error in the encounter
plane at 95 % (target 93-97 %), the reliability table of the 2D Pc (per Pc bin: approaches,
mean Pc, collisions of the truth, their rate's Wilson 95 % interval), the Pc's sum against
the collisions, and the same for a covariance reported four times too small (what a
dishonest one looks like). Asserts that every planted approach was found and scored. Last
line: JSON.

    nice -n 10 python bench/bench_pc_honesty.py [--pairs 4000]
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
import time
from typing import Any

from ssa_fusion.studies.conjunction_honesty import (
    HonestyConfig,
    HonestyResult,
    reliability,
    run_honesty,
)

TARGET = (0.93, 0.97)


def report(name: str, r: HonestyResult, wall_s: float) -> dict[str, Any]:
    """Print one run's coverage and reliability table; return its numbers."""
    assert r.epsilon.size == r.planted, f"{r.planted - r.epsilon.size} approaches not found"
    expected, observed = float(r.pc.sum()), int(r.collided.sum())
    print(f"{name}: {r.planted} approaches ({wall_s:.0f} s): chi2(2) coverage at 95 % "
          f"{100 * r.coverage95:.1f} % (target {100 * TARGET[0]:.0f}-{100 * TARGET[1]:.0f} "
          f"%), mean normalised miss error {r.epsilon.mean():.3f} (chi2(2): 2); collisions "
          f"{observed}, sum of Pc {expected:.1f} (Poisson sd {math.sqrt(expected):.1f})")
    rows = reliability(r.pc, r.collided)
    print("| Pc bin | approaches | mean Pc | collisions | rate | 95 % interval | mean Pc in it |")
    print("|---|---:|---:|---:|---:|---|---|")
    for row in rows:
        if not row.n:
            continue
        print(f"| [{row.lo:g}, {row.hi:g}) | {row.n} | {row.mean_pc:.4f} | {row.collisions} | "
              f"{row.collisions / row.n:.4f} | [{row.rate_lo:.4f}, {row.rate_hi:.4f}] | "
              f"{'yes' if row.consistent else 'no'} |")
    return {"approaches": r.planted, "coverage95": round(r.coverage95, 4),
            "mean_epsilon": round(float(r.epsilon.mean()), 4), "collisions": observed,
            "sum_pc": round(expected, 2), "wall_s": round(wall_s, 1),
            "reliability": [dataclasses.asdict(row) | {"consistent": row.consistent}
                            for row in rows if row.n]}


def main() -> None:
    """Run the honest and the overconfident study; print them and the JSON line."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--pairs", type=int, default=4000)
    ap.add_argument("--seed", type=int, default=1)
    args = ap.parse_args()
    out: dict[str, Any] = {}
    for name, scale in (("honest", 1.0), ("overconfident (covariance / 4)", 0.25)):
        cfg = HonestyConfig(pairs=args.pairs, seed=args.seed, cov_scale=scale)
        t = time.perf_counter()
        r = run_honesty(cfg)
        out[name.split()[0]] = report(name, r, time.perf_counter() - t)
    c = HonestyConfig()
    out["config"] = {"lead_s": c.lead_s, "miss_disk_km": c.miss_disk_km, "hbr_km": c.hbr_km,
                     "sigma_pos_km": c.sigma_pos_km, "sigma_vel_km_s": c.sigma_vel_km_s,
                     "truth_model": str(c.truth_model), "filter_model": str(c.filter_model)}
    print(json.dumps(out))


if __name__ == "__main__":
    main()

"""Benchmark: the catalog surrogate's physics-only gap fit, its covariance against the truth.

Per seed (``--tuning``: the tuning seeds `studies.distributions.TUNING_SEEDS`, the first
``--seeds``; else the catalog's evaluation seeds `studies.catalog_gaps.EVALUATION_SEEDS`), a
synthetic LEO catalog through survey, batched filter and `core.catalog.gap_bank.GapBank`
(`studies.catalog_gaps.offline_run`, every gap fitted), once per ``--accel-sigma`` of the
physics-only fit (`core.gaps.residual.PHYSICS_RESIDUAL`). Prints, for the forecasts of the
physics-only fit and of the learned residual apart, the share whose position NEES lies
within chi2(3)'s 95 % bound (target >= 90 %), the median NEES and position error against
the SGP4 truth, the fits of each, and the gaps after the first day with a forecast.
Asserts that physics-only forecasts were made and scored. Last line: JSON.

    nice -n 5 python bench/bench_physics_fit.py --tuning --accel-sigma 1e-8 3e-8 1e-7
"""

from __future__ import annotations

import argparse
import json
import sys
from dataclasses import replace
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from ssa_fusion import limit_blas_threads

limit_blas_threads()

from ssa_fusion.core.base.types import MotionModel  # noqa: E402
from ssa_fusion.core.catalog.gap_bank import GapBankConfig  # noqa: E402
from ssa_fusion.core.gaps.residual import PHYSICS_ACCEL_SIGMA, PHYSICS_RESIDUAL  # noqa: E402
from ssa_fusion.studies.catalog_gaps import EVALUATION_SEEDS, offline_run  # noqa: E402
from ssa_fusion.studies.distributions import TUNING_SEEDS  # noqa: E402


def main() -> None:
    """Run the seeds and settings, print each, end with the JSON line."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--tuning", action="store_true", help="the tuning seeds")
    ap.add_argument("--seeds", type=int, default=3, help="how many seeds")
    ap.add_argument("--objects", type=int, default=20)
    ap.add_argument("--hours", type=float, default=30.0)
    ap.add_argument("--accel-sigma", type=float, nargs="+", default=[PHYSICS_ACCEL_SIGMA],
                    help="km/s^2, the physics-only fit's acceleration prior")
    ap.add_argument("--window-h", type=float, default=PHYSICS_RESIDUAL.window_s / 3600.0,
                    help="h of pass ends before the gap the physics-only fit spans")
    args = ap.parse_args()
    seeds = (TUNING_SEEDS if args.tuning else EVALUATION_SEEDS)[:args.seeds]
    out = []
    for sigma in args.accel_sigma:
        cfg = GapBankConfig(motion_model=MotionModel.J2,
                            physics=replace(PHYSICS_RESIDUAL, accel_sigma=sigma,
                                            window_s=3600.0 * args.window_h))
        for seed in seeds:
            r = offline_run(seed, args.objects, args.hours, gap_config=cfg)
            n, cov = r["nees"], r["coverage"]
            assert n is not None and n["physics"]["forecasts"] > 0, "no physics forecasts"
            line = {"accel_sigma": sigma, "window_h": args.window_h, "seed": seed,
                    "fits_made": r["fits_made"],
                    "fits_physics": r["fits_physics"], "gaps": cov["gaps"],
                    "gaps_with_forecast": cov["with_forecast"],
                    **{f"{k}_{m}": n[k].get(m) for k in ("physics", "learned")
                       for m in ("forecasts", "in_bound", "nees_median", "error_km_median")}}
            out.append(line)
            print(f"sigma {sigma:g} km/s^2, seed {seed}: fits {r['fits_made']} "
                  f"({r['fits_physics']} physics-only); gaps after the first day "
                  f"{cov['gaps']}, {cov['with_forecast']} with a forecast")
            for k in ("physics", "learned"):
                g = n[k]
                if g["forecasts"]:
                    print(f"  {k}: {g['forecasts']} forecasts, position NEES within the "
                          f"95 % bound {100 * g['in_bound']:.1f} % (target >= 90), median "
                          f"NEES {g['nees_median']:.2f}, median error "
                          f"{1e3 * g['error_km_median']:.0f} m")
    print(json.dumps({"tuning": args.tuning, "objects": args.objects, "hours": args.hours,
                      "runs": out}))


if __name__ == "__main__":
    main()

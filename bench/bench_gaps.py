"""Benchmark of the gap study: forecasting through the gaps between passes.

Runs `studies.gap_study` over the evaluation seeds (101-120) x start epochs (0, 8, 16 h) of
the real-sky scenarios with the residual surrogate setting chosen on the tuning seeds 1-3
(`gap_study.CHOSEN`), and prints per scenario the distributions over runs (medians
[quartiles]) of every arm, then the targets against the measured values:

- the surrogate forecasts in >= 95 % of the inter-pass gaps after its training span;
- kepler placeholder: mean gap position error >= 5x smaller than coast (kepler);
- j2 placeholder: >= 1.5x smaller than j2_coast, gaps of 1.5-16 h (SGP4 truth, real B*);
- mean NEES of every EKF arm inside its 95 % chi-square band (6 dof, per epoch);
- against the physics-only fit an engineer would run (``batch_fit``, a J2 batch fit of the
  last three passes): the surrogate's error smaller (ratio > 1).

Asserts what it claims: every run scored gaps after the training span with both
placeholders, and the surrogate forecast in some of them. `--tune` instead compares the
candidate settings on the tuning seeds (what chose `CHOSEN`). Last line: one JSON object.

The truth (``--truth``): ``sgp4`` (default: the study's published table) or
``high_fidelity`` (`sim.world`), printed with the tables and in the JSON.

Usage: .venv/bin/python bench/bench_gaps.py [--quick] [--tune] [--bopdmd] [--workers N]
       [--scenario NAME ...] [--truth sgp4|high_fidelity]
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

from ssa_fusion.core.base.metrics import chi2_bounds  # noqa: E402
from ssa_fusion.sim import sky  # noqa: E402
from ssa_fusion.sim.world import TruthModel  # noqa: E402
from ssa_fusion.studies import gap_study  # noqa: E402
from ssa_fusion.studies.distributions import EVALUATION_SEEDS, START_OFFSETS_H  # noqa: E402


def targets(name: str, r: dict, arm: str) -> list[str]:
    """The targets against the measured medians, for scenario `name`."""
    lo, hi = chi2_bounds(6)
    rows = []
    rng = r.get("range", {})
    k, j = rng.get("kepler", {}), rng.get("j2", {})
    fc = [p[arm]["forecast_median"] for p in (k, j) if arm in p]
    fc_mean = [p[arm]["forecast_mean"] for p in r.get("all", {}).values() if arm in p]
    rows.append(f"| {name} | forecasts in gaps after training (median; mean over runs) | "
                f">= 95 % | {', '.join(f'{v:.1f}' for v in fc)} %; "
                f"{', '.join(f'{v:.1f}' for v in fc_mean)} % |")
    ratios = r.get("ratios", {}).get(arm, {})
    rows.append(f"| {name} | coast(kepler) / {arm}(kepler), 1.5-16 h | >= 5 | "
                f"{ratios.get('coast_kepler_over_kepler', float('nan')):.3g} |")
    rows.append(f"| {name} | j2_coast / {arm}(j2), 1.5-16 h | >= 1.5 | "
                f"{ratios.get('j2_coast_over_j2', float('nan')):.3g} |")
    rows.append(f"| {name} | batch_fit / {arm}(j2), 1.5-16 h | > 1 | "
                f"{ratios.get('batch_fit_over_j2', float('nan')):.3g} |")
    for p in ("kepler", "j2"):
        for a in ("coast", "dmd_ekf", "batch_fit", arm):
            if a in rng.get(p, {}):
                n = rng[p][a]["nees_median"]
                rows.append(f"| {name} | mean NEES {a} ({p}), median over runs | "
                            f"[{lo:.2f}, {hi:.2f}] | {n:.3g} "
                            f"({'in' if lo <= n <= hi else 'out'}; "
                            f"{100 * rng[p][a]['nees_in_band']:.0f} % of runs in band) |")
    return rows


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--quick", action="store_true",
                    help="iss_radar_columbus, 2 evaluation seeds, start epoch 0 h")
    ap.add_argument("--tune", action="store_true",
                    help="compare the candidate settings on the tuning seeds 1-3")
    ap.add_argument("--bopdmd", action="store_true", help="also the BOP-DMD variant")
    ap.add_argument("--variant", nargs="*", default=None,
                    help="with --tune: only these candidates (no BOP-DMD)")
    ap.add_argument("--fit-anchors", action="store_true",
                    help="each variant also anchored on the batch fit of the last passes "
                         "instead of the filter's pass-end estimate (<variant>_fit)")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--truth", choices=[str(t) for t in TruthModel], default=str(TruthModel.SGP4),
                    help="the object's truth (default sgp4)")
    ap.add_argument("--scenario", nargs="*", default=None)
    args = ap.parse_args()
    names = args.scenario or (["iss_radar_columbus"] if args.quick else list(sky.SKY_SCENARIOS))
    t0 = time.perf_counter()
    if args.tune:
        text, result = gap_study.tune(names, args.workers, args.variant, args.fit_anchors)
        print(text)
        print(json.dumps({"tuning_seeds": list(gap_study.TUNING_SEEDS), **result}))
        return 0
    seeds = EVALUATION_SEEDS[:2] if args.quick else EVALUATION_SEEDS
    offsets = (0.0,) if args.quick else START_OFFSETS_H
    arm = gap_study.CHOSEN
    variants = {arm: gap_study.tuning_candidates()[arm]}
    done = [0]

    def progress(name: str) -> None:
        done[0] += 1
        print(f"[{time.perf_counter() - t0:.0f} s] run {done[0]} done ({name})", file=sys.stderr,
              flush=True)

    text, result, runs = gap_study.run_gap_study(names, seeds, offsets, variants,
                                                 bopdmd=args.bopdmd,
                                                 fit_anchors=args.fit_anchors,
                                                 workers=args.workers,
                                                 progress=progress,
                                                 truth=TruthModel(args.truth))
    wall = time.perf_counter() - t0
    for name in names:  # it did what it claims: gaps scored, forecasts made
        r = result[name]
        assert r["runs"] == len(seeds) * len(offsets), (name, r["runs"])
        for p in ("kepler", "j2"):
            assert r["all"][p]["gaps"] > 0, (name, p, "no gap scored after the training span")
            assert r["all"][p][arm]["forecast_mean"] > 0, (name, p, "the surrogate never forecast")
            assert r["all"][p]["batch_fit"]["forecast_mean"] > 0, (name, p, "no batch fit")
    print(text + "\n")
    print("Targets (medians over runs):\n")
    print("| scenario | target | wanted | measured |\n|---|---|---|---|")
    for name in names:
        print("\n".join(targets(name, result[name], arm)))
    print(f"\n{len(runs)} runs in {wall:.0f} s, {args.truth} truth")
    print(json.dumps({"truth": args.truth, "seeds": list(seeds),
                      "start_offsets_h": list(offsets), "variant": arm, "wall_s": wall,
                      **result}))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

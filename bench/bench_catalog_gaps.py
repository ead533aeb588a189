"""Benchmark of gap forecasts over a catalog (the catalog_surrogate's method).

1. Offline (`studies.catalog_gaps.offline_run`), the methods' accuracy: per evaluation seed
   (101-105, never used for tuning), a synthetic LEO catalog (the sample's CBERS 2 element
   set spread around the Earth) measured for two days by the radar network, fused by the
   batched J2 filter, every gap forecast by each arm: ``residual``, the residual surrogate
   after a day of pass ends (the live setting chosen on the ISS gap study's tuning seeds),
   and ``batch_fit``, the batch fit of the last three passes at every pass end (the
   single-object filter's `core.gaps.batch_gap`, tuned on the real-sky tuning runs). Scored
   against the SGP4 truth beside the filter coasting on its J2 model from the same pass end
   (the physics-only baseline), at the same epochs: each arm on all its gaps, and both on
   the gaps both forecast (paired). Cost per object: the filter's and each arm's wall time
   over the run, divided by the objects, and the pipeline's (filter + arm) ratio.
2. Live (`ssa-fusion live --catalog ... --synthetic N`), what the node keeps up with: the
   whole graph over DDS, the catalog_surrogate fitting under its wall-time budget (half a
   core), once per arm (``--surrogate-param gap_forecast=...``); fits made against gaps
   skipped for want of time, real-time factor, nothing lost, wall time per object.

Asserts what it claims: forecasts were made and scored by every arm in every offline seed
and in the live runs. Last line: one JSON object.

Usage: nice -n 10 .venv/bin/python bench/bench_catalog_gaps.py [--quick] [--workers N]
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from ssa_fusion import limit_blas_threads

limit_blas_threads()

import numpy as np  # noqa: E402

from ssa_fusion.core.gaps.publisher import GapFill  # noqa: E402
from ssa_fusion.studies.catalog_gaps import EVALUATION_SEEDS, SAMPLE, offline_run  # noqa: E402

ARMS = (GapFill.RESIDUAL, GapFill.BATCH_FIT)
"""The gap forecasts compared (`core.catalog.gap_bank.GAP_FORECASTS`)."""


def _offline(job: tuple[int, int, float]) -> dict:
    return offline_run(*job, gap_forecasts=ARMS)

TRUTH = "sgp4"
"""The catalogs' truth: SGP4/SDP4 of their element sets (`sim.survey`; a high-fidelity
world per object is the real-sky scenarios', `bench/bench_sky.py`)."""


def _q(values: list[float]) -> str:
    a = np.asarray(values, float)
    return (f"{np.median(a):.3g} [{np.percentile(a, 25):.3g}, {np.percentile(a, 75):.3g}] "
            f"min {a.min():.3g}")


def offline_part(seeds: tuple[int, ...], objects: int, hours: float, workers: int) -> dict:
    print(f"offline: {len(seeds)} seeds x {objects} objects x {hours:g} h, arms "
          f"{', '.join(ARMS)} (truth: {TRUTH}, the catalog's element sets)")
    with ProcessPoolExecutor(max_workers=workers) as pool:
        runs = list(pool.map(_offline, [(s, objects, hours) for s in seeds]))
    out: dict = {"offline_seeds": list(seeds), "offline_objects": objects,
                 "offline_hours": hours}
    for r in runs:
        print(f"  seed {r['seed']}: filter {r['filter_wall_s_per_object']:.3f} s per object")
        for arm in ARMS:
            a, c = r["arms"][arm], r["common"][arm]
            assert a["fits_made"] > 0 and a.get("forecasts_scored", 0) > 0, (arm, a)
            assert c.get("forecasts_scored", 0) > 0, (arm, c)
            print(f"    {arm}: {a['fits_made']} fits ({a['fits_refused']} refused), "
                  f"{a['forecasts_scored']} forecasts in {a['gaps_scored']} gaps: median "
                  f"{1e3 * a['forecast_error_km']['median']:.0f} m (p95 "
                  f"{1e3 * a['forecast_error_km']['p95']:.0f}), coast "
                  f"{1e3 * a['coast_error_km']['median']:.0f} m, coast/arm "
                  f"{a['coast_over_forecast']:.2f}; on the {c['gaps_scored']} gaps both "
                  f"forecast: {1e3 * c['forecast_error_km']['median']:.0f} m; "
                  f"{a['wall_s_per_fit']:.3f} s per fit, "
                  f"{a['surrogate_wall_s_per_object']:.3f} s per object, window "
                  f"{a['window_bytes_per_object']:.0f} B per object")
    for arm in ARMS:
        a = [r["arms"][arm] for r in runs]
        ratio = [x["coast_over_forecast"] for x in a]
        common = [1e3 * r["common"][arm]["forecast_error_km"]["median"] for r in runs]
        per_obj = [x["surrogate_wall_s_per_object"] for x in a]
        pipeline = [r["filter_wall_s_per_object"] + x["surrogate_wall_s_per_object"]
                    for r, x in zip(runs, a, strict=True)]
        print(f"  {arm} over seeds: coast/arm {_q(ratio)}; median m on the common gaps "
              f"{_q(common)}; s per fit {_q([x['wall_s_per_fit'] for x in a])}; "
              f"s per object {_q(per_obj)}; filter + arm s per object {_q(pipeline)}")
        out.update({f"offline_{arm}_coast_over": ratio,
                    f"offline_{arm}_gaps_better": [x["gaps_forecast_better"] for x in a],
                    f"offline_{arm}_median_m": [1e3 * x["forecast_error_km"]["median"]
                                                for x in a],
                    f"offline_{arm}_p95_m": [1e3 * x["forecast_error_km"]["p95"] for x in a],
                    f"offline_{arm}_common_median_m": common,
                    f"offline_{arm}_fits": [x["fits_made"] for x in a],
                    f"offline_{arm}_s_per_fit": [x["wall_s_per_fit"] for x in a],
                    f"offline_{arm}_s_per_object": per_obj,
                    f"offline_{arm}_pipeline_s_per_object": pipeline,
                    f"offline_{arm}_window_bytes_per_object": [x["window_bytes_per_object"]
                                                               for x in a]})
    out["offline_coast_median_m"] = [1e3 * r["coast_error_km"]["median"] for r in runs]
    out["offline_filter_s_per_object"] = [r["filter_wall_s_per_object"] for r in runs]
    base, fit = (out[f"offline_{a}_pipeline_s_per_object"] for a in ARMS)
    cost = [f / b for b, f in zip(base, fit, strict=True)]
    paired = [f / b for b, f in zip(out["offline_residual_common_median_m"],
                                    out["offline_batch_fit_common_median_m"], strict=True)]
    print(f"  batch_fit / residual over seeds: pipeline cost per object {_q(cost)} "
          f"(target <= 2); median error on the common gaps {_q(paired)}")
    out.update({"offline_cost_batch_fit_over_residual": cost,
                "offline_common_error_batch_fit_over_residual": paired})
    return out


def live_part(objects: int, hours: float, time_scale: float, extra: list[str],
              arm: GapFill) -> dict:
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "run"
        cmd = [str(Path(sys.executable).parent / "ssa-fusion"), "live", "--catalog",
               str(SAMPLE), "--synthetic", str(objects), "--duration", str(hours),
               "--time-scale", str(time_scale), "--seed", "101", "--out", str(out), *extra,
               "--surrogate-param", f"gap_forecast={arm}"]
        env = {**os.environ, "ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST"}
        print("live: $ " + " ".join(["ssa-fusion", *cmd[1:]]), flush=True)
        start = time.perf_counter()
        done = subprocess.run(cmd, env=env, capture_output=True, text=True, check=False)
        wall = time.perf_counter() - start
        print("\n".join("  " + line for line in done.stdout.strip().splitlines()[-9:]))
        assert done.returncode == 0, done.stderr[-3000:]
        s = json.loads((out / "catalog.json").read_text())
    g = next(iter(s["surrogates"].values()))
    ge = s["gap_errors"]
    assert g["fits_made"] > 0 and ge.get("forecasts_scored", 0) > 0, (g, ge)
    print(f"  {arm}: {wall:.1f} wall s in all, {wall / objects:.3f} s per object; "
          f"fits {g['fits_made']}, fit s {g['fit_seconds']}")
    return {f"live_{arm}_{k}": v for k, v in {
        "objects": objects, "hours": hours, "time_scale": time_scale,
        "real_time_factor": s["live_real_time_factor"],
        "wall_s": wall, "wall_s_per_object": wall / objects,
        "lost_measurements": s["lost_measurements"],
        "fits_made": g["fits_made"], "fits_refused": g["fits_refused"],
        "fits_skipped": g["fits_skipped"], "fit_seconds": g["fit_seconds"],
        "forecasts": s["forecasts_recorded"],
        "forecasts_overtaken": g["forecasts_overtaken"],
        "surrogate_rss_mib": g["rss_mib"],
        "coast_over_surrogate": ge["coast_over_forecast"],
        "gaps_better": ge["gaps_forecast_better"],
        "surrogate_median_m": 1e3 * ge["forecast_error_km"]["median"],
        "coast_median_m": 1e3 * ge["coast_error_km"]["median"]}.items()}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true",
                    help="one seed, fewer objects, shorter spans (a few minutes)")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--no-live", action="store_true")
    ap.add_argument("--no-offline", action="store_true")
    args = ap.parse_args()
    result: dict = {}
    if args.quick:
        if not args.no_offline:
            result = offline_part(EVALUATION_SEEDS[:1], 6, 30.0, 1)
        live = (20, 14.0, 2000.0, ["--surrogate-param", "min_span=21600"])
    else:
        if not args.no_offline:
            result = offline_part(EVALUATION_SEEDS, 20, 48.0, args.workers)
        live = (200, 48.0, 600.0, [])
    if not args.no_live:
        for arm in ARMS:
            result.update(live_part(*live, arm=arm))
    result["mode"] = "quick" if args.quick else "full"
    result["truth"] = TRUTH
    print(json.dumps(result))


if __name__ == "__main__":
    main()

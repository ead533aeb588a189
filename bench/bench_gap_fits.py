"""Benchmark: a catalog's residual gap fits, this tree against a git revision, on the same
estimates: wall time per fit and how far the forecasts moved.

The catalog is `bench_catalog_scale`'s (``--objects`` spread over the 306 real objects of
LEO, MEO, GEO and HEO), measured by iss_network's radars for ``--hours`` and fused by the
batched filter every 60 s (`studies.catalog_gaps.estimate_batches`). The estimates are
kept, then replayed into a `core.catalog.gap_bank.GapBank` with the catalog_surrogate's defaults
(no budget: every pass end fitted, as in lockstep) by this tree's code and by the code of
``--before`` (``git archive`` of that revision, each replay a process of its own with
OPENBLAS_NUM_THREADS=1, as the nodes run), alternately ``--repeats`` times each, so that
both see the same load. Prints, per tree, the fits made and refused, the forecasts, the
wall s in the bank's fits (`GapBank.fit_seconds`, the fastest repeat) and per fit made;
before / after as a ratio; and the largest difference of the two trees' forecasts
(position km, velocity km/s, position over its standard deviation, covariance relative to
its largest entry). The last line is JSON.

    nice -n 5 python bench/bench_gap_fits.py --objects 300 --hours 30 --before main

Asserts that both made the same fits and forecasts (the same objects and epochs), that
fits were made, and that the forecasts agree to 1e-5 km in position and 1e-4 of the
covariance's largest entry (the tolerance of `test_residual`'s forecast test).
"""

from __future__ import annotations

import argparse
import json
import os
import pickle
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
POSITION_TOL_KM = 1e-5
COVARIANCE_TOL = 1e-4


def record(objects: int, hours: float, seed: int, out: Path) -> int:
    """Simulate and fuse the catalog; pickle its estimate batches to `out`; return estimates."""
    sys.path.insert(0, str(ROOT / "bench"))
    from bench_catalog_scale import write_catalog

    from ssa_fusion.formats import element_sets as catalog_io
    from ssa_fusion.sim.sky import SKY_SCENARIOS
    from ssa_fusion.studies.catalog_gaps import estimate_batches

    with tempfile.TemporaryDirectory() as tmp:
        tle = Path(tmp) / "catalog.tle"
        write_catalog(tle, objects, seed)
        entries = catalog_io.read_catalog(tle)
    steps = [(st.now, [(oid, t, st.x[j], st.P[j]) for j, (oid, t) in enumerate(st.fused)])
             for st in estimate_batches(entries, SKY_SCENARIOS["iss_network"], hours, seed)]
    out.write_bytes(pickle.dumps(steps))
    return sum(len(rows) for _, rows in steps)


def replay(stream: Path, out: Path) -> None:
    """Replay the estimates of `stream` into a GapBank of the imported tree; pickle results."""
    from ssa_fusion.core.base.types import MotionModel
    from ssa_fusion.core.catalog.gap_bank import GapBank, GapBankConfig
    from ssa_fusion.params.defaults import CATALOG_SURROGATE as D

    steps = pickle.loads(stream.read_bytes())
    bank = GapBank(GapBankConfig(motion_model=MotionModel(D.motion_model),
                                 period_s=D.predict_period, pass_break_s=D.pass_break,
                                 hold_s=D.hold, fit_budget=0.0))
    forecasts = []
    c = time.perf_counter()
    for now, rows in steps:
        for oid, t, x, P in rows:
            forecasts += bank.on_estimate(oid, t, x, P)
        forecasts += bank.step(now)
    wall = time.perf_counter() - c
    out.write_bytes(pickle.dumps({
        "fit_seconds": bank.fit_seconds, "replay_seconds": wall, "counts": dict(bank.counts),
        "forecasts": {(f.object_id, f.t): (f.x, f.P) for f in forecasts}}))


def compare(a: dict[Any, Any], b: dict[Any, Any]) -> dict[str, float]:
    """Largest differences of two trees' forecasts {(object, t): (x, P)} (the same keys)."""
    dr = dv = rel_sigma = rel_P = 0.0
    for k, (xa, Pa) in a.items():
        xb, Pb = b[k]
        d = float(np.linalg.norm(xa[:3] - xb[:3]))
        dr, dv = max(dr, d), max(dv, float(np.linalg.norm(xa[3:] - xb[3:])))
        rel_sigma = max(rel_sigma, d / float(np.sqrt(np.trace(Pa[:3, :3]))))
        rel_P = max(rel_P, float(np.abs(Pa - Pb).max() / np.abs(Pa).max()))
    return {"position_km": dr, "velocity_km_s": dv, "position_over_sigma": rel_sigma,
            "covariance_relative": rel_P}


def main() -> None:
    """Record, replay both trees alternately, print the comparison and the JSON line."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--objects", type=int, default=300)
    ap.add_argument("--hours", type=float, default=30.0)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--before", default="main", help="git revision to compare against")
    ap.add_argument("--repeats", type=int, default=2)
    ap.add_argument("--replay", nargs=2, metavar=("STREAM", "OUT"), help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.replay:
        replay(Path(args.replay[0]), Path(args.replay[1]))
        return
    with tempfile.TemporaryDirectory() as tmp:
        root = Path(tmp)
        before = root / "before"
        before.mkdir()
        archive = subprocess.run(["git", "-C", str(ROOT), "archive", args.before],
                                 capture_output=True, check=True).stdout
        subprocess.run(["tar", "-x", "-C", str(before)], input=archive, check=True)
        rev = subprocess.run(["git", "-C", str(ROOT), "rev-parse", "--short", args.before],
                             capture_output=True, text=True, check=True).stdout.strip()
        stream = root / "stream.pkl"
        c = time.perf_counter()
        n = record(args.objects, args.hours, args.seed, stream)
        print(f"{args.objects} objects, {args.hours:g} h: {n} estimates recorded in "
              f"{time.perf_counter() - c:.0f} s", flush=True)
        trees = {"before": before, "after": ROOT}
        runs: dict[str, list[dict[str, Any]]] = {k: [] for k in trees}
        for i in range(args.repeats):
            for name, tree in trees.items():
                out = root / f"{name}_{i}.pkl"
                env = {**os.environ, "PYTHONPATH": str(tree), "OPENBLAS_NUM_THREADS": "1",
                       "OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"}
                subprocess.run([sys.executable, str(Path(__file__).resolve()), "--replay",
                                str(stream), str(out)], env=env, cwd=str(tree), check=True)
                r = pickle.loads(out.read_bytes())
                runs[name].append(r)
                print(f"  {name} ({rev if name == 'before' else 'this tree'}) repeat {i + 1}: "
                      f"{r['fit_seconds']:.2f} s of fits, {r['replay_seconds']:.2f} s replay",
                      flush=True)
    result: dict[str, Any] = {"objects": args.objects, "hours": args.hours, "before": rev,
                              "estimates": n}
    for name, rs in runs.items():
        best = min(rs, key=lambda r: r["fit_seconds"])
        made = best["counts"].get("fitted", 0)
        result[name] = {"fits_made": made, "fits_refused": best["counts"].get("refused", 0),
                        "forecasts": len(best["forecasts"]),
                        "fit_seconds": round(best["fit_seconds"], 3),
                        "ms_per_fit_made": round(1e3 * best["fit_seconds"] / max(made, 1), 2),
                        "replay_seconds": round(min(r["replay_seconds"] for r in rs), 3)}
        print(f"{name}: fits made {made}, refused {result[name]['fits_refused']}, "
              f"{result[name]['forecasts']} forecasts; fits {best['fit_seconds']:.2f} s "
              f"(fastest of {len(rs)}) = {result[name]['ms_per_fit_made']:.2f} ms per fit made")
    a, b = runs["before"][0], runs["after"][0]
    assert a["counts"] == b["counts"], (a["counts"], b["counts"])
    assert a["forecasts"].keys() == b["forecasts"].keys(), "the trees forecast different epochs"
    assert result["after"]["fits_made"] > 0, "no fits made: nothing measured"
    diff = compare(a["forecasts"], b["forecasts"])
    ratio = result["before"]["fit_seconds"] / result["after"]["fit_seconds"]
    result.update({"fit_seconds_before_over_after": round(ratio, 2),
                   "replay_before_over_after": round(result["before"]["replay_seconds"]
                                                     / result["after"]["replay_seconds"], 2),
                   "forecast_difference": diff})
    print(f"fits: before / after = {ratio:.2f}x; forecasts differ by at most "
          f"{diff['position_km'] * 1e6:.3g} mm ({diff['position_over_sigma']:.2g} sigma), "
          f"{diff['velocity_km_s'] * 1e6:.3g} mm/s, covariance {diff['covariance_relative']:.2g} "
          f"relative (tolerance {POSITION_TOL_KM * 1e6:g} mm, {COVARIANCE_TOL:g})")
    assert diff["position_km"] < POSITION_TOL_KM and diff["covariance_relative"] < COVARIANCE_TOL
    print(json.dumps(result))


if __name__ == "__main__":
    main()

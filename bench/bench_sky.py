"""Benchmark of the real-sky scenarios: `studies.sky_study` over the evaluation
seeds and start epochs (the same study as `ssa-fusion reproduce --scenario
iss_radar_columbus ...`), with the time it took.

Asserts what it claims: every scenario ran every seed and start epoch, every run scored
passes after initialisation, and at least half of them all six arms over their outage (a
station's outage can fall where it would have seen nothing; the table says how often), and
that what the filter publishes between passes was scored with every ``gap_forecast``.
Prints one markdown table per scenario, the orbit-determination targets (error at every gap
epoch and over gaps > 12 h, after each pass, position NEES coverage of chi2(3)'s 95 % bound)
against what the filter publishes, how many times smaller the error of ``fit_residual``
(the fit corrected by the surrogate learnt against it) is than ``batch_fit``'s at all gap
epochs and over gaps > 12 h (`sky_study.fit_ratios`), and, last, one JSON line.

The truth (``--truth``, default ``high_fidelity``: `sim.world`, EGM96 20 x 20, Sun, Moon,
SRP, NRLMSISE-00 drag under space weather drawn from each seed; ``sgp4``: the historic SGP4
truth) is printed with every table and in the JSON. With the high-fidelity truth the runs
also score ``full_fit`` (the gap fit with the world's force model, the physics upper bound)
and the CPU time of every gap fill's fits, and the table of the learned forecaster's
targets (`sky_study.targets_49`: the fit corrected by the learned residual against the
cheap fit alone and the full fit; the live default's position NEES) is printed.

Usage: .venv/bin/python bench/bench_sky.py [--quick] [--workers N] [--scenario NAME ...]
       [--truth sgp4|high_fidelity]

``--tuning`` runs the tuning seeds (`TUNING_SEEDS` 1-3, every start epoch; ``--tuning-seeds
N`` the first N of 1-10) instead: where
the gap fit's process noise is chosen (``--gap-fit-snc`` / ``--gap-fit-snc-angles``
km^2/s^3 replace `batch_gap.GAP_FIT_SNC` / `GAP_FIT_SNC_ANGLES` for the run,
``--gap-fit-accel`` km/s^2 `batch_gap.GAP_FIT_ACCEL_SIGMA`) and its window
(``--gap-fit-passes``, ``--gap-fit-span-h``, ``--gap-fit-span-h-angles``,
``--gap-fit-max-measurements``, ``--gap-fit-solve-t-span-h``: `batch_gap.GAP_FIT_PASSES`,
`GAP_FIT_SPAN_H`, `GAP_FIT_SPAN_H_ANGLES`, `GAP_FIT_MAX_MEASUREMENTS`,
`GAP_FIT_SOLVE_T_SPAN_H`) and the calibration of its covariance (``--gap-fit-scored-fits``,
``--scale-excess-power``, ``--scale-min``: `batch_gap.GAP_FIT_SCORED_FITS`,
`calibration.EXCESS_POWER`, `calibration.MIN_SCALE`). The evaluation seeds
never choose a setting.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from dataclasses import replace
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from ssa_fusion import limit_blas_threads

limit_blas_threads()

from ssa_fusion.core.gaps import batch_gap, calibration  # noqa: E402
from ssa_fusion.sim import sky  # noqa: E402
from ssa_fusion.sim.world import TruthModel  # noqa: E402
from ssa_fusion.studies import sky_study  # noqa: E402
from ssa_fusion.studies.distributions import (  # noqa: E402
    EVALUATION_SEEDS,
    START_OFFSETS_H,
    TUNING_SEEDS,
)

TARGETS = {  # scenario -> (all gap epochs, gaps > 12 h, after each pass) km, NEES coverage
    "iss_radar_columbus": (0.20, 0.30, 0.06, 0.90),
    "iss_network": (0.10, 0.15, 0.04, 0.90),
    "iss_network_april": (0.10, 0.15, 0.04, 0.90),
    "leo_optical": (0.50, 1.0, 0.10, 0.90),
}
"""The orbit-determination targets of what the filter publishes (medians over runs)."""


def targets_table(result: dict) -> list[str]:
    """The targets against the measured medians, per scenario and gap_forecast."""
    rows = ["| scenario | filter's gap_forecast | all gap epochs [km] | gaps > 12 h [km] | "
            "after each pass [km] | position NEES <= chi2(3) 95 % |", "|---|---|---|---|---|---|"]
    for name, (g, lg, ap, cov) in TARGETS.items():
        if name not in result:
            continue
        live = str(sky.SKY_SCENARIOS[name].gap_fill)
        rows.append(f"| {name} | target | <= {g} | <= {lg} | <= {ap} | >= {100 * cov:.0f} % |")
        for fill, m in result[name]["published"].items():

            def cell(v: float | None, limit: float, pct: bool = False, ge: bool = False) -> str:
                if v is None:
                    return "-"
                ok = v >= limit if ge else v <= limit
                text = f"{100 * v:.1f} %" if pct else f"{v:.3g}"
                return f"{text} ({'met' if ok else 'not met'})"

            rows.append(f"| {name} | {fill}{' (live default)' if fill == live else ''} | "
                        f"{cell(m['err_median_km'], g)} | {cell(m['long_err_median_km'], lg)} | "
                        f"{cell(m['after_pass_median_km'], ap)} | "
                        f"{cell(m['nees_in_95'], cov, pct=True, ge=True)} |")
    return rows


def learned_table(result: dict) -> list[str]:
    """The learned forecaster's targets (issue 49) against the measured values."""
    rows = ["| scenario | measure | target | measured |", "|---|---|---|---|"]
    for name, r in result.items():
        t = r["targets_49"]

        def row(what: str, target: str, value: float | None, ok: bool | None,
                name: str = name) -> str:
            text = "-" if value is None else f"{value:.3g}"
            verdict = "" if ok is None else (" (met)" if ok else " (not met)")
            return f"| {name} | {what} | {target} | {text}{verdict} |"

        v = t["cheap_over_corrected_long"]
        rows.append(row("cheap fit / fit + learned correction, gaps > 12 h (median of runs)",
                        ">= 1.5", v, None if v is None else v >= 1.5))
        for key, what in (("corrected_over_cheap_all", "all gap epochs"),
                          ("corrected_over_cheap_long", "gaps > 12 h")):
            v = t[key]
            rows.append(row(f"fit + correction / cheap fit, {what} (ratio of medians)",
                            "<= 1.05", v, None if v != v else v <= 1.05))
        rows.append(row("fit + correction / cheap fit, worst run", "(no target)",
                        t["corrected_over_cheap_worst_run"], None))
        if "corrected_over_full_long" in t:
            v, c = t["corrected_over_full_long"], t["cpu_corrected_over_cheap"]
            rows.append(row("fit + correction / full-force fit, gaps > 12 h", "<= 1.3", v,
                            v <= 1.3))
            rows.append(row("cheap fit / full-force fit, gaps > 12 h", "(reference)",
                            t["cheap_over_full_long"], None))
            rows.append(row("CPU: fit + correction / cheap fit", "<= 1.5", c, c <= 1.5))
            rows.append(row("CPU: full-force fit / cheap fit", "(reference)",
                            t["cpu_full_over_cheap"], None))
        n, cov = t["nees_median"], t["nees_in_95"]
        rows.append(row(f"median position NEES at gap epochs ({t['live']})", "[1.6, 3.7]", n,
                        1.6 <= n <= 3.7))
        rows.append(row(f"position NEES <= chi2(3) 95 % ({t['live']})", "90-98 %", 100 * cov,
                        0.90 <= cov <= 0.98))
        rows.append(f"| {name} | step-aside choices of fit_residual (gaps) | | "
                    f"{t['choices']} |")
    return rows


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--quick", action="store_true", help="3 seeds, one start epoch")
    ap.add_argument("--eval-seeds", type=int, default=0,
                    help="only the first N evaluation seeds (0: all 20, 101-120)")
    ap.add_argument("--offsets", type=float, nargs="*", default=None,
                    help="start offsets, h (default 0 8 16; --quick 0)")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--scenario", nargs="*", default=list(sky.SKY_SCENARIOS))
    ap.add_argument("--gaps-only", action="store_true",
                    help="score only what is published with batch_init and fit_residual (and "
                         "the full fit): the learned forecaster's targets, without the arms "
                         "over the outage")
    ap.add_argument("--truth", choices=[str(t) for t in TruthModel],
                    default=str(TruthModel.HIGH_FIDELITY),
                    help="the object's truth (default high_fidelity: sim.world)")
    ap.add_argument("--tuning", action="store_true",
                    help="the tuning seeds 1-3 (every start epoch), not the evaluation seeds")
    ap.add_argument("--tuning-seeds", type=int, default=3,
                    help="with --tuning: how many of the tuning seeds (the first N of "
                         "TUNING_SEEDS, 1-10)")
    for flag, kind, what in (
            ("--gap-fit-snc", float, "the gap fit's SNC for windows with ranges"),
            ("--gap-fit-snc-angles", float, "the gap fit's SNC for windows of angles"),
            ("--gap-fit-accel", float, "the standard deviation (km/s^2) of the gap fit's "
                                       "considered R, T, N accelerations for windows with ranges"),
            ("--gap-fit-passes", int, "the fewest passes of the gap fit's window"),
            ("--gap-fit-span-h", float, "the span (h) of the gap fit's window"),
            ("--gap-fit-span-h-angles", float, "the span (h) of the window of angles only"),
            ("--gap-fit-max-measurements", int, "the most measurements of the gap fit's window"),
            ("--gap-fit-solve-t-span-h", float, "the span (h) from which a ranged gap fit "
                                                "solves for the along-track acceleration"),
            ("--gap-fit-scored-fits", int, "how many of the last gap fits the calibration "
                                           "scores on each pass"),
            ("--scale-excess-power", float, "the power of the horizon with which the gap "
                                            "covariance's calibration grows beyond the "
                                            "horizons its passes saw"),
            ("--scale-min", float, "the least factor the gap covariance's calibration may "
                                   "put on the fit's covariance")):
        ap.add_argument(flag, type=kind, default=None, help=f"with --tuning: {what}")
    args = ap.parse_args()
    constants = {  # module constants a tuning run replaces, read where they are used
        (batch_gap, "GAP_FIT_PASSES"): args.gap_fit_passes,
        (batch_gap, "GAP_FIT_SPAN_H"): args.gap_fit_span_h,
        (batch_gap, "GAP_FIT_SPAN_H_ANGLES"): args.gap_fit_span_h_angles,
        (batch_gap, "GAP_FIT_MAX_MEASUREMENTS"): args.gap_fit_max_measurements,
        (batch_gap, "GAP_FIT_SOLVE_T_SPAN_H"): args.gap_fit_solve_t_span_h,
        (batch_gap, "GAP_FIT_SCORED_FITS"): args.gap_fit_scored_fits,
        (calibration, "EXCESS_POWER"): args.scale_excess_power,
        (calibration, "MIN_SCALE"): args.scale_min}
    chosen = (args.gap_fit_snc, args.gap_fit_snc_angles, args.gap_fit_accel,
              *constants.values())
    if any(v is not None for v in chosen) and not args.tuning:
        ap.error("--gap-fit-* and --scale-* options choose settings: --tuning only")
    if not 1 <= args.tuning_seeds <= len(TUNING_SEEDS):
        ap.error(f"--tuning-seeds: 1 to {len(TUNING_SEEDS)}")
    for (module, name), value in constants.items():
        if value is not None:
            setattr(module, name, value)
    if args.gap_fit_snc is not None:  # the worker processes are forked: they inherit it
        batch_gap.GAP_FIT = replace(batch_gap.GAP_FIT, snc_psd=(args.gap_fit_snc,) * 3)
    if args.gap_fit_accel is not None:
        batch_gap.GAP_FIT = batch_gap.with_accel_sigma(batch_gap.GAP_FIT, args.gap_fit_accel)
    if args.gap_fit_snc_angles is not None:
        batch_gap.GAP_FIT_ANGLES = replace(batch_gap.GAP_FIT_ANGLES,
                                           snc_psd=(args.gap_fit_snc_angles,) * 3)
    seeds = (TUNING_SEEDS[:args.tuning_seeds] if args.tuning else
             EVALUATION_SEEDS[:3] if args.quick else
             EVALUATION_SEEDS[:args.eval_seeds] if args.eval_seeds else EVALUATION_SEEDS)
    offsets = (tuple(args.offsets) if args.offsets is not None else
               (0.0,) if args.quick and not args.tuning else START_OFFSETS_H)
    t0 = time.perf_counter()
    truth = TruthModel(args.truth)
    text, result = sky_study.run_sky_study(args.scenario, seeds, offsets, args.workers,
                                           truth=truth, gaps_only=args.gaps_only)
    wall = time.perf_counter() - t0
    for name in [] if args.gaps_only else args.scenario:  # every run, passes, outages scored
        r = result[name]
        assert r["runs"] == r["runs_with_passes"] == len(seeds) * len(offsets), (name, r)
        assert r["runs_with_outage"] >= 0.5 * r["runs"], (name, r)
        assert all(m["err_median_km"] is not None for m in r["published"].values()), (name, r)
        assert r["batch_fit_over_fit_residual"]["all gap epochs: median of run ratios"] \
            is not None, (name, r)  # the fit and the fit corrected were both scored
    print(f"Truth: {truth} (seeds {list(seeds)}, start offsets {list(offsets)} h)\n")
    print(text + "\n")
    if not args.gaps_only:
        print("Targets of what the filter publishes (medians over runs):\n")
        print("\n".join(targets_table(result)) + "\n")
    for name in args.scenario:  # every run scored every gap fill it ran
        assert result[name]["runs"] == len(seeds) * len(offsets), (name, result[name]["runs"])
    print(f"The learned forecaster against its references ({truth} truth):\n")
    print("\n".join(learned_table(result)) + "\n")
    print(f"{len(args.scenario) * len(seeds) * len(offsets)} runs in {wall:.0f} s")
    print(json.dumps({"truth": str(truth), "seeds": list(seeds), "start_offsets_h": list(offsets),
                      "wall_s": wall, **result}))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

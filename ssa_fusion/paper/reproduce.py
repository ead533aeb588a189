"""`ssa-fusion reproduce`: the paper's experiments, every arm of `paper.arms` per scenario
(the paper's three plus the coasting EKF and the J2 EKF coasting), plus the Van der Pol
sweep and the surrogate consistency study (paper section 4).

Writes OUT/results.json, OUT/results.md (the table) and PNG plots; prints the table.
Same seed, same numbers. ``--quick`` shortens the tracking windows and gaps (for tests).
"""

from __future__ import annotations

import json
import math
import sys
import time
from pathlib import Path

import numpy as np

from ssa_fusion.core.hankel_dmd import HankelDMD
from ssa_fusion.core.iod import razel_to_eci
from ssa_fusion.paper import distributions, experiments, scenarios
from ssa_fusion.paper.simulate import simulate

ARMS = ("placeholder", "dmd_ekf", "hypothetical_ekf")
TARGET_CLOSE = ("iss_j2_pos", "iss_sgp4_pos", "iss_j2_pos_noisy", "iss_j2_rae",
                "cr3bp_halo_noisy")
NEES_RUNS = 10
NEES_RUNS_QUICK = 3
QUICK_SEEDS = 3
VDP_MUS = np.round(np.arange(1.0, 3.0 + 1e-9, 0.1), 10)
VDP_MUS_QUICK = np.array([1.0, 2.0, 3.0])
CONSISTENCY_SCENARIO = "iss_j2_pos_noisy"
CONSISTENCY_SEEDS = 20
CONSISTENCY_RETRAIN_STEPS = 31  # new measurements (and a refit) every 31 cadences


# ----------------------------------------------------------------------------------------
class Progress:
    """A one-line progress bar on stderr (no dependency)."""

    def __init__(self, total: int, stream=None, width: int = 30) -> None:
        # sys.stderr looked up now, not at import (it may have been replaced since)
        self.total, self.done, self.width = total, 0, width
        self.stream = stream if stream is not None else sys.stderr
        self.t0 = time.monotonic()

    def step(self, label: str) -> None:
        self.done += 1
        frac = self.done / max(1, self.total)
        bar = "#" * round(frac * self.width)
        el = time.monotonic() - self.t0
        self.stream.write(f"\r[{bar:<{self.width}}] {self.done}/{self.total} "
                          f"{el:5.0f}s {label:<28}")
        self.stream.flush()
        if self.done >= self.total:
            self.stream.write("\n")
            self.stream.flush()


def quick_variant(s: scenarios.Scenario) -> scenarios.Scenario:
    """Shorter tracking window and gap (same cadence and estimator settings)."""
    track = max(s.track_s / 2, 2 * s.delays * s.cadence_s + 4 * s.cadence_s)
    track = s.cadence_s * round(track / s.cadence_s)
    gap = s.cadence_s * max(10, round(s.gap_s / 2 / s.cadence_s))
    return s.with_(track_s=track, gap_s=gap)


def settings_of(s: scenarios.Scenario, sim) -> dict:
    sc = experiments.make_surrogate(s).config
    return {
        "truth": s.truth, "placeholder": s.placeholder,
        "placeholder_params": s.placeholder_params, "observed": (
            "range_az_el" if s.kind == 1 else list(s.observed)),
        "cadence_s": s.cadence_s, "training_window_s": sc.buffer_s,
        "gap_s": s.gap_s, "gap_epochs": int(sim.in_gap.sum()),
        "delays": s.delays,
        "rank": s.rank if s.rank is not None else f"auto (SVHT, <= {HankelDMD(1).max_rank})",
        "surrogate_observable": "ECI position from range/az/el" if s.lift == "eci"
        else "measurement",
        "forecast_covariance": (f"R + k^{sc.correlation_power:g} * D(k), Var(e(k)) = R + D(k), "
                                "D >= 0 (k-th forecast of the gap)") if sc.inflate_correlated
        else "Var(e(k)) = R + D(k), D >= 0",
        "whitened": bool(sc.whiten and sc.lift is None and s.kind != 1
                         and np.all(sim.sigma > 0)),
        "iod_samples": s.iod_samples,
        "P0": "IOD covariance (R through the IOD map) + diag(p0_sigma^2)",
        "p0_sigma": list(s.p0_sigma), "Q": "white-noise acceleration, q [units^2/s^3]",
        "q": s.q, "R_sigma": [float(v) for v in sim.sigma],
        "noise_rel": s.noise_rel, "seed_note": "noise seed = --seed",
        "particles": experiments.N_PARTICLES,
    }


def run_one(s: scenarios.Scenario, seed: int, nees_runs: int, out: Path, plots: bool) -> dict:
    t0 = time.monotonic()
    r = experiments.run_scenario(s, seed, nees_runs=nees_runs)
    sim, ev, dmd = r.pop("_sim"), r.pop("_eval"), r.pop("_dmd_trajectory")
    r.pop("_forecast")
    eps = {k: r["arms"][k]["epsilon"] for k in r["arms"]}
    r["ratios"] = {
        "dmd_over_hypothetical": eps["dmd_ekf"] / eps["hypothetical_ekf"],
        "placeholder_over_dmd": eps["placeholder"] / eps["dmd_ekf"],
        "coast_over_dmd": eps["coast"] / eps["dmd_ekf"],
    }
    if "j2_coast" in eps:
        r["ratios"]["j2_coast_over_dmd"] = eps["j2_coast"] / eps["dmd_ekf"]
    r["settings"] = settings_of(s, sim)
    r["paper_finding"] = s.finding
    r["targets"] = targets(s.name, r)
    if plots:
        from ssa_fusion.paper import plots as pl
        # orbits in hours; the CR3BP runs on its nondimensional time unit (TU)
        unit = "h" if s.is_orbit else ("TU" if s.truth == "cr3bp" else "s")
        files = [pl.error_plot(s.name, sim, ev.arms, out / f"{s.name}_error.png", unit).name]
        if r["noisy"]:
            files.append(pl.sigma_plot(s.name, sim, dmd, out / f"{s.name}_sigma.png",
                                       unit).name)
        r["plots"] = files
    r["seconds"] = round(time.monotonic() - t0, 2)
    return r


def targets(name: str, r: dict) -> dict:
    """The issue's targets where the paper found DMD-EKF close to hypothetical."""
    if name not in TARGET_CLOSE:
        return {}
    out = {
        "dmd_over_hyp_le_1.5": bool(r["ratios"]["dmd_over_hypothetical"] <= 1.5),
    }
    if r.get("nees"):
        lo, hi = r["nees"]["band95"]
        out["nees_in_band"] = bool(lo <= r["nees"]["dmd_ekf_mean"] <= hi)
    return out


# ----------------------------------------------------------------------------------------
def consistency_study(s: scenarios.Scenario, seeds: int, retrain_steps: int) -> dict:
    """Paper section 4: the surrogate's forecast error variance against horizon.

    one-shot: one Hankel-DMD fit on the tracking window, forecasts through the whole gap.
    retrained: the sensor comes back every `retrain_steps` cadences; the model is refitted on
    the window ending at the newest real measurement and forecasts the next cadences.
    Errors are forecast minus the (noisy) measurement the sensor would have made, the
    quantity the surrogate's covariance describes; the statistics pool `seeds` noise
    realisations. Only the surrogate is involved (no filter)."""
    H = round(s.gap_s / s.cadence_s)
    n_train = round(s.track_s / s.cadence_s)
    e_one, c_one, e_re, c_re = [], [], [], []
    for seed in range(seeds):
        sim = simulate(s, seed)
        Z = sim.z
        if s.lift == "eci":
            Z = razel_to_eci(Z, s.jd0 + sim.t / 86400.0, scenarios.station(s))
        g0 = int(np.flatnonzero(sim.in_gap)[0])
        m = HankelDMD(s.delays, s.rank).fit(Z[g0 - n_train:g0].T)
        e_one.append(m.forecast(H).T - Z[g0:g0 + H])
        c_one.append(m.forecast_covariance(H))
        er, cr = [], []
        for o in range(0, H, retrain_steps):
            k = min(retrain_steps, H - o)
            end = g0 + o  # measurements up to index end-1 are real (sensor came back)
            mo = HankelDMD(s.delays, s.rank).fit(Z[end - n_train:end].T)
            er.append(mo.forecast(k).T - Z[end:end + k])
            cr.append(mo.forecast_covariance(k))
        e_re.append(np.concatenate(er))
        c_re.append(np.concatenate(cr))

    def stats(e: list, c: list) -> dict:
        e, c = np.array(e), np.array(c)  # (seeds, H, m), (seeds, H, m, m)
        emp = np.mean(np.sum(e**2, axis=2), axis=0)
        pred = np.mean(np.trace(c, axis1=2, axis2=3), axis=0)
        sol = np.linalg.solve(c, e[..., None])[..., 0]
        nees_h = np.mean(np.sum(e * sol, axis=2), axis=0)
        return {"empirical_var": emp.tolist(), "predicted_var": pred.tolist(),
                "forecast_nees_mean": float(np.mean(nees_h)),
                "empirical_var_at_end": float(emp[-1]),
                "empirical_var_mean": float(np.mean(emp))}

    unit, scale = ("min", 60.0) if s.is_orbit else ("s", 1.0)
    return {
        "scenario": s.name, "seeds": seeds, "retrain_every_steps": retrain_steps,
        "channels": int(np.array(e_one).shape[2]), "R_trace": float(np.trace(sim.R)),
        "horizon_s": (s.cadence_s * np.arange(1, H + 1)).tolist(),
        "time_unit": unit, "time_scale": scale,
        "one_shot": stats(e_one, c_one), "retrained": stats(e_re, c_re),
    }


# ----------------------------------------------------------------------------------------
def _fmt(v: float | None) -> str:
    return "—" if v is None or not math.isfinite(v) else f"{v:.3g}"


def table(results: dict) -> str:
    rows = ["| scenario | ε placeholder | ε coast | ε J2 coast | ε DMD-EKF | ε hypothetical | "
            "DMD/hyp | coast/DMD | J2 coast/DMD | NEES DMD-EKF (95 % band) | targets | paper |",
            "|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for name, r in results["scenarios"].items():
        a = r["arms"]
        nees = "—"
        if r.get("nees"):
            lo, hi = r["nees"]["band95"]
            nees = f"{r['nees']['dmd_ekf_mean']:.2f} ({lo:.2f}–{hi:.2f}, {r['nees']['runs']} runs)"
        tg = r.get("targets") or {}
        tgs = "—" if not tg else ("pass" if all(tg.values()) else
                                  "FAIL: " + ", ".join(k for k, v in tg.items() if not v))
        rows.append(
            f"| {name} | {_fmt(a['placeholder']['epsilon'])} | {_fmt(a['coast']['epsilon'])} "
            f"| {_fmt(a.get('j2_coast', {}).get('epsilon'))} | {_fmt(a['dmd_ekf']['epsilon'])} "
            f"| {_fmt(a['hypothetical_ekf']['epsilon'])} "
            f"| {_fmt(r['ratios']['dmd_over_hypothetical'])} "
            f"| {_fmt(r['ratios']['coast_over_dmd'])} "
            f"| {_fmt(r['ratios'].get('j2_coast_over_dmd'))} | {nees} | {tgs} "
            f"| {r['paper_finding']} |")
    for name, r in results["scenarios"].items():
        frac = r["arms"]["dmd_ekf"].get("forecast_fraction", 1.0)
        if frac < 1.0:
            rows.append(f"\n{name}: the DMD-EKF fused forecasts at {100 * frac:.0f} % of the "
                        "gap epochs; the others carry the filter's prediction.")
    return "\n".join(rows)


def _ratio(d: dict, key: str) -> str:
    r = d["ratios"].get(key)
    if r is None:
        return "—"
    return f"{_fmt(r['median'])} [{_fmt(r['q25'])}–{_fmt(r['q75'])}] {_fmt(r['worst'])}"


def distribution_table(dist: dict) -> str:
    """Markdown table of the distributions over the evaluation seeds (and start epochs)."""
    rows = ["| scenario | runs | ε DMD-EKF (median) | ε(DMD-EKF)/ε(coast) | "
            "ε(DMD-EKF)/ε(J2 coast) | ε(DMD-EKF)/ε(hypothetical) | DMD-EKF beats coasting |",
            "|---|---|---|---|---|---|---|"]
    for name, d in dist.items():
        rows.append(f"| {name} | {d['runs']} | {_fmt(d['epsilon_median']['dmd_ekf'])} | "
                    f"{_ratio(d, 'dmd_over_coast')} | {_ratio(d, 'dmd_over_j2_coast')} | "
                    f"{_ratio(d, 'dmd_over_hypothetical')} | "
                    f"{100 * d['dmd_beats_coast']:.0f} % |")
    first = next(iter(dist.values()))
    rows.append(f"\nratios: median [interquartile range] worst (largest) over seeds "
                f"{first['seeds'][0]}-{first['seeds'][-1]} (never used for tuning); below 1 "
                f"the DMD-EKF is better. Range/az/el scenarios from "
                f"{len(max((d['start_offsets_h'] for d in dist.values()), key=len))} start "
                f"epoch(s).")
    return "\n".join(rows)


def markdown(results: dict) -> str:
    lines = ["# Reproduction of the paper's experiments", "",
             f"seed {results['seed']}, quick={results['quick']}, "
             f"{results['seconds']:.0f} s", "", table(results), ""]
    if results.get("distributions"):
        lines += ["## Distributions over the evaluation seeds", "",
                  distribution_table(results["distributions"]), ""]
    v = results.get("vdp_sweep")
    if v:
        lines += ["## Van der Pol: ε over the gap against the placeholder μ_p", "",
                  "| μ_p | " + " | ".join(ARMS) + " |", "|---|---|---|---|"]
        for i, mu in enumerate(v["mu_p"]):
            lines.append(f"| {mu:.1f} | " + " | ".join(_fmt(v[a][i]) for a in ARMS) + " |")
        lines.append("")
    c = results.get("consistency")
    if c:
        lines += [f"## Surrogate consistency ({c['scenario']}, {c['seeds']} seeds)", "",
                  "| training | mean Var(e) | Var(e) at gap end | forecast NEES (dof "
                  f"{c['channels']}) |", "|---|---|---|---|"]
        for k in ("one_shot", "retrained"):
            d = c[k]
            lines.append(f"| {k} | {_fmt(d['empirical_var_mean'])} | "
                         f"{_fmt(d['empirical_var_at_end'])} | {_fmt(d['forecast_nees_mean'])} |")
        lines.append("")
    return "\n".join(lines)


def _jsonable(o):
    if isinstance(o, dict):
        return {str(k): _jsonable(v) for k, v in o.items()}
    if isinstance(o, (list, tuple)):
        return [_jsonable(v) for v in o]
    if isinstance(o, (np.floating, float)):
        return float(o) if math.isfinite(o) else None
    if isinstance(o, (np.integer,)):
        return int(o)
    if isinstance(o, np.bool_):
        return bool(o)
    if isinstance(o, np.ndarray):
        return _jsonable(o.tolist())
    return o


# ----------------------------------------------------------------------------------------
def add_arguments(parser) -> None:
    parser.add_argument("--scenario", nargs="+", metavar="NAME", default=None,
                        help=f"scenarios to run (default: all: {', '.join(scenarios.SCENARIOS)})")
    parser.add_argument("--out", default="out/reproduce",
                        help="output directory (default out/reproduce)")
    parser.add_argument("--seed", type=int, default=1, help="noise and Monte Carlo seed")
    parser.add_argument("--quick", action="store_true",
                        help="shorter windows and fewer runs (about 45 s; the shorter "
                             "training windows miss some targets the full run meets)")
    parser.add_argument("--no-plots", action="store_true", help="skip the PNG plots")
    parser.add_argument("--no-studies", action="store_true",
                        help="skip the Van der Pol sweep and the consistency study")
    parser.add_argument("--seeds", type=int, default=None, metavar="N",
                        help=f"evaluation seeds of the distributions (default "
                             f"{len(distributions.EVALUATION_SEEDS)}, --quick "
                             f"{QUICK_SEEDS}; 0 skips them)")
    parser.add_argument("--workers", type=int, default=None,
                        help="processes for the distributions (default: the CPU count)")


def run(args) -> int:
    names = args.scenario or list(scenarios.SCENARIOS)
    try:
        chosen = [scenarios.get(n) for n in names]
    except ValueError as exc:
        print(f"ssa-fusion reproduce: {exc}", file=sys.stderr)
        return 2
    out = Path(args.out)
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        print(f"ssa-fusion reproduce: cannot use --out {out}: {exc}", file=sys.stderr)
        return 2
    plots = not args.no_plots
    studies = not args.no_studies
    do_vdp = studies and "vdp" in names
    do_cons = studies and (args.scenario is None or CONSISTENCY_SCENARIO in names)
    if args.quick:
        chosen = [quick_variant(s) for s in chosen]
    nees_runs = NEES_RUNS_QUICK if args.quick else NEES_RUNS
    t0 = time.monotonic()
    bar = Progress(len(chosen) + int(do_vdp) + int(do_cons))
    results = {"seed": args.seed, "quick": bool(args.quick), "scenarios": {}}
    for s in chosen:
        results["scenarios"][s.name] = run_one(s, args.seed, nees_runs, out, plots)
        bar.step(s.name)
    if do_vdp:
        sv = next(s for s in chosen if s.name == "vdp")
        mus = VDP_MUS_QUICK if args.quick else VDP_MUS
        results["vdp_sweep"] = experiments.vdp_sweep(sv, args.seed, mus)
        if plots:
            from ssa_fusion.paper import plots as pl
            pl.vdp_sweep_plot(results["vdp_sweep"], out / "vdp_sweep.png")
        bar.step("vdp sweep")
    if do_cons:
        sc = scenarios.get(CONSISTENCY_SCENARIO)
        if args.quick:
            sc = quick_variant(sc)
        seeds = 3 if args.quick else CONSISTENCY_SEEDS
        results["consistency"] = consistency_study(sc, seeds, CONSISTENCY_RETRAIN_STEPS)
        if plots:
            from ssa_fusion.paper import plots as pl
            pl.consistency_plot(results["consistency"], out / "consistency.png")
        bar.step("consistency study")
    n_seeds = args.seeds if args.seeds is not None else (
        QUICK_SEEDS if args.quick else len(distributions.EVALUATION_SEEDS))
    if n_seeds > 0:
        seeds = distributions.EVALUATION_SEEDS[:n_seeds] if n_seeds <= len(
            distributions.EVALUATION_SEEDS) else tuple(range(101, 101 + n_seeds))
        offsets = (0.0,) if args.quick else distributions.START_OFFSETS_H
        runs = sum(len(distributions.cases(s, seeds, offsets)) for s in chosen)
        dbar = Progress(runs)
        print(f"distributions: {len(seeds)} evaluation seeds ({seeds[0]}-{seeds[-1]}; settings "
              f"were chosen on seeds {distributions.TUNING_SEEDS[0]}-"
              f"{distributions.TUNING_SEEDS[-1]}), range/az/el from "
              f"{len(offsets)} start epoch(s): {runs} runs"
              + (" (--quick: fewer seeds and one start epoch)" if args.quick else ""),
              file=sys.stderr)
        results["distributions"] = distributions.run_distributions(
            chosen, seeds, offsets, args.workers, dbar.step)
    results["seconds"] = round(time.monotonic() - t0, 1)
    (out / "results.json").write_text(json.dumps(_jsonable(results), indent=1))
    md = markdown(results)
    (out / "results.md").write_text(md)
    print(table(results))
    if results.get("distributions"):
        print("\n" + distribution_table(results["distributions"]))
    print(f"\nwrote {out / 'results.json'}, {out / 'results.md'} and plots "
          f"in {results['seconds']:.0f} s")
    return 0

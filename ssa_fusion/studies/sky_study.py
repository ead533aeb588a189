"""The real-sky study: what the filter achieves with stations that see only above their masks.

Distributions over evaluation seeds and start epochs, on the scenarios of `sky`. Per run
(simulate, then filter + surrogate over the delivered measurements as the live graph drives
them): the position error right after each pass, the NEES at every truth epoch
(predictions through the gaps included), and every arm over the scheduled outage
(`placeholder`, `coast`, `j2_coast`, `batch_fit`, `dmd_ekf`, `hypothetical_ekf`: mean
position error and NEES); also the after-pass error of the same filter with its light-time
correction off (the cost of ignoring light time); and what the filter publishes between
passes with each ``gap_forecast`` (`evaluation.gap_scores`: error at every gap epoch and
over gaps > 12 h, after each pass, position NEES against chi2(3); and how many times smaller
the error of ``fit_residual`` is than ``batch_fit``'s, `fit_ratios`). Seeds are
`distributions.EVALUATION_SEEDS` (never used to choose a setting: `sky.SKY_Q` was chosen on
seeds 1-3); start epochs `distributions.START_OFFSETS_H` after the nominal one move the
passes, and each seed turns the orbit (`case_geometry`: its plane by up to
`RAAN_SPREAD_DEG` about the pole, its phase anywhere along it), so that no two runs share
their passes and gaps; a network scenario's case also observes with a network of its own,
drawn from the scenario's pool of real sites (`case_sites`: as many radars and optical
sites as the scenario has; no tuning and evaluation case share one). Each run asserts that
it scored passes and all six arms.

The truth is a case's choice (`sim.world.TruthModel`): SGP4 with the ISS's B* (the historic
one), or the high-fidelity world (EGM96 20 x 20, Sun, Moon, SRP, NRLMSISE-00 drag under
space weather drawn from the case's seed). With the high-fidelity truth the runs also score
the physics upper bound, ``full_fit`` (`FULL_FIT`): the same gap fit and restart as
``batch_init`` with the world's own force model (`sim.world.force_spec`; its drag the
exponential atmosphere with the fitted factor), with the CPU time of every fit (`cpu_s`)
and the step-aside choices of ``fit_residual`` (`core.gaps.step_aside`); `targets_49`
compares them. Units: km, h.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from concurrent.futures import ProcessPoolExecutor
from dataclasses import asdict, replace
from typing import Any

import numpy as np

from ssa_fusion.core.gaps import batch_gap
from ssa_fusion.core.gaps.publisher import GapFill
from ssa_fusion.core.od.batch_ls import BatchOptions
from ssa_fusion.evaluation import arms, gap_scores, passes
from ssa_fusion.sim import sky, world
from ssa_fusion.sim.world import TruthModel
from ssa_fusion.studies import sky_runs
from ssa_fusion.studies.distributions import EVALUATION_SEEDS, TUNING_SEEDS

ARMS = [str(a) for a in arms.ArmName]


RAAN_SPREAD_DEG = sky.RAAN_SPREAD_DEG
case_geometry = sky.case_geometry
"""A case's orbit turn (`sim.sky.case_geometry`, which `ssa-fusion live --seed` shares)."""


CASE_SEEDS = (*TUNING_SEEDS, *EVALUATION_SEEDS)
"""The seeds whose networks `case_sites` keeps apart: every tuning and evaluation seed."""


def case_sites(s: sky.SkyScenario, seed: int) -> tuple[str, ...]:
    """Return the sensors of case `seed` of scenario `s`: a network of its `site_pool`.

    One of `s.network_choices()` (the scenario's own sensors when it has no pool: a single
    station), drawn without replacement over `CASE_SEEDS`: the choices are shuffled once
    (a fixed generator) and the k-th of `CASE_SEEDS` takes the k-th, so every tuning and
    evaluation case has a network of its own (as long as there are as many choices as
    seeds: 35 and 350 for 30) and no evaluation case shares one with a tuning case. Any
    other seed draws one from a generator of its own. The same seed, the same sites.
    """
    choices = s.network_choices()
    order = np.random.default_rng([len(choices), 11]).permutation(len(choices))
    k = (CASE_SEEDS.index(seed) if seed in CASE_SEEDS
         else int(np.random.default_rng([seed, 11]).integers(len(choices))))
    return choices[int(order[k % len(choices)])]


def case_scenario(name: str, offset_h: float, seed: int,
                  truth: TruthModel = TruthModel.SGP4) -> sky.SkyScenario:
    """Return case (scenario name, start offset h, seed): its start, orbit and network.

    The start `offset_h` after the scenario's, the orbit turned (`case_geometry`), the
    sites drawn (`case_sites`), the `truth`; a high-fidelity world's space weather drawn
    from `seed`.
    """
    base = sky.SKY_SCENARIOS[name]
    out = (base.with_(t0=base.t0 + 3600.0 * offset_h).with_geometry(*case_geometry(seed))
           .with_sensors(case_sites(base, seed)))
    if truth == TruthModel.SGP4:
        return out
    return out.with_(truth=truth, world=base.world.with_(weather_seed=seed))


FULL_FIT = "full_fit"
"""The published-table row of the gap fit with the world's force model (the upper bound)."""


def full_fit_options(s: sky.SkyScenario) -> BatchOptions:
    """Return the gap fit of `s` with its world's force model (`sim.world.force_spec`).

    The live gap fit's options (`batch_gap.GAP_FIT`, or `GAP_FIT_ANGLES` for a scenario
    without a radar: read at the call) with the force model replaced.
    """
    live = batch_gap.GAP_FIT if s.radars else batch_gap.GAP_FIT_ANGLES
    return replace(live, force=world.force_spec(s.world))


GAP_FILLS_OF_THE_TARGETS = (GapFill.BATCH_INIT, GapFill.FIT_RESIDUAL)
"""The gap fills a gaps-only run scores (`run_gap_case`): the cheap fit, and the same fit
corrected by the learned residual (with the full fit beside them, high-fidelity)."""


def _published(s: sky.SkyScenario, sim: sky.SkySimulation,
               only: tuple[GapFill, ...] = tuple(GapFill)) -> dict[str, Any]:
    """Score what the filter publishes with each gap fill (and the full fit, high-fidelity)."""
    c = s.estimator()
    fills: list[tuple[str, GapFill, BatchOptions | None]] = [
        (str(f), f, None) for f in only]
    if s.truth == TruthModel.HIGH_FIDELITY:
        fills.append((FULL_FIT, GapFill.BATCH_INIT, full_fit_options(s)))
    out = {}
    for key, f, options in fills:
        run = gap_scores.publish_run(c, sim.real, sim.t, f, options)
        out[key] = {**asdict(gap_scores.score_gaps(run.estimates, sim.real, sim.t, sim.x)),
                    "cpu_s": run.cpu_s, "choices": run.choices}
    return out


def run_gap_case(case: tuple[str, float, int, str]) -> dict[str, Any]:
    """Run one case (scenario name, start offset h, seed, truth): what is published only.

    The gap fills of `GAP_FILLS_OF_THE_TARGETS` (and the full fit), without the arms over
    the outage or the light-time comparison of `run_case`: the learned forecaster's
    targets in a fraction of the time.
    """
    name, offset_h, seed, truth = case
    s = case_scenario(name, offset_h, seed, TruthModel(truth))
    sim = sky.simulate_sky(s, seed=seed)
    return {"published": _published(s, sim, GAP_FILLS_OF_THE_TARGETS), "truth": truth}


def summarise_gaps(name: str, runs: list[dict[str, Any]]) -> tuple[str, dict[str, Any]]:
    """Return the Markdown and JSON summary of `run_gap_case` runs of scenario `name`."""
    truth = runs[0]["truth"]
    pub_lines, pub_summary = _published_table(runs)
    t49 = targets_49(runs, sky.SKY_SCENARIOS[name].gap_fill)
    lines = [f"### {name} ({len(runs)} runs, {truth} truth, what is published only: medians "
             "[quartiles] over runs)", "", *pub_lines, "",
             "- the learned correction against its references: " + ", ".join(
                 f"{k} {v:.3g}" if isinstance(v, float) else f"{k} {v}"
                 for k, v in t49.items())]
    return "\n".join(lines), {"runs": len(runs), "truth": truth, "published": pub_summary,
                              "targets_49": t49}


def run_case(case: tuple[str, float, int] | tuple[str, float, int, str]) -> dict[str, Any]:
    """Run one case (scenario name, start offset h, seed[, truth]); return its numbers."""
    name, offset_h, seed = case[:3]
    truth = TruthModel(case[3]) if len(case) > 3 else TruthModel.SGP4
    s = case_scenario(name, offset_h, seed, truth)
    sim = sky.simulate_sky(s, seed=seed)
    ev = sky_runs.evaluate_sky(sim, seed=seed)
    after = [p[3] for p in ev.passes.passes]
    c_off = s.with_(light_time=False).estimator()  # the same measurements (light time in)
    off = passes.pass_report(c_off, arms.run_filter(c_off, sim.real), sim.real, sim.t, sim.x)
    o = ev.outage  # None where the outage's station would have seen nothing
    if o is not None and set(o.scores) != set(arms.ArmName):
        raise RuntimeError(f"{case}: an arm is missing over the outage")
    lo, hi = ev.passes.nees_band
    return {"published": _published(s, sim), "truth": str(truth), "after_pass_km": after,
            "nees_mean": float(np.mean(ev.passes.nees)),
            "nees_in_band": ev.passes.nees_in_band, "nees_band": [lo, hi],
            "gaps_h": ev.passes.gaps_h.tolist(), "forecasts": ev.forecasts,
            "outage_mean_km": None if o is None else
            {str(k): v.pos_err_mean_km for k, v in o.scores.items()},
            "outage_nees": None if o is None else
            {str(k): v.nees_mean for k, v in o.scores.items()},
            "after_pass_km_no_light_time": [p[3] for p in off.passes]}


def _q(v: list[float] | np.ndarray) -> str:
    """Return the median [quartiles] of the finite values of `v`, as text ("-" if none)."""
    a = np.asarray(v, float)
    if not np.isfinite(a).any():
        return "-"
    q25, med, q75 = np.nanpercentile(a, [25, 50, 75])
    return f"{med:.3g} [{q25:.3g}, {q75:.3g}]"


PUBLISHED_KEYS = ("err_median_km", "long_err_median_km", "after_pass_median_km", "nees_in_95",
                  "nees_median", "cpu_s")
"""The `gap_scores.GapScores` fields the study summarises (medians over runs)."""


def _published_table(runs: list[dict[str, Any]]) -> tuple[list[str], dict[str, Any]]:
    """Return the table of what the filter publishes between passes, per gap fill."""
    lines = ["| filter's gap_forecast | median error at gap epochs [km] | gaps > 12 h [km] | "
             "after each pass [km] | position NEES <= chi2(3) 95 % [%] | median position "
             "NEES (chi2(3): 2.37) | CPU of its fits per run [s] |",
             "|---|---|---|---|---|---|---|"]
    out: dict[str, Any] = {}
    for f in runs[0]["published"]:
        vals = {k: np.array([r["published"][f].get(k, np.nan) for r in runs], float)
                for k in PUBLISHED_KEYS}
        out[f] = {k: float(np.nanmedian(v)) if np.isfinite(v).any() else None
                  for k, v in vals.items()}
        cov = 100 * vals["nees_in_95"]
        lines.append(f"| {f} | {_q(vals['err_median_km'])} | {_q(vals['long_err_median_km'])} "
                     f"| {_q(vals['after_pass_median_km'])} | {_q(cov)} | "
                     f"{_q(vals['nees_median'])} | {_q(vals['cpu_s'])} |")
    return lines, out


def _run_ratios(runs: list[dict[str, Any]], a: str, b: str, key: str) -> np.ndarray:
    """Return each run's ``published[a][key] / published[b][key]`` where both are finite."""
    x = np.array([r["published"][a][key] for r in runs], float)
    y = np.array([r["published"][b][key] for r in runs], float)
    ok = np.isfinite(x) & np.isfinite(y) & (y > 0)
    out: np.ndarray = x[ok] / y[ok]
    return out


def targets_49(runs: list[dict[str, Any]], live: GapFill) -> dict[str, Any]:
    """Return the learned forecaster's measures against its references (medians over runs).

    * ``cheap_over_corrected_long``: median of the runs' ``batch_init / fit_residual`` over
      gaps > 12 h (the cheap fit and the same fit corrected, the same restarts);
    * ``corrected_over_cheap_all`` / ``_long``: the ratio of the medians over runs,
      ``fit_residual / batch_init`` at all gap epochs / gaps > 12 h (never worse than 1.05
      on a held-out set), with the worst run's;
    * ``corrected_over_full_long``: ``fit_residual / full_fit`` over gaps > 12 h (ratio of
      medians; None without a full fit), and ``cpu_corrected_over_cheap``, the ratio of the
      medians of the runs' CPU time of their fits;
    * the position NEES of the live default (`live`) at gap epochs: median NEES and the
      share inside chi2(3)'s 95 % bound (medians over runs);
    * ``choices``: the step-aside choices of ``fit_residual``, summed over runs.
    """
    cheap, corr = str(GapFill.BATCH_INIT), str(GapFill.FIT_RESIDUAL)

    def med(key: str, fill: str) -> float:
        v = np.array([r["published"][fill][key] for r in runs], float)
        return float(np.nanmedian(v)) if np.isfinite(v).any() else math.nan

    long = _run_ratios(runs, cheap, corr, "long_err_median_km")
    out: dict[str, Any] = {
        "cheap_over_corrected_long": float(np.median(long)) if long.size else None,
        "corrected_over_cheap_all": med("err_median_km", corr) / med("err_median_km", cheap),
        "corrected_over_cheap_long": (med("long_err_median_km", corr)
                                      / med("long_err_median_km", cheap)),
        "corrected_over_cheap_worst_run": float(np.max(_run_ratios(
            runs, corr, cheap, "err_median_km"))),
        "cpu_corrected_over_cheap": med("cpu_s", corr) / med("cpu_s", cheap),
        "live": str(live), "nees_median": med("nees_median", str(live)),
        "nees_in_95": med("nees_in_95", str(live)),
        "choices": {k: int(sum(r["published"][corr]["choices"].get(k, 0) for r in runs))
                    for k in runs[0]["published"][corr]["choices"]}}
    if FULL_FIT in runs[0]["published"]:
        out["corrected_over_full_long"] = (med("long_err_median_km", corr)
                                           / med("long_err_median_km", FULL_FIT))
        out["cheap_over_full_long"] = (med("long_err_median_km", cheap)
                                       / med("long_err_median_km", FULL_FIT))
        out["cpu_full_over_cheap"] = med("cpu_s", FULL_FIT) / med("cpu_s", cheap)
    return out


FIT_RATIOS = {"all gap epochs": "err_median_km", "gaps > 12 h": "long_err_median_km"}
"""The errors of what the filter publishes whose ratio `fit_ratios` takes."""


def fit_ratios(runs: list[dict[str, Any]], fill: GapFill = GapFill.FIT_RESIDUAL,
               against: GapFill = GapFill.BATCH_FIT) -> dict[str, float | None]:
    """Return how many times smaller `fill`'s gap errors are than `against`'s.

    Per `FIT_RATIOS` error: the median over runs of each run's ratio (`against` / `fill`;
    runs where either is missing, e.g. no gap > 12 h, left out), and the ratio of the two
    medians over runs (as the table shows them); None where no run has both.
    """
    out: dict[str, float | None] = {}
    for label, key in FIT_RATIOS.items():
        a = np.array([r["published"][str(against)][key] for r in runs], float)
        b = np.array([r["published"][str(fill)][key] for r in runs], float)
        ok = np.isfinite(a) & np.isfinite(b) & (b > 0)
        out[f"{label}: median of run ratios"] = float(np.median(a[ok] / b[ok])) if ok.any() \
            else None
        out[f"{label}: ratio of medians"] = (float(np.nanmedian(a) / np.nanmedian(b))
                                             if ok.any() else None)
    return out


def summarise(name: str, runs: list[dict[str, Any]]) -> tuple[str, dict[str, Any]]:
    """Return the Markdown for one scenario and its JSON summary."""
    with_passes = [r for r in runs if r["after_pass_km"]]
    after_med = [float(np.median(r["after_pass_km"])) for r in with_passes]
    after_max = [float(np.max(r["after_pass_km"])) for r in with_passes]
    after_all = np.concatenate([r["after_pass_km"] for r in runs] + [[np.nan]])[:-1]
    no_lt = np.concatenate([r["after_pass_km_no_light_time"] for r in runs] + [[np.nan]])[:-1]
    nees = [r["nees_mean"] for r in runs]
    gaps = np.concatenate([r["gaps_h"] for r in runs]) if runs else np.zeros(0)
    lo, hi = runs[0]["nees_band"]
    truth = runs[0].get("truth", str(TruthModel.SGP4))
    lines = [f"### {name} ({len(runs)} runs, {truth} truth: medians [quartiles] over runs)", "",
             "| arm over the outage (first to last withheld measurement) | mean position error "
             "[km] | mean NEES |",
             "|---|---|---|"]
    scored = [r for r in runs if r["outage_mean_km"] is not None]
    arm_med: dict[str, float] = {}
    for a in ARMS if scored else []:
        v = [r["outage_mean_km"][a] for r in scored]
        n = [r["outage_nees"][a] for r in scored if r["outage_nees"][a] is not None]
        arm_med[a] = float(np.median(v))
        lines.append(f"| {a} | {_q(v)} | {_q(n) if n else '-'} |")
    lines.append(f"\n(over the {len(scored)} runs whose outage withheld measurements; in "
                 f"{len(runs) - len(scored)} the outage's station would have seen nothing, "
                 f"or not across a truth epoch)")
    ratio = [r["outage_mean_km"]["dmd_ekf"] / r["outage_mean_km"]["coast"] for r in scored]
    ratio_j2 = [r["outage_mean_km"]["dmd_ekf"] / r["outage_mean_km"]["j2_coast"]
                for r in scored]
    ratio_fit = [r["outage_mean_km"]["dmd_ekf"] / r["outage_mean_km"]["batch_fit"]
                 for r in scored]
    fc = sum(r["forecasts"] for r in runs)
    in_band = [r["nees_in_band"] for r in runs]
    lines += [
        "",
        f"- after each pass: position error {_q(after_all)} km over {len(after_all)} passes "
        f"(median per run {_q(after_med)}; largest per run {_q(after_max)}; largest of all "
        f"{after_all.max():.3g} km); {100 * np.mean(after_all < 1.0):.1f} % of passes < 1 km",
        f"- same filter without its light-time correction: after each pass {_q(no_lt)} km",
        f"- NEES at every truth epoch after initialisation (gaps included): run mean "
        f"{_q(nees)} (6 expected; per-epoch 95 % band [{lo:.2f}, {hi:.2f}] holds "
        f"{_q(100 * np.asarray(in_band))} % of epochs)",
        f"- gaps between passes: {len(gaps)}, {gaps.min():.2f} to {gaps.max():.2f} h"
        if len(gaps) else "- gaps between passes: none",
        f"- surrogate forecasts issued: {fc} in all runs"
        + (f"; dmd_ekf / coast {_q(ratio)}, dmd_ekf / j2_coast {_q(ratio_j2)}, "
           f"dmd_ekf / batch_fit {_q(ratio_fit)}" if scored else ""),
    ]
    pub_lines, pub_summary = _published_table(runs)
    ratios = fit_ratios(runs)
    lines += ["", *pub_lines, "",
              f"- {GapFill.BATCH_FIT} / {GapFill.FIT_RESIDUAL} (how many times smaller the "
              "error of the fit corrected by the surrogate is): "
              + "; ".join(f"{k} {'-' if v is None else f'{v:.3g}'}" for k, v in ratios.items())]
    t49 = targets_49(runs, sky.SKY_SCENARIOS[name].gap_fill)
    lines += ["", "- the learned correction against its references: " + ", ".join(
        f"{k} {v:.3g}" if isinstance(v, float) else f"{k} {v}" for k, v in t49.items())]
    summary = {"runs": len(runs), "runs_with_outage": len(scored), "published": pub_summary,
               "truth": truth, "targets_49": t49,
               "batch_fit_over_fit_residual": ratios,
               "runs_with_passes": sum(bool(r["after_pass_km"]) for r in runs),
               "after_pass_km_median": float(np.median(after_all)),
               "after_pass_km_max": float(after_all.max()),
               "after_pass_below_1km": float(np.mean(after_all < 1.0)),
               "after_pass_km_median_no_light_time": float(np.median(no_lt)),
               "nees_mean_median": float(np.median(nees)),
               "nees_in_band_median": float(np.median(in_band)),
               "outage_mean_km_median": arm_med, "forecasts": fc}
    return "\n".join(lines), summary


def run_sky_study(names: list[str], seeds: tuple[int, ...], offsets_h: tuple[float, ...],
                  workers: int = 2,
                  progress: Callable[[str], None] | None = None,
                  truth: TruthModel = TruthModel.SGP4, gaps_only: bool = False
                  ) -> tuple[str, dict[str, dict[str, Any]]]:
    """Run the scenarios `names` over `seeds` x `offsets_h`; return (markdown, summaries).

    The runs go to `workers` processes; the summaries are by scenario name; every case's
    object follows `truth`; `gaps_only`: `run_gap_case` (`summarise_gaps`). The result does
    not depend on `workers`.
    """
    todo = [(n, o, s, str(truth)) for n in names for o in offsets_h for s in seeds]
    one, summary = (run_gap_case, summarise_gaps) if gaps_only else (run_case, summarise)
    outs: list[dict[str, Any]] = []
    with ProcessPoolExecutor(max(1, workers)) as pool:
        for (n, _, _, _), r in zip(todo, pool.map(one, todo), strict=True):
            outs.append(r)
            if progress:
                progress(n)
    texts, result = [], {}
    for name in names:
        runs = [r for (n, _, _, _), r in zip(todo, outs, strict=True) if n == name]
        text, result[name] = summary(name, runs)
        texts.append(text)
    return "\n\n".join(texts), result

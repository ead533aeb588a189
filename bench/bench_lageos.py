"""Benchmark: orbit determination on real laser ranging of LAGEOS-2, judged against its targets.

The data (``../shared/realdata/lageos2-2016``, its SOURCE.md): 70 ILRS normal points of
2016-02-11..13 from Mt Stromlo, Yarragadee, Haleakala and Matera, SLRF2014 coordinates, the
ILRS eccentricities, and SGF's CPF prediction of 2016-02-13. They go in as a user's would:
``ssa-fusion import crd`` into a bag (in a temporary directory), read back by
`ros.laser_bag`, estimated by `apps.laser_run` (the core's `laser_od` and the laser filter).
No setting is chosen from these files: the noise of a normal point (5 mm), the forces and
the priors are `core.od.laser_od`'s, each from physics.

Printed, the issue's table:

* post-fit range residual RMS over all 70 points, a range bias per station solved for
  (target <= 0.25 m; Orekit's own test on this file: 0.26 m std);
* the fitted orbit against the CPF over 2016-02-13, 3D RMS (and R, T, N) at its 288 states
  (target <= 0.5 m);
* predicted range residual RMS of the passes 2-12 h after the fit's last point: the fit of
  the points up to 2016-02-13 18:00 (its last: Yarragadee's, 14:06) propagated to the later
  passes of Haleakala and Matera (41 points; those two stations' biases are not in that fit:
  0, their prior) (target <= 1 m); with the RMS of the residuals over their predicted sigma
  (the fit's realistic covariance mapped and R);
* the filter's NIS inside its two-sided 95 % band of chi-square(1) over the 70 points, the
  offline replay of the bag (target >= 90 %);
* one fit of the 3 days, wall time, in a process that has fitted once before (the compiled
  kernels loaded) (target <= 2 s); the first fit's too;
* microseconds per force-model derivative with the STM and k_R's sensitivity, 20 x 20 + Sun +
  Moon + solid tides + SRP, inside a day's integration (CPU time / its 1440 x 12 stage
  calls), beside the catalog's J2 kernel (`propagation.integrate_stm`).

And the baselines a reviewer asks for: the same fit with a J2-only and a J2-J4 (zonal)
geopotential and no other force (state and biases solved), the full model without the solid
tides, the full model with constant RTN accelerations solved; and the filter coasting: the
laser filter run up to 18:00 and predicted to the same passes (its own bias states).

And the learned gap correction on the J2 fit ("J2 + learned correction"): the J2-only fit
of the points up to 18:00 plus the residual surrogate learnt against it
(`core.gaps.fit_residual.correct_fit`, the gap forecaster's settings, Hill's equations with
constant and once-per-revolution RTN accelerations in the J2 trajectory's frame), its
anchors the object's states estimated from the same points: the full model's fit up to
18:00 sampled every 300 s (the filter's publication period) over the fit span, with its
realistic covariance (no CPF, nothing after the cut-off); predicted to the same 41 points
with the J2 fit's range model and biases. What it learns is the full model's orbit less the
J2 one, so it is judged against both: the J2 fit it corrects and the full model.

Usage::

    python bench/bench_lageos.py

Last line: a JSON object.
"""

from __future__ import annotations

import json
import math
import os
import sys
import tempfile
import time
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # run from a source checkout

from ssa_fusion.apps import laser_run
from ssa_fusion.apps.cli import main as cli
from ssa_fusion.apps.replay import replay_offline
from ssa_fusion.core.base.metrics import chi2_bounds
from ssa_fusion.core.base.types import Measurement, UpdateSource
from ssa_fusion.core.earth.frames import rtn_axes
from ssa_fusion.core.earth.timescales import DAY_S, iso, parse_utc
from ssa_fusion.core.gaps.fit_residual import correct_fit
from ssa_fusion.core.measure.laser_model import LaserModels
from ssa_fusion.core.motion import high_fidelity as hf
from ssa_fusion.core.motion import propagation
from ssa_fusion.core.motion.force_model import PARAMETERS
from ssa_fusion.core.motion.force_spec import ForceSpec
from ssa_fusion.core.od import batch_ls, laser_od
from ssa_fusion.formats.icgem import egm96
from ssa_fusion.ros import bagio
from ssa_fusion.ros.laser_bag import LaserBag, laser_bag

DATA = Path(__file__).resolve().parents[2] / "shared" / "realdata" / "lageos2-2016"
CUTOFF = "2016-02-13T18:00:00"
PREDICT_H = (2.0, 12.0)
TARGETS = {"residual_rms_m": 0.25, "cpf_3d_rms_m": 0.5, "predicted_rms_m": 1.0,
           "nis_inside": 0.90, "fit_wall_s": 2.0}
M = 1000.0
FULL = "full (20x20, Sun, Moon, tides, SRP; Cr)"
J2 = "J2 only"
LEARNED = "J2 + learned correction"
ANCHOR_STEP_S = 300.0
"""The learned correction's anchors are this far apart (s): the laser filter's publication
period between passes (`laser_run.GAPS`)."""


def _data_dir() -> Path:
    shared = [Path(os.environ["SSA_FUSION_SHARED"])] if "SSA_FUSION_SHARED" in os.environ else []
    for d in (*(p / "realdata" / "lageos2-2016" for p in shared), DATA,
              Path(__file__).resolve().parents[3] / "shared" / "realdata" / "lageos2-2016"):
        if d.is_dir():
            return d
    raise SystemExit(f"no {DATA}: the LAGEOS-2 data are not beside the repository")


def _import(tmp: Path) -> LaserBag:
    """``ssa-fusion import crd`` the files into a bag; return it read back."""
    d = _data_dir()
    bag = tmp / "lageos2"
    code = cli(["import", "crd", str(d / "lageos2_20160211-13.npt"), "--stations",
                str(d / "SLRF2014_POS+VEL_2030.0_200428.snx"), "--eccentricities",
                str(d / "ecc_une.snx"), "--reference", str(d / "lageos2_cpf_160213_5441.sgf"),
                "--bag", str(bag)])
    assert code == 0
    return laser_bag(list(bagio.read_records(bag)))


def _rms(a: np.ndarray) -> float:
    return float(np.sqrt(np.mean(np.square(a))))


def _against_reference(bag: LaserBag, fit: batch_ls.BatchFit) -> tuple[float, list[float]]:
    """Return the fitted orbit minus the reference at its states: 3D RMS and R, T, N RMS (m)."""
    x, _ = fit.predict(bag.reference_t, realistic=False)
    d = np.einsum("kij,kj->ki", rtn_axes(bag.reference_x), x[:, :3] - bag.reference_x[:, :3])
    d *= M
    return float(np.sqrt(np.mean(np.sum(d**2, axis=1)))), [_rms(d[:, k]) for k in range(3)]


def _later(bag: LaserBag, fit: batch_ls.BatchFit) -> list[Measurement]:
    """Return the normal points of the passes 2-12 h after the fit's last point."""
    last = max(fit.t_meas)
    return [m for m in bag.measurements
            if last + PREDICT_H[0] * 3600 <= m.t <= last + PREDICT_H[1] * 3600]


def _predicted(bag: LaserBag, fit: batch_ls.BatchFit,
               models: LaserModels) -> tuple[float, float, int]:
    """Return the predicted range residual RMS (m), its RMS over the predicted sigma, count."""
    ms = _later(bag, fit)
    return _range_check(ms, *fit.predict([m.t for m in ms]), fit, models)


def _range_check(ms: list[Measurement], x: np.ndarray, P: np.ndarray,
                 fit: batch_ls.BatchFit, models: LaserModels) -> tuple[float, float, int]:
    """Return the range residual RMS (m) of states x, P (GCRF) at the points ``ms`` (with
    ``fit``'s station biases, 0 for a station it has none of), its RMS over sigma, count."""
    t = np.array([m.t for m in ms])
    pts = models.points(t, [m.frame_id for m in ms])
    bias = np.zeros(len(models.network.ids))
    for name, v in fit.measurement_params.items():
        bias[models.network.ids.index(name.removeprefix("bias_"))] = v
    got = pts.predict(x, bias)
    res = np.array([m.z[0] for m in ms]) - got.range_km
    var = np.einsum("ki,kij,kj->k", got.H, P, got.H) + np.array([m.R[0, 0] for m in ms])
    return _rms(res) * M, _rms(res / np.sqrt(var)), len(ms)


def _learned(bag: LaserBag, j2: batch_ls.BatchFit, full: batch_ls.BatchFit) -> dict[str, Any]:
    """The J2 fit up to the cut-off corrected by the learned residual (`correct_fit`).

    Its anchors: the full model's fit of the same points (up to the cut-off), sampled every
    `ANCHOR_STEP_S` over the fit span, with its realistic covariance; then
    the J2 fit's own state at its epoch. Scored on the same points as the fits: in sample
    (the points up to the cut-off) and the passes 2-12 h later.
    """
    models = _models_of(bag)
    t = np.arange(j2.t - ANCHOR_STEP_S, min(j2.t_meas), -ANCHOR_STEP_S)[::-1]
    r = correct_fit(j2, t, *full.predict(t))
    assert r is not None, "the learned correction refused its fit"
    before = [m for m in bag.measurements if m.t <= j2.t]
    later = _later(bag, j2)
    res, _, n_fit = _range_check(before, *r.predict([m.t for m in before]), j2, models)
    pred, norm, n = _range_check(later, *r.predict([m.t for m in later]), j2, models)
    return {"residual_rms_m": res, "residual_points": n_fit, "predicted_rms_m": pred,
            "predicted_over_sigma": norm, "predicted_points": n, "anchors": r.n_anchors,
            "max_residual_m": r.max_residual_km * M,
            "j2_biases_m": {k: v * M for k, v in j2.measurement_params.items()}}


def _models_of(bag: LaserBag) -> LaserModels:
    """The laser network's range model of the bag (stations, meteo)."""
    c = laser_run.estimator(bag)
    assert c.laser is not None
    return LaserModels(c.laser, bag.meteo)


def _fit(bag: LaserBag, force: ForceSpec, until: float | None = None,
         accelerations: bool = False) -> batch_ls.BatchFit:
    """The laser fit with ``force`` (k_R with SRP), from the reference's nearest state."""
    ms = [m for m in bag.measurements if until is None or m.t <= until]
    guess = laser_od.first_guess(bag.reference_t, bag.reference_x, ms[-1].t)
    return laser_od.fit(ms, _models_of(bag), guess, force, accelerations=accelerations)


def _judge(bag: LaserBag, force: ForceSpec, accelerations: bool,
           part: batch_ls.BatchFit) -> dict[str, Any]:
    """The three numbers of one model: residuals, the CPF, the prediction (of ``part``,
    its fit up to the cut-off)."""
    full = _fit(bag, force, accelerations=accelerations)
    d3, rtn = _against_reference(bag, full)
    pred, norm, n = _predicted(bag, part, _models_of(bag))
    res = np.array([r[0] for r in full.residuals]) * M
    # a fit that stopped on a step it could not take keeps its last linearisation's RMS
    sigma_m = math.sqrt(bag.measurements[0].R[0, 0]) * M
    rms = _rms(res) if np.isfinite(res).all() else full.rms * sigma_m
    return {"status": str(full.status), "reason": full.reason,
            "residual_rms_m": rms, "cpf_3d_rms_m": d3,
            "cpf_rtn_rms_m": rtn, "predicted_rms_m": pred, "predicted_over_sigma": norm,
            "predicted_points": n, "edited": int(np.sum(~full.accepted)),
            "biases_m": {k: v * M for k, v in full.measurement_params.items()},
            "bias_sigma_m": {k: full.sigma(k, realistic=True) * M
                             for k in full.measurement_params},
            "cr": full.params["srp_scale"] * laser_od.LAGEOS_CR if force.srp else math.nan}


def _filter(bag: LaserBag, stream: list[bagio.BagMessage]) -> dict[str, Any]:
    """The laser filter over the bag (NIS), and coasting from the cut-off to the passes."""
    c = laser_run.estimator(bag)
    result = replay_offline(stream, c, laser_run.GAPS, False, laser_run.tracker(bag, c))
    nis = np.array([e.nis for _, e in result.estimates if e.update_source == UpdateSource.SENSOR])
    lo, hi = chi2_bounds(1)
    cut = parse_utc(CUTOFF)
    tracker = laser_run.tracker(bag, c)
    assert tracker.model is not None and isinstance(tracker.model, LaserModels)
    tracker.model.add_meteo(bag.meteo)
    before = [m for m in bag.measurements if m.t <= cut]
    for m in before:
        tracker.process(m)
    last = before[-1].t
    later = [m for m in bag.measurements
             if last + PREDICT_H[0] * 3600 <= m.t <= last + PREDICT_H[1] * 3600]
    res, norm = [], []
    for m in later:
        e = tracker.predicted(m.t)
        assert e is not None
        model = tracker.model.get(m.kind, m.frame_id)
        assert model is not None
        z, H = model.h_and_H(e.x, m.t)
        res.append(m.z[0] - z[0])
        norm.append(res[-1] / math.sqrt(float((H @ e.P @ H.T)[0, 0]) + m.R[0, 0]))
    return {"fused": int(nis.size), "nis_inside": float(np.mean((nis >= lo) & (nis <= hi))),
            "nis_below": int(np.sum(nis < lo)), "nis_above": int(np.sum(nis > hi)),
            "nis_mean": float(nis.mean()), "coast_rms_m": _rms(np.array(res)) * M,
            "coast_over_sigma": _rms(np.array(norm)), "coast_points": len(res)}


def _fit_time(bag: LaserBag) -> tuple[float, float]:
    """Wall time of the first fit of the 3 days in this process, and of the next one."""
    times = []
    for _ in range(2):
        tic = time.perf_counter()
        fit = laser_run.fit(bag)
        times.append(time.perf_counter() - tic)
        assert fit.converged
    return times[0], times[1]


def _kernel_us() -> tuple[float, float]:
    """Microseconds per derivative with the STM: the full model, the J2 kernel (CPU time)."""
    t0 = parse_utc("2016-02-13T00:00:00")
    x0 = np.array([-6020.0, 8950.0, 5400.0, -3.9, -2.6, 0.2])  # LAGEOS-2-like
    spec = laser_od.laser_force(egm96())
    ctx = hf.setup(spec, t0, 0.0, DAY_S)
    calls = math.ceil(DAY_S / 60.0) * 12
    hf.propagate(ctx, x0, t0, [t0 + 600.0], which=[4])
    best = best_j2 = math.inf
    for _ in range(3):
        tic = time.process_time()
        hf.propagate(ctx, x0, t0, [t0 + DAY_S], which=[PARAMETERS.index("srp_scale")],
                     max_step_s=60.0)
        best = min(best, time.process_time() - tic)
        tic = time.process_time()
        propagation.integrate_stm("j2", x0[None], [DAY_S], 60.0)
        best_j2 = min(best_j2, time.process_time() - tic)
    return best / calls * 1e6, best_j2 / calls * 1e6


def _models() -> dict[str, tuple[ForceSpec, bool]]:
    """The models judged: (forces, RTN accelerations solved for) by name."""
    g = egm96()
    full = laser_od.laser_force(g)
    return {FULL: (full, False),
            J2: (ForceSpec(g, 2, 0, sun=False, moon=False), False),
            "J2-J4 (zonal)": (ForceSpec(g, 4, 0, sun=False, moon=False), False),
            "full without solid tides": (replace(full, solid_tides=False), False),
            "full + RTN accelerations": (full, True)}


def _table(main: dict, filt: dict, walls: tuple[float, float],
           us: tuple[float, float]) -> list[tuple[str, str, str, str, bool | None]]:
    t = TARGETS
    return [
        ("post-fit range residual RMS, all 70 points, biases solved", f"<= {t['residual_rms_m']} m",
         f"{main['residual_rms_m']:.3f} m", "Orekit 0.26 m (std)",
         main["residual_rms_m"] <= t["residual_rms_m"]),
        ("orbit vs the CPF over 2016-02-13, 3D RMS", f"<= {t['cpf_3d_rms_m']} m",
         f"{main['cpf_3d_rms_m']:.3f} m (R {main['cpf_rtn_rms_m'][0]:.3f}, T "
         f"{main['cpf_rtn_rms_m'][1]:.3f}, N {main['cpf_rtn_rms_m'][2]:.3f})",
         "Orekit 0.62 m vs another centre", main["cpf_3d_rms_m"] <= t["cpf_3d_rms_m"]),
        (f"predicted range residual RMS, passes 2-12 h after the fit's last point "
         f"({main['predicted_points']} points)", f"<= {t['predicted_rms_m']} m",
         f"{main['predicted_rms_m']:.3f} m ({main['predicted_over_sigma']:.2f} sigma RMS)", "-",
         main["predicted_rms_m"] <= t["predicted_rms_m"]),
        ("filter (EKF, same model) NIS inside its 95 % band", f">= {100 * t['nis_inside']:.0f} %",
         f"{100 * filt['nis_inside']:.1f} % ({filt['nis_below']} below, {filt['nis_above']} "
         f"above, mean {filt['nis_mean']:.2f})", "-", filt["nis_inside"] >= t["nis_inside"]),
        ("one fit of the 3 days, wall time", f"<= {t['fit_wall_s']} s",
         f"{walls[1]:.2f} s (first in the process {walls[0]:.2f} s)", "-",
         walls[1] <= t["fit_wall_s"]),
        ("force-model derivative with STM, 20x20 + Sun/Moon + tides + SRP", "measured",
         f"{us[0]:.1f} us per call (J2 kernel {us[1]:.2f} us)", "-", None),
    ]


def _verdict(learned: float, j2: float, full: float) -> str:
    """The learned correction's predicted RMS (m) against the J2 fit's and the full model's."""
    return (f"{LEARNED}: predicted RMS {learned:.3f} m, "
            f"{'beats' if learned < j2 else 'does NOT beat'} the J2 fit alone ({j2:.3f} m: "
            f"{j2 / learned:.1f} times smaller); the full model's {full:.3f} m is "
            f"{learned / full:.0f} times smaller still")


def main() -> None:
    """Run the benchmark; print the tables; last line JSON."""
    with tempfile.TemporaryDirectory() as tmp:
        bag = _import(Path(tmp))
        stream = list(bagio.read_records(Path(tmp) / "lageos2"))
    print(f"LAGEOS-2: {len(bag.measurements)} normal points "
          f"{iso(bag.measurements[0].t)} .. {iso(bag.measurements[-1].t)} from "
          f"{', '.join(bag.network.ids)}; CPF {len(bag.reference_t)} states; fit cut-off for "
          f"the predictions {CUTOFF}")
    walls = _fit_time(bag)
    cut = parse_utc(CUTOFF)
    parts = {name: _fit(bag, force, cut, acc) for name, (force, acc) in _models().items()}
    judged = {name: _judge(bag, force, acc, parts[name])
              for name, (force, acc) in _models().items()}
    main_ = judged[FULL]
    learned = _learned(bag, parts[J2], parts[FULL])
    filt = _filter(bag, stream)
    us = _kernel_us()
    print("\n| measure | target | measured | anchor | met |\n|---|---|---|---|---|")
    for row in _table(main_, filt, walls, us):
        met = "-" if row[4] is None else ("yes" if row[4] else "NO")
        print(f"| {row[0]} | {row[1]} | {row[2]} | {row[3]} | {met} |")
    print("\nbiases (m, sigma): " + ", ".join(
        f"{k.removeprefix('bias_')} {v:+.3f} +- {main_['bias_sigma_m'][k]:.3f}"
        for k, v in main_["biases_m"].items()) + f"; Cr {main_['cr']:.3f}")
    print("\n| model | residual RMS (70) | vs CPF 3D RMS | predicted RMS | status |\n"
          "|---|---|---|---|---|")
    for name, j in judged.items():
        print(f"| {name} | {j['residual_rms_m']:.3f} m | {j['cpf_3d_rms_m']:.3f} m | "
              f"{j['predicted_rms_m']:.3f} m | {j['status']}, {j['edited']} edited |")
        if j["status"] != "converged":
            print(f"|   ({j['reason']}) | | | | |")
    print(f"| {LEARNED} (the J2 fit to {CUTOFF} plus the residual learnt against the full "
          f"model's fit of the same points, {learned['anchors']} anchors) | "
          f"{learned['residual_rms_m']:.3f} m ({learned['residual_points']} up to the cut-off, "
          f"the J2 fit's biases: " + ", ".join(f"{k.removeprefix('bias_')} {v:+.1f} m" for k, v
                                               in learned["j2_biases_m"].items()) + ") "
          f"| - | {learned['predicted_rms_m']:.3f} m ({learned['predicted_over_sigma']:.2f} "
          f"sigma RMS) | largest residual learnt {learned['max_residual_m']:.1f} m |")
    print(f"| the laser filter coasting from {CUTOFF} | - | - | {filt['coast_rms_m']:.3f} m "
          f"({filt['coast_over_sigma']:.2f} sigma RMS) | {filt['fused']} fused |")
    print("\n" + _verdict(learned["predicted_rms_m"], judged[J2]["predicted_rms_m"],
                           main_["predicted_rms_m"]))
    print(json.dumps({"full": main_, "baselines": {k: v for k, v in judged.items()
                                                    if v is not main_},
                      LEARNED: learned,
                      "filter": filt, "fit_wall_s": walls[1], "fit_wall_first_s": walls[0],
                      "us_per_call": us[0], "j2_us_per_call": us[1]}))


if __name__ == "__main__":
    main()

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

Usage::

    python bench/bench_lageos.py

Last line: a JSON object.
"""

from __future__ import annotations

import json
import math
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
from ssa_fusion.core.base.types import UpdateSource
from ssa_fusion.core.earth.frames import rtn_axes
from ssa_fusion.core.earth.timescales import DAY_S, iso, parse_utc
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


def _data_dir() -> Path:
    for d in (DATA, Path(__file__).resolve().parents[3] / "shared" / "realdata"
              / "lageos2-2016"):
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


def _predicted(bag: LaserBag, fit: batch_ls.BatchFit,
               models: LaserModels) -> tuple[float, float, int]:
    """Return the predicted range residual RMS (m), its RMS over the predicted sigma, count."""
    last = max(fit.t_meas)
    ms = [m for m in bag.measurements
          if last + PREDICT_H[0] * 3600 <= m.t <= last + PREDICT_H[1] * 3600]
    t = np.array([m.t for m in ms])
    x, P = fit.predict(t)
    pts = models.points(t, [m.frame_id for m in ms])
    bias = np.zeros(len(models.network.ids))
    for name, v in fit.measurement_params.items():
        bias[models.network.ids.index(name.removeprefix("bias_"))] = v
    got = pts.predict(x, bias)
    res = np.array([m.z[0] for m in ms]) - got.range_km
    var = np.einsum("ki,kij,kj->k", got.H, P, got.H) + np.array([m.R[0, 0] for m in ms])
    return _rms(res) * M, _rms(res / np.sqrt(var)), len(ms)


def _fit(bag: LaserBag, force: ForceSpec, until: float | None = None,
         accelerations: bool = False) -> batch_ls.BatchFit:
    """The laser fit with ``force`` (k_R with SRP), from the reference's nearest state."""
    ms = [m for m in bag.measurements if until is None or m.t <= until]
    c = laser_run.estimator(bag)
    assert c.laser is not None
    models = LaserModels(c.laser, bag.meteo)
    guess = laser_od.first_guess(bag.reference_t, bag.reference_x, ms[-1].t)
    return laser_od.fit(ms, models, guess, force, accelerations=accelerations)


def _judge(bag: LaserBag, force: ForceSpec, accelerations: bool) -> dict[str, Any]:
    """The three numbers of one model: residuals, the CPF, the prediction."""
    c = laser_run.estimator(bag)
    assert c.laser is not None
    models = LaserModels(c.laser, bag.meteo)
    full = _fit(bag, force, accelerations=accelerations)
    part = _fit(bag, force, parse_utc(CUTOFF), accelerations)
    d3, rtn = _against_reference(bag, full)
    pred, norm, n = _predicted(bag, part, models)
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
            "J2 only": (ForceSpec(g, 2, 0, sun=False, moon=False), False),
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
    judged = {name: _judge(bag, force, acc) for name, (force, acc) in _models().items()}
    main_ = judged[FULL]
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
    print(f"| the laser filter coasting from {CUTOFF} | - | - | {filt['coast_rms_m']:.3f} m "
          f"({filt['coast_over_sigma']:.2f} sigma RMS) | {filt['fused']} fused |")
    print(json.dumps({"full": main_, "baselines": {k: v for k, v in judged.items()
                                                    if v is not main_},
                      "filter": filt, "fit_wall_s": walls[1], "fit_wall_first_s": walls[0],
                      "us_per_call": us[0], "j2_us_per_call": us[1]}))


if __name__ == "__main__":
    main()

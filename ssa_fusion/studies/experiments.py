"""The arms of `ssa_fusion.evaluation.arms` on a simulated scenario, plus the paper's two studies.

Pure functions, no I/O.

The DMD-EKF runs exactly as the live graph drives the two nodes: the real measurements go
to a `Surrogate` (Hankel-DMD) and to a `Tracker` (IOD + EKF); during the gap the
surrogate's forecasts for the missed epochs are fused instead (`surrogate.add` /
`surrogate.due`, `tracker.process`), so offline equals live. The other arms and the scores
are `arms.evaluate_gap`'s, the same as for a recorded bag.

The experiments' EKF has no innovation gate (the live filter's glitch gate is off), so a
poor placeholder (Van der Pol) is scored on what it does, not on skipped updates.

Nothing here reads the true trajectory except to score the arms.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from ssa_fusion.core.base.metrics import chi2_bounds, nees
from ssa_fusion.core.base.types import Measurement, StateEstimate
from ssa_fusion.core.earth.frames import Frame, wrap_pi
from ssa_fusion.core.filter.tracker import Tracker
from ssa_fusion.core.gaps import estimator as config
from ssa_fusion.core.gaps.estimator import EstimatorConfig
from ssa_fusion.core.gaps.surrogate import Surrogate
from ssa_fusion.evaluation.arms import (
    ArmName,
    ArmScore,
    ArmTrajectory,
    GapEvaluation,
    evaluate_gap,
)
from ssa_fusion.evaluation.montecarlo import N_PARTICLES
from ssa_fusion.sim.scenarios import Scenario, measurement_model
from ssa_fusion.sim.simulate import Simulation, simulate

__all__ = ["N_PARTICLES", "DmdEkfRun", "evaluate_sim", "run_dmd_ekf", "run_scenario",
           "scenario_estimator", "scenario_surrogate", "scenario_tracker", "vdp_sweep"]


def scenario_estimator(s: Scenario) -> EstimatorConfig:
    """Return the scenario's estimator without the innovation gate (see the module docstring)."""
    c = s.estimator()
    return c.with_(filter=c.filter.with_(gate=None))


def scenario_tracker(s: Scenario) -> Tracker:
    """Return the scenario's EKF, built as the live filter node builds it (`scenario_estimator`)."""
    return config.make_tracker(scenario_estimator(s), object_id=s.name)


def scenario_surrogate(s: Scenario, **overrides: object) -> Surrogate:
    """Return the scenario's surrogate, built as the live surrogate node builds it.

    Trained on the tracking window, one fit at the start of the gap, forecasts for every
    missed epoch. `overrides`: `SurrogateConfig` fields for studies.
    """
    c = scenario_estimator(s)
    # arg-type: `overrides` are fields of different types by name, which mypy cannot match
    # to `object`; replace itself rejects a name that is no field
    surrogate = replace(c.surrogate, **overrides)  # type: ignore[arg-type]
    return config.make_surrogate(c.with_(surrogate=surrogate))


def measurements(s: Scenario, sim: Simulation) -> tuple[list[Measurement], list[Measurement]]:
    """Return the simulation's real measurements (outside the gap) and the gap's (withheld)."""
    ms = [Measurement(t=float(t), z=z.copy(), R=sim.R, kind=s.kind, object_id=s.name,
                      frame_id=s.station or Frame.GCRF) for t, z in zip(sim.t, sim.z, strict=True)]
    real = [m for m, g in zip(ms, sim.in_gap, strict=True) if not g]
    withheld = [m for m, g in zip(ms, sim.in_gap, strict=True) if g]
    return real, withheld


@dataclass
class DmdEkfRun:
    """The filter's estimates of a DMD-EKF run and the forecasts the surrogate issued.

    The estimates are the last per epoch, keyed by epoch, s.
    """

    estimates: dict[float, StateEstimate]
    forecasts: list[Measurement]


def run_dmd_ekf(s: Scenario, sim: Simulation, **surrogate_overrides: object) -> DmdEkfRun:
    """Run surrogate + filter over the simulation, driven as the live graph drives the nodes.

    `surrogate_overrides`: `SurrogateConfig` fields for studies (none in the reproduction).
    """
    tr = scenario_tracker(s)
    su = scenario_surrogate(s, **surrogate_overrides)
    run = DmdEkfRun({}, [])
    grace = su.config.grace

    def feed(m: Measurement) -> None:
        out = tr.process(m)
        for e in (out.estimate, *out.fused_again):
            if e is not None:
                run.estimates[e.t] = e

    real, _ = measurements(s, sim)
    by_t = {m.t: m for m in real}
    for t, in_gap in zip(sim.t, sim.in_gap, strict=True):
        # in the gap, the live graph's surrogate timer: forecasts due once an epoch is
        # missed; otherwise the forecasts still owed when a real measurement arrives
        fs = (su.due(float(t) + (grace + 0.1) * s.cadence_s) if in_gap
              else su.add(by_t[float(t)]))
        run.forecasts.extend(fs)
        for f in fs:
            feed(f)
        if not in_gap:
            feed(by_t[float(t)])
    return run


def evaluate_sim(s: Scenario, sim: Simulation, seed: int,
                 only: tuple[ArmName, ...] = tuple(ArmName),
                 **surrogate_overrides: object) -> tuple[GapEvaluation, DmdEkfRun]:
    """Score the arms (all, or `only` those) over the simulation's gap; return them and the run.

    The arms are `arms.evaluate_gap`'s; the run is the DMD-EKF's (`run_dmd_ekf`).
    """
    real, withheld = measurements(s, sim)
    run = run_dmd_ekf(s, sim, **surrogate_overrides)
    gap = sim.gap_index
    ev = evaluate_gap(scenario_estimator(s), run.estimates, real, withheld, sim.t[gap],
                      sim.x[gap], seed, only)
    return ev, run


def trajectory(estimates: dict[float, StateEstimate]) -> ArmTrajectory:
    """Return all of a run's estimates as one trajectory, in epoch order (for plots)."""
    es = [estimates[t] for t in sorted(estimates)]
    return ArmTrajectory(np.array([e.t for e in es]), np.array([e.x for e in es]),
                         np.array([e.P for e in es]),
                         np.array([e.update_source for e in es], dtype=int))


def forecast_errors(s: Scenario, sim: Simulation,
                    forecasts: list[Measurement]) -> dict[str, np.ndarray]:
    """Return the forecasts' errors against the true measurements, and their covariances.

    Forecast minus true (noise-free) measurement ("err"), and the forecast's covariance
    ("cov"), by horizon ("horizon"), for the forecasts issued during the gap.
    """
    model = measurement_model(s)
    h, err, C = [], [], []
    for f in forecasts:
        i = round((f.t - s.t0) / s.cadence_s)
        zt = sim.z_true[i]
        e = np.asarray(f.z, float) - zt
        for c, is_angle in enumerate(model.angle_mask):
            if is_angle:
                e[c] = wrap_pi(e[c])
        h.append(f.horizon)
        err.append(e)
        C.append(np.asarray(f.R, float))
    return {"horizon": np.array(h), "err": np.array(err), "cov": np.array(C)}


def _arm_result(sc: ArmScore, noisy: bool) -> dict[str, float]:
    """Return an arm's score as results (its mean NEES only for a noisy scenario)."""
    r = {"epsilon": sc.epsilon, "pos_err_mean": sc.pos_err_mean_km,
         "pos_err_final": sc.pos_err_final_km}
    if noisy and sc.nees_mean is not None:
        r["nees_mean"] = sc.nees_mean
    return r


def run_scenario(s: Scenario, seed: int, nees_runs: int = 1) -> dict[str, Any]:
    """Run every arm on `s`: return a dict of results, and of arrays for plots under `_` keys.

    For noisy scenarios with nees_runs > 1 the DMD-EKF's NEES is averaged over `nees_runs`
    independent noise seeds (seed, seed+1, ...), the first of which is the one scored and
    plotted. Position errors are in the state's units (km for orbits).
    """
    sim = simulate(s, seed)
    ev, run = evaluate_sim(s, sim, seed)
    noisy = bool(np.any(sim.sigma > 0))
    result: dict[str, Any] = {
        "arms": {str(k): _arm_result(sc, noisy) for k, sc in ev.scores.items()}, "noisy": noisy}
    # how much of the DMD-EKF is forecasts (the rest: the filter's predictions)
    result["arms"]["dmd_ekf"]["forecast_fraction"] = ev.coverage
    if noisy:
        runs = [ev.scores[ArmName.DMD_EKF].nees]
        hyp_runs = [ev.scores[ArmName.HYPOTHETICAL_EKF].nees]
        for j in range(1, nees_runs):
            ev_j, _ = evaluate_sim(s, simulate(s, seed + j), seed + j,
                                   only=(ArmName.DMD_EKF, ArmName.HYPOTHETICAL_EKF))
            runs.append(ev_j.scores[ArmName.DMD_EKF].nees)
            hyp_runs.append(ev_j.scores[ArmName.HYPOTHETICAL_EKF].nees)
        dmd_nees = [r for r in runs if r is not None]
        hyp_nees = [r for r in hyp_runs if r is not None]
        if len(dmd_nees) == len(runs) and len(hyp_nees) == len(hyp_runs):  # all invertible
            avg = np.mean(dmd_nees, axis=0)  # per-epoch NEES averaged over the runs
            lo, hi = chi2_bounds(s.n, len(runs))
            result["nees"] = {
                "runs": len(runs), "dof": s.n, "band95": [lo, hi],
                "dmd_ekf_mean": float(np.mean(avg)),
                "dmd_ekf_fraction_in_band": float(np.mean((avg >= lo) & (avg <= hi))),
                "hypothetical_ekf_mean": float(np.mean(np.mean(hyp_nees, axis=0))),
            }
            result["arms"]["dmd_ekf"]["nees_mean"] = result["nees"]["dmd_ekf_mean"]
            result["arms"]["hypothetical_ekf"]["nees_mean"] = \
                result["nees"]["hypothetical_ekf_mean"]
    fe = forecast_errors(s, sim, run.forecasts)
    if len(fe["err"]):
        result["forecast"] = {
            "count": len(fe["err"]),
            "rms_error_last": float(np.sqrt(np.mean(fe["err"][-1] ** 2))),
            "nees_mean": float(np.mean(nees(fe["err"], fe["cov"]))) if noisy else None,
        }
    result["_sim"] = sim
    result["_eval"] = ev
    result["_dmd_trajectory"] = trajectory(run.estimates)
    result["_forecast"] = fe
    return result


# ----------------------------------------------------------------------------------------
def vdp_sweep(s: Scenario, seed: int, mus: np.ndarray) -> dict[str, list[float]]:
    """Return epsilon of each arm against the placeholder's mu_p.

    The paper's figure "VDP with different mu".
    """
    sim = simulate(s, seed)
    out: dict[str, list[float]] = {"mu_p": [], "placeholder": [], "dmd_ekf": [],
                                   "hypothetical_ekf": []}
    for mu in mus:
        sm = s.with_(placeholder_params={**s.placeholder_params, "mu": float(mu)})
        ev, _ = evaluate_sim(sm, sim, seed, only=(ArmName.PLACEHOLDER, ArmName.DMD_EKF,
                                                  ArmName.HYPOTHETICAL_EKF))
        out["mu_p"].append(round(float(mu), 10))
        for arm in ("placeholder", "dmd_ekf", "hypothetical_ekf"):
            out[arm].append(ev.scores[ArmName(arm)].epsilon)
    return out

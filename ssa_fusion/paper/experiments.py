"""The paper's three arms on one scenario, plus its two studies (pure functions, no I/O).

Arms (paper section 3), all scored over the gap (the sensor outage) with the paper's
normalised error epsilon (`metrics.epsilon`):

* ``placeholder`` -- the placeholder model alone: 200 particles drawn from the tracker's
  initial estimate (IOD + P0 floor) and propagated with the placeholder, never corrected;
  the ensemble mean is the estimate, the ensemble covariance its covariance.
* ``dmd_ekf`` -- the real measurements before the gap go to a `Surrogate` (Hankel-DMD) and to
  a `Tracker` (IOD + EKF on the placeholder); during the gap the surrogate's forecasts for the
  missed epochs are fused instead. It is driven exactly as the live graph drives the two
  nodes (`surrogate.add` / `surrogate.due`, `tracker.process`), so offline equals live.
* ``hypothetical_ekf`` -- the same `Tracker` given the real measurements during the gap.

Extra baseline (not in the paper): ``ekf_coast`` -- the filter's own prediction through the
gap from its last real update (what the filter does with no surrogate at all).

Nothing here reads the true trajectory except to score the arms.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ssa_fusion.core.ekf import process_noise
from ssa_fusion.core.frames import wrap_pi
from ssa_fusion.core.metrics import chi2_bounds, epsilon, nees
from ssa_fusion.core.surrogate import Surrogate
from ssa_fusion.core.tracker import Tracker
from ssa_fusion.core.types import Measurement, StateEstimate, UpdateSource
from ssa_fusion.paper import pipeline
from ssa_fusion.paper.montecarlo import N_PARTICLES as MC_PARTICLES
from ssa_fusion.paper.montecarlo import placeholder_ensemble
from ssa_fusion.paper.scenarios import Scenario, measurement_model, placeholder
from ssa_fusion.paper.simulate import Simulation, simulate

N_PARTICLES = MC_PARTICLES


@dataclass
class Arm:
    """Estimates of one arm at the simulation epochs `idx` (indices into `Simulation.t`).

    x : (k, n) estimates; P : (k, n, n) covariances or None; source : (k,) update source
    (0 none, 1 sensor, 2 forecast) where it applies."""

    idx: np.ndarray
    x: np.ndarray
    P: np.ndarray | None = None
    source: np.ndarray | None = None
    extra: dict = field(default_factory=dict)


def make_tracker(s: Scenario) -> Tracker:
    """The scenario's EKF, built as the live filter node builds it, except that the paper's
    EKF has no innovation gate: the live filter's glitch gate is off in the experiments, so
    a poor placeholder (Van der Pol) is scored on what it does, not on skipped updates."""
    return pipeline.make_tracker(s, object_id=s.name, iod_samples=s.iod_samples, gate=None)


def make_surrogate(s: Scenario, **overrides) -> Surrogate:
    """The scenario's surrogate, built as the live surrogate node builds it: trained on the
    tracking window, one fit at the start of the gap, forecasts for every missed epoch.
    `overrides`: `SurrogateConfig` fields for studies."""
    return pipeline.make_surrogate(s, **overrides)


def _measurement(s: Scenario, sim: Simulation, i: int) -> Measurement:
    return Measurement(t=float(sim.t[i]), z=sim.z[i].copy(), R=sim.R, kind=s.kind,
                       object_id=s.name, frame_id=s.station or "eci")


def _index(s: Scenario, t: float) -> int:
    return round((t - s.t0) / s.cadence_s)


def _collect(est: dict[int, object], n: int) -> Arm:
    idx = np.array(sorted(est), dtype=int)
    x = np.array([est[i].x for i in idx]).reshape(len(idx), n)
    P = np.array([est[i].P for i in idx]).reshape(len(idx), n, n)
    src = np.array([est[i].update_source for i in idx], dtype=int)
    return Arm(idx, x, P, src)


def run_hypothetical(s: Scenario, sim: Simulation) -> Arm:
    """The EKF with every real measurement, the gap's included."""
    tr = make_tracker(s)
    est = {}
    for i in range(len(sim.t)):
        out = tr.process(_measurement(s, sim, i))
        if out.estimate is not None:
            est[i] = out.estimate
    return _collect(est, s.n)


def run_dmd_ekf(s: Scenario, sim: Simulation, **surrogate_overrides
                ) -> tuple[Arm, Arm, list[Measurement]]:
    """The DMD-EKF (surrogate forecasts fused through the gap) and the coasting EKF.

    A gap epoch without a usable forecast (the surrogate could not fit, or the filter
    refused the forecast) carries the filter's prediction, as the live filter publishes.
    `surrogate_overrides`: `SurrogateConfig` fields for studies (none in the reproduction).
    Returns (dmd_ekf arm, ekf_coast arm, the forecasts the surrogate issued)."""
    tr = make_tracker(s)
    su = make_surrogate(s, **surrogate_overrides)
    est: dict[int, object] = {}
    forecasts: list[Measurement] = []
    grace = su.config.grace

    def feed(m: Measurement) -> None:
        out = tr.process(m)
        if out.estimate is not None:
            est[_index(s, m.t)] = out.estimate
        for e in out.fused_again:
            est[_index(s, e.t)] = e

    for i in range(len(sim.t)):
        if sim.in_gap[i]:
            # the live graph's surrogate timer: forecasts due once the epoch is missed
            fs = su.due(float(sim.t[i]) + (grace + 0.1) * s.cadence_s)
            forecasts.extend(fs)
            for f in fs:
                feed(f)
            if i not in est:  # no (usable) forecast for this epoch: the filter predicts
                e = tr.predicted(float(sim.t[i]))
                if e is not None:
                    est[i] = e
            continue
        m = _measurement(s, sim, i)
        owed = su.add(m)
        forecasts.extend(owed)
        for f in owed:
            feed(f)
        feed(m)
    return _collect(est, s.n), _coast_arm(s, sim), forecasts


def _coast_arm(s: Scenario, sim: Simulation) -> Arm:
    """The filter coasting through the gap on its placeholder (no updates): the EKF
    prediction chained epoch by epoch from the last real update (x <- f(x), P <- F P F' + Q)."""
    tr = make_tracker(s)
    for i in range(len(sim.t)):
        if sim.in_gap[i]:
            break
        tr.process(_measurement(s, sim, i))
    x, P, t = tr.ekf.x.copy(), tr.ekf.P.copy(), tr.t
    f = placeholder(s)
    est = {}
    for i in np.flatnonzero(sim.in_gap):
        dt = float(sim.t[i]) - t
        x, F = f(x, dt)
        P = F @ P @ F.T + process_noise(dt, s.q, dim=s.n // 2)
        P = 0.5 * (P + P.T)
        t = float(sim.t[i])
        est[int(i)] = StateEstimate(t, x.copy(), P.copy())
    return _collect(est, s.n)


def initial_estimate(s: Scenario, sim: Simulation) -> tuple[int, np.ndarray, np.ndarray]:
    """(index, state, covariance) of the tracker's first estimate (IOD + P0 floor)."""
    tr = make_tracker(s)
    for i in range(len(sim.t)):
        out = tr.process(_measurement(s, sim, i))
        if out.estimate is not None:
            return _index(s, out.estimate.t), out.estimate.x, out.estimate.P
    raise RuntimeError(f"{s.name}: initial orbit determination never succeeded")


def run_placeholder(s: Scenario, sim: Simulation, seed: int,
                    n_particles: int = N_PARTICLES) -> Arm:
    """Monte Carlo of the placeholder alone from the initial estimate and its covariance."""
    i0, x0, P0 = initial_estimate(s, sim)
    idx = np.arange(i0, len(sim.t))
    mean, P = placeholder_ensemble(s.placeholder, x0, P0, sim.t[idx] - sim.t[i0], seed,
                                   n_particles, **s.placeholder_params)
    return Arm(idx, mean, P)


# ----------------------------------------------------------------------------------------
def _gap_view(arm: Arm, sim: Simulation) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
    gap = sim.gap_index
    pos = {int(i): k for k, i in enumerate(arm.idx)}
    missing = [int(i) for i in gap if int(i) not in pos]
    if missing:
        raise RuntimeError(f"arm has no estimate for {len(missing)} gap epochs")
    k = np.array([pos[int(i)] for i in gap])
    return arm.x[k], sim.x[gap], None if arm.P is None else arm.P[k]


def forecast_fraction(arm: Arm, sim: Simulation) -> float:
    """Fraction of the gap epochs at which `arm` fused a forecast."""
    gap = set(int(i) for i in sim.gap_index)
    fused = sum(1 for i, src in zip(arm.idx, arm.source, strict=True)
                if int(i) in gap and src == UpdateSource.FORECAST)
    return fused / max(1, len(gap))


def score(arm: Arm, sim: Simulation) -> dict:
    """epsilon over the gap, and the NEES over the gap where a covariance exists."""
    xh, xt, P = _gap_view(arm, sim)
    out = {"epsilon": epsilon(xh, xt)}
    if P is not None and np.all(np.isfinite(P)):
        try:
            e = nees(xh - xt, P)
            out["nees"] = e
        except np.linalg.LinAlgError:
            pass
    return out


def forecast_errors(s: Scenario, sim: Simulation, forecasts: list[Measurement]) -> dict:
    """Forecast minus true (noise-free) measurement, and the forecast's covariance, per
    horizon, for the forecasts issued during the gap."""
    model = measurement_model(s)
    h, err, C = [], [], []
    for f in forecasts:
        i = _index(s, f.t)
        zt = sim.z_true[i]
        e = np.asarray(f.z, float) - zt
        for c, is_angle in enumerate(model.angle_mask):
            if is_angle:
                e[c] = wrap_pi(e[c])
        h.append(f.horizon)
        err.append(e)
        C.append(np.asarray(f.R, float))
    return {"horizon": np.array(h), "err": np.array(err), "cov": np.array(C)}


def run_scenario(s: Scenario, seed: int, nees_runs: int = 1) -> dict:
    """The three arms (and the coasting EKF) on `s`; a dict of results and of arrays for
    plots. For noisy scenarios with nees_runs > 1 the DMD-EKF's NEES is averaged over
    `nees_runs` independent noise seeds (seed, seed+1, ...), the first of which is the one
    scored and plotted."""
    sim = simulate(s, seed)
    hyp = run_hypothetical(s, sim)
    dmd, coast, forecasts = run_dmd_ekf(s, sim)
    ph = run_placeholder(s, sim, seed)
    arms = {"placeholder": ph, "dmd_ekf": dmd, "hypothetical_ekf": hyp, "ekf_coast": coast}
    scores = {k: score(a, sim) for k, a in arms.items()}
    noisy = bool(np.any(sim.sigma > 0))
    result = {"arms": {}, "noisy": noisy}
    for k, sc in scores.items():
        r = {"epsilon": sc["epsilon"]}
        if noisy and "nees" in sc:
            r["nees_mean"] = float(np.mean(sc["nees"]))
        result["arms"][k] = r
    # how much of the DMD-EKF is forecasts (the rest: the filter's predictions, see run_dmd_ekf)
    result["arms"]["dmd_ekf"]["forecast_fraction"] = forecast_fraction(dmd, sim)
    if noisy:
        runs = [scores["dmd_ekf"]["nees"]]
        hyp_runs = [scores["hypothetical_ekf"]["nees"]]
        for j in range(1, nees_runs):
            sim_j = simulate(s, seed + j)
            dmd_j, _, _ = run_dmd_ekf(s, sim_j)
            runs.append(score(dmd_j, sim_j)["nees"])
            hyp_runs.append(score(run_hypothetical(s, sim_j), sim_j)["nees"])
        avg = np.mean(runs, axis=0)  # per-epoch NEES averaged over the runs
        lo, hi = chi2_bounds(s.n, len(runs))
        result["nees"] = {
            "runs": len(runs), "dof": s.n, "band95": [lo, hi],
            "dmd_ekf_mean": float(np.mean(avg)),
            "dmd_ekf_fraction_in_band": float(np.mean((avg >= lo) & (avg <= hi))),
            "hypothetical_ekf_mean": float(np.mean(np.mean(hyp_runs, axis=0))),
        }
        result["arms"]["dmd_ekf"]["nees_mean"] = result["nees"]["dmd_ekf_mean"]
        result["arms"]["hypothetical_ekf"]["nees_mean"] = result["nees"]["hypothetical_ekf_mean"]
    fe = forecast_errors(s, sim, forecasts)
    if len(fe["err"]):
        result["forecast"] = {
            "count": len(fe["err"]),
            "rms_error_last": float(np.sqrt(np.mean(fe["err"][-1] ** 2))),
            "nees_mean": float(np.mean(nees(fe["err"], fe["cov"]))) if noisy else None,
        }
    result["_sim"] = sim
    result["_arms"] = arms
    result["_forecast"] = fe
    return result


# ----------------------------------------------------------------------------------------
def vdp_sweep(s: Scenario, seed: int, mus: np.ndarray) -> dict:
    """Paper fig. "VDP with different mu": epsilon of each arm vs the placeholder's mu_p."""
    sim = simulate(s, seed)
    out = {"mu_p": [], "placeholder": [], "dmd_ekf": [], "hypothetical_ekf": []}
    for mu in mus:
        sm = s.with_(placeholder_params={**s.placeholder_params, "mu": float(mu)})
        out["mu_p"].append(round(float(mu), 10))
        out["hypothetical_ekf"].append(score(run_hypothetical(sm, sim), sim)["epsilon"])
        out["dmd_ekf"].append(score(run_dmd_ekf(sm, sim)[0], sim)["epsilon"])
        out["placeholder"].append(score(run_placeholder(sm, sim, seed), sim)["epsilon"])
    return out

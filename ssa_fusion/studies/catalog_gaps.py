"""Gap forecasts over a catalog: the residual surrogate against the filter coasting.

`gap_errors` scores the forecasts a catalog run made (`core.catalog.gap_bank`, the
``catalog_surrogate`` node) against the SGP4 truth of its catalog, beside the filter coasting
on its own motion model (two-body + J2: the physics-only filter) from the same pass end, at
the same epochs. `offline_run` runs the same pipeline without ROS: a synthetic LEO catalog
measured by a scenario's radars (`sim.survey`), fused by the batched filter
(`core.catalog.track_bank`) and forecast by a `GapBank` that fits every gap (no wall-time
budget), so the accuracy of the method is measured apart from the time the live node has for it.

The residual setting is the live filter's (`core.gaps.residual.LIVE_RESIDUAL`, chosen on the
ISS gap study's tuning seeds 1-3): nothing here is tuned, and the catalog seeds
(`EVALUATION_SEEDS`) are used for nothing else.
"""

from __future__ import annotations

import math
import time
from collections import defaultdict
from collections.abc import Iterable, Iterator
from dataclasses import replace
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np
from scipy.stats import chi2

from ssa_fusion.core.base.rows import MeasurementRows
from ssa_fusion.core.base.types import Kind, MotionModel, Source
from ssa_fusion.core.catalog.gap_bank import GapBank, GapBankConfig, GapForecast
from ssa_fusion.core.catalog.track_bank import TrackBank
from ssa_fusion.core.earth.timescales import DAY_S, UNIX_EPOCH_JD
from ssa_fusion.core.filter.options import FilterOptions
from ssa_fusion.core.gaps import residual_frame
from ssa_fusion.core.gaps.forecaster import PLACEHOLDER_TRAJECTORY
from ssa_fusion.core.gaps.publisher import GapFill
from ssa_fusion.core.measure.measurement import StationModels
from ssa_fusion.core.motion.element_sets import CatalogEntry, catalog_states
from ssa_fusion.evaluation.object_states import States, states_of
from ssa_fusion.formats import element_sets as catalog_io
from ssa_fusion.sim import survey
from ssa_fusion.sim.sky import SKY_SCENARIOS, SkyScenario

SAMPLE = Path(__file__).resolve().parents[2] / "config" / "catalogs" / "sample.tle"
"""The sample catalog; its first element set (CBERS 2, LEO) is spread into synthetic ones."""
EVALUATION_SEEDS = tuple(range(101, 106))
"""Seeds of the synthetic catalogs and their measurement noise; never used for tuning."""
GAPS_SCORED = 200
"""Most gaps whose forecasts are scored against the coasting filter (evenly chosen)."""

def bank_config(s: SkyScenario) -> FilterOptions:
    """Return the batched filter's settings of scenario `s`.

    Its motion model, process noise, IOD, bounds; no light time: the batched filter has
    none.
    """
    return s.filter_options()


def gap_errors(entries: list[CatalogEntry], estimates: States, forecasts: States,
               motion_model: str = "j2", max_gaps: int = GAPS_SCORED) -> dict[str, Any]:
    """Score forecasts against the SGP4 truth of `entries`, beside coasting.

    Position errors (km) of the `forecasts` and of the filter coasting on `motion_model`
    from the same pass end (the object's newest estimate before them), at the same epochs,
    over up to `max_gaps` gaps evenly chosen (a gap: the forecasts after one estimate).
    """
    gaps = []  # (object, pass end t, x, forecast epochs, forecast positions)
    for oid, fc in sorted(forecasts.items()):
        est = estimates.get(oid)
        if est is None or not est.t.size:
            continue
        end = np.searchsorted(est.t, fc.t) - 1  # the estimate each forecast follows
        for j in np.unique(end[end >= 0]):
            at = end == j
            gaps.append((oid, est.t[j], est.x[j], fc.t[at], fc.x[at, :3]))
    if not gaps:
        return {"gaps": 0, "forecasts": 0}
    pick = np.unique(np.linspace(0, len(gaps) - 1, min(max_gaps, len(gaps))).astype(int))
    by_id = {e.object_id: e for e in entries}
    coast = residual_frame.orbit_propagator(PLACEHOLDER_TRAJECTORY[MotionModel(motion_model)])
    e_fc, e_coast, better = [], [], 0
    for i in pick.tolist():
        oid, t0, x0, tf, rf = gaps[i]
        truth = catalog_states([by_id[oid]], tf).x[0][:, :3]
        a = np.linalg.norm(rf - truth, axis=1)
        b = np.linalg.norm(coast(x0, float(t0), tf)[:, :3] - truth, axis=1)
        e_fc.append(a)
        e_coast.append(b)
        better += int(np.median(a) < np.median(b))
    fc_all, coast_all = np.concatenate(e_fc), np.concatenate(e_coast)
    med_fc, med_coast = float(np.median(fc_all)), float(np.median(coast_all))
    return {"gaps": len(gaps), "gaps_scored": int(pick.size),
            "forecasts": int(sum(len(g[3]) for g in gaps)),
            "forecasts_scored": int(fc_all.size),
            "forecast_error_km": {"median": med_fc, "p95": float(np.percentile(fc_all, 95))},
            "coast_error_km": {"median": med_coast,
                               "p95": float(np.percentile(coast_all, 95))},
            "coast_over_forecast": med_coast / med_fc if med_fc > 0 else None,
            "gaps_forecast_better": better / pick.size}


def forecast_nees(entries: list[CatalogEntry],
                  forecasts: list[GapForecast]) -> dict[str, Any]:
    """Score forecasts' covariances against the SGP4 truth of `entries`, by fit.

    Position NEES (3 dof) of each forecast: its share within chi2(3)'s 95 % bound
    (``in_bound``, the gap fits' criterion, `core.gaps.batch_gap.GAP_FIT_SNC`), median NEES and
    median position error (km); for all forecasts, those of the physics-only fit
    (``physics``) and of the learned residual (``learned``).
    """
    by_id = {e.object_id: e for e in entries}
    nees, err, phys = [], [], []
    groups: dict[str, list[GapForecast]] = defaultdict(list)
    for f in forecasts:
        groups[f.object_id].append(f)
    for oid, fs in groups.items():
        truth = catalog_states([by_id[oid]], np.array([f.t for f in fs])).x[0]
        for f, xt in zip(fs, truth, strict=True):
            e = f.x[:3] - xt[:3]
            nees.append(float(e @ np.linalg.solve(f.P[:3, :3], e)))
            err.append(float(np.linalg.norm(e)))
            phys.append(f.physics)
    bound = float(chi2.ppf(0.95, 3))
    a, b, p = np.array(nees), np.array(err), np.array(phys, bool)
    out: dict[str, Any] = {"bound": bound}
    for name, m in (("all", np.ones(a.size, bool)), ("physics", p), ("learned", ~p)):
        out[name] = ({"forecasts": int(m.sum()), "in_bound": float(np.mean(a[m] <= bound)),
                      "nees_median": float(np.median(a[m])),
                      "error_km_median": float(np.median(b[m]))}
                     if m.any() else {"forecasts": 0})
    return out


def gap_coverage(estimates: States, forecasts: States, t_start: float, t_end: float,
                 pass_break_s: float, after_s: float = DAY_S) -> dict[str, Any]:
    """Count the gaps after the first `after_s` of a run and those with a forecast.

    A gap: an object's estimate (epoch t_e, s) followed by `pass_break_s` or more without
    one (up to its next estimate, or to `t_end`, the run's last sim epoch), with t_e at
    least `after_s` after `t_start` (the run's first sim epoch). It has a forecast when one
    of the object's `forecasts` lies in (t_e, next estimate or `t_end`]. Returns ``gaps``,
    ``with_forecast`` and ``after_s``; and the same for the gaps at least `after_s` after
    the object's own first gap (``object_gaps``, ``object_with_forecast``: where the
    residual's pass ends can span a day, ``min_span_s``, whenever the object's first pass
    ends).
    """
    gaps = covered = own = own_covered = 0
    for oid, est in estimates.items():
        te = np.unique(est.t)
        nxt = np.append(te[1:], t_end)
        is_gap = nxt - te >= pass_break_s
        if not is_gap.any():
            continue
        fc = forecasts.get(oid)
        tf = np.zeros(0) if fc is None else fc.t
        first_after = np.searchsorted(tf, te, side="right")  # each t_e's first forecast after
        hit = (first_after < tf.size) & (tf[np.minimum(first_after, max(tf.size - 1, 0))]
                                         <= nxt) if tf.size else np.zeros(te.size, bool)
        late = is_gap & (te >= t_start + after_s)
        mine = is_gap & (te >= te[is_gap][0] + after_s)
        gaps, covered = gaps + int(late.sum()), covered + int((late & hit).sum())
        own, own_covered = own + int(mine.sum()), own_covered + int((mine & hit).sum())
    return {"gaps": gaps, "with_forecast": covered, "after_s": after_s,
            "object_gaps": own, "object_with_forecast": own_covered}


class _FrozenWall:
    """A wall clock that moves only between rounds: every fit costs nothing of the budget."""

    def __init__(self) -> None:
        self.now = 0.0

    def __call__(self) -> float:
        return self.now


class EstimateStep(NamedTuple):
    """One batch of `estimate_batches`: the measurements of a batch and what they gave.

    `now`: sim s (Unix) at the batch's end; `rows`: its measurements (None: none);
    `fused`: (object id, epoch s) of each estimate, epoch order within an object; `x`
    (k, 6) GCRF km, km/s and `P` (k, 6, 6) the estimates; `filter_wall_s`: the filter's
    wall s on the batch.
    """

    now: float
    rows: MeasurementRows | None
    fused: list[tuple[str, float]]
    x: np.ndarray
    P: np.ndarray
    filter_wall_s: float


def estimate_batches(entries: list[CatalogEntry], s: SkyScenario, hours: float,
                     seed: int, batch_s: float = 60.0) -> Iterator[EstimateStep]:
    """Yield a catalog's measurements and the batched filter's estimates, batch by batch.

    `entries` measured by the radars of `s` for `hours` from their `survey.catalog_start`
    (noise by `seed`), fused by a `track_bank.TrackBank` every `batch_s` sim s.
    """
    radars = s.radars
    t0 = survey.catalog_start(entries)
    obs = survey.observe_catalog(entries, radars, t0, hours * 3600.0, seed=seed)
    names = [r.station.name for r in radars]
    bank = TrackBank(bank_config(s), {r.station.name: r.station for r in radars})
    R = np.array([r.R for r in radars])
    edges = np.searchsorted(obs.t, t0 + batch_s * np.arange(
        1, math.ceil(hours * 3600.0 / batch_s) + 2))
    first = 0
    for k, last in enumerate(edges):
        now = t0 + batch_s * (k + 1)
        if last <= first:
            yield EstimateStep(now, None, [], np.zeros((0, 6)), np.zeros((0, 6, 6)), 0.0)
            continue
        sl = slice(first, int(last))
        ids = [obs.object_ids[i] for i in obs.obj[sl]]
        frames = [names[i] for i in obs.sensor[sl]]
        c = time.perf_counter()
        res = bank.process(obs.t[sl], ids, frames, obs.z[sl], R[obs.sensor[sl]])
        spent = time.perf_counter() - c
        rows = MeasurementRows(obs.t[sl], ids, frames, obs.z[sl], R[obs.sensor[sl]],
                               kind=np.full(len(ids), Kind.RANGE_AZ_EL, np.uint8),
                               source=np.full(len(ids), Source.SENSOR, np.uint8))
        fused = [(ids[i], float(obs.t[sl][i])) for i in res.fused.tolist()]
        first = int(last)
        yield EstimateStep(now, rows, fused, res.x, res.P, spent)


def offline_run(seed: int, objects: int, hours: float, scenario: str = "iss_network",
                batch_s: float = 60.0, gap_config: GapBankConfig | None = None,
                max_gaps: int = GAPS_SCORED,
                gap_forecasts: tuple[GapFill, ...] = (GapFill.RESIDUAL,)) -> dict[str, Any]:
    """One synthetic catalog through survey, batched filter and gap forecasts, scored.

    `objects` LEO objects (the sample catalog's first element set spread by `seed`),
    measured for `hours` by the radars of `scenario`, fused every `batch_s` sim s. One
    `GapBank` per arm of `gap_forecasts` (`gap_bank.GAP_FORECASTS`; `gap_config` with its
    ``gap_forecast`` replaced) takes the same estimates (and, for the batch fit, every
    measurement of the object, as the catalog_surrogate does) and fits every gap (no
    budget). Returns the first arm's scores (`gap_errors`) with its fits' counts
    (``fits_physics``: of the physics-only fit, `GapBankConfig.physics`), its forecasts'
    covariances against the truth (``nees``, `forecast_nees`), its gaps after the first day
    with a forecast (``coverage``, `gap_coverage`), the fits' mean wall time and the
    surrogate's wall time per object (fits, scoring and keeping the windows), the filter's
    wall time per object; under ``arms`` the same for every arm, and
    under ``common`` every arm's scores at the epochs of the gaps every arm forecast (the
    same gaps: a paired comparison).
    """
    s = SKY_SCENARIOS[scenario]
    entries = survey.synthetic_catalog(catalog_io.read_catalog(SAMPLE)[0], objects, seed=seed)
    t_first = survey.catalog_start(entries)
    stations = {r.station.name: r.station for r in s.radars}
    wall = _FrozenWall()
    base = gap_config or GapBankConfig(motion_model=MotionModel(s.motion_model))
    model = StationModels(stations, UNIX_EPOCH_JD)
    arms = {GapFill(f): _Arm(GapBank(replace(base, gap_forecast=GapFill(f)), wall=wall,
                                     model=model))
            for f in gap_forecasts}
    estimates: dict[str, list[tuple[float, np.ndarray]]] = defaultdict(list)
    c_filter = 0.0
    measurements = 0
    for step in estimate_batches(entries, s, hours, seed, batch_s):
        c_filter += step.filter_wall_s
        measurements += len(step.rows) if step.rows is not None else 0
        for j, (oid, t) in enumerate(step.fused):
            estimates[oid].append((t, step.x[j]))
        for arm in arms.values():
            arm.take(step)
        wall.now += 1.0
        for arm in arms.values():
            arm.advance(step.now)
    shared = set.intersection(*({(o, t) for o, r in arm.forecasts.items() for t, _ in r}
                                for arm in arms.values()))
    est = states_of(estimates)
    coverage_window = (t_first, t_first + 3600.0 * hours, base.pass_break_s)
    scores = {str(f): arm.scores(entries, est, s.motion_model, max_gaps, objects,
                                 coverage_window)
              for f, arm in arms.items()}
    common = {str(f): gap_errors(entries, est,
                                 states_of({o: [r for r in rows if (o, r[0]) in shared]
                                            for o, rows in arm.forecasts.items()}),
                                 s.motion_model, max_gaps) for f, arm in arms.items()}
    out = dict(scores[str(next(iter(arms)))])
    out.update({"seed": seed, "objects": objects, "hours": hours, "measurements": measurements,
                "estimates": sum(len(v) for v in estimates.values()),
                "filter_wall_s_per_object": c_filter / objects,
                "arms": scores, "common": common})
    return out


class _Arm:
    """One arm of `offline_run`: its gap bank, the forecasts it made and its wall time, s."""

    def __init__(self, bank: GapBank) -> None:
        self.bank = bank
        self.forecasts: dict[str, list[tuple[float, np.ndarray]]] = defaultdict(list)
        self.made: list[GapForecast] = []
        self.wall_s = 0.0

    def _keep(self, made: Iterable[GapForecast]) -> None:
        for g in made:
            self.forecasts[g.object_id].append((g.t, g.x))
            self.made.append(g)

    def take(self, step: EstimateStep) -> None:
        """Give the bank a step's measurements and estimates; keep the forecasts it makes."""
        c = time.perf_counter()
        if step.rows is not None:
            self.bank.on_measurements(step.rows)
        for j, (oid, t) in enumerate(step.fused):
            self._keep(self.bank.on_estimate(oid, t, step.x[j], step.P[j]))
        self.wall_s += time.perf_counter() - c

    def advance(self, now: float) -> None:
        """Let the bank fit and forecast up to `now` (Unix s); keep the forecasts."""
        c = time.perf_counter()
        self._keep(self.bank.step(now))
        self.wall_s += time.perf_counter() - c

    def scores(self, entries: list[CatalogEntry], est: States, motion_model: str,
               max_gaps: int, objects: int,
               coverage_window: tuple[float, float, float]) -> dict[str, Any]:
        """Return the arm's scores (`offline_run`).

        ``coverage_window``: `gap_coverage`'s start and end (Unix s) and pass break (s).
        """
        gaps = self.bank
        n_fits = gaps.counts["fitted"]
        fc = states_of(self.forecasts)
        one = gap_errors(entries, est, fc, motion_model, max_gaps)
        one.update({"gap_forecast": str(gaps.config.gap_forecast), "fits_made": n_fits,
                    "fits_physics": gaps.counts["fitted_physics"],
                    "fits_refused": gaps.counts["refused"], "surrogate_wall_s": self.wall_s,
                    "surrogate_wall_s_per_object": self.wall_s / objects,
                    "window_bytes_per_object": gaps.windows.nbytes() / objects,
                    "wall_s_per_fit": self.wall_s / n_fits if n_fits else None,
                    "nees": forecast_nees(entries, self.made) if self.made else None,
                    "coverage": gap_coverage(est, fc, *coverage_window)})
        return one

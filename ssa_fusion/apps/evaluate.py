"""Evaluate a bag the graph recorded: every arm of `ssa_fusion.evaluation.arms` over the gap.

The arms (placeholder, coast, j2_coast, batch_fit, dmd_ekf, hypothetical_ekf) are defined and scored
once, in `evaluation.arms`, for the offline study and for bags alike. Here the DMD-EKF arm
is the filter's live estimates during the gap (`/ssa/estimate`); the gap epochs are the
`/ssa/withheld` stamps; the truth is `/ssa/truth`.

The estimator settings the other arms run with are, in this order: a ROS params file
(`--params-file`), a paper scenario (`--scenario`), a filter set-up (`--filter`,
`filter_setup`), the settings the nodes recorded with the bag on `/ssa/config`, and for a
bag without them (your own data, or one written without ROS) the set-up its measurements
call for (`filter_setup`: radar, optical, network or position, by their kinds and
stations), said in the output.
"""

from __future__ import annotations

import sys
from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ssa_fusion.apps.filter_setup import DataMix, FilterSetup, chosen_estimator
from ssa_fusion.core.base import metrics, types
from ssa_fusion.core.earth.frames import Frame, Station
from ssa_fusion.core.earth.stations import find_station
from ssa_fusion.core.gaps import estimator as config
from ssa_fusion.core.gaps.estimator import EstimatorConfig
from ssa_fusion.evaluation import passes as passes_
from ssa_fusion.evaluation.arms import ArmName, GapEvaluation, evaluate_gap
from ssa_fusion.evaluation.gap_scores import GapScores, score_gaps
from ssa_fusion.params import settings
from ssa_fusion.params.params_file import load_params_file
from ssa_fusion.ros import bagio, topics
from ssa_fusion.ros.messages import estimate_from_msg, measurement_from_msg
from ssa_fusion.sim import scenarios, sky


@dataclass
class BagData:
    """Decoded topics of a bag, in core units (km, km/s, rad, s)."""

    truth: list[types.StateEstimate] = field(default_factory=list)
    estimates: list[types.StateEstimate] = field(default_factory=list)
    measurements: list[types.Measurement] = field(default_factory=list)
    withheld: list[types.Measurement] = field(default_factory=list)
    forecasts: list[types.Measurement] = field(default_factory=list)
    smoothed: list[types.StateEstimate] = field(default_factory=list)
    """`replay --offline --smooth`'s smoothed estimates (/ssa/estimate_smoothed)."""
    config: list[str] = field(default_factory=list)
    counts: dict[str, int] = field(default_factory=dict)
    frames: set[str] = field(default_factory=set)
    """The frame_id of the truth and estimate messages: {"gcrf"}, or {"eci"} for a bag
    recorded before the GCRF (`frames.Frame.LEGACY_ECI`)."""

    @property
    def legacy_frame(self) -> bool:
        """True when the bag's states are not in the GCRF (a recording of older versions)."""
        return bool(self.frames - {Frame.GCRF})

    def frame_note(self, path: Path | str) -> str:
        """One line saying a legacy bag's frame, or "" for a GCRF bag."""
        if not self.legacy_frame:
            return ""
        return (f"note: {path}: its states are in frame {', '.join(sorted(self.frames))!r}, "
                f"recorded before ssa_fusion used the GCRF (Earth-consistent frames); errors "
                f"against its own truth stand, its states are not GCRF")


def load(path: Path | str) -> BagData:
    """Read the /ssa topics of a bag into core types (other topics are counted only).

    Measurements and estimates recorded as batches are read as their rows
    (`bagio.read_records`) and counted under /ssa/measurement and /ssa/estimate, as if
    recorded one message each; what was left out is counted and said on stderr.
    """
    data = BagData()
    states = {topics.TOPIC_TRUTH: data.truth, topics.TOPIC_ESTIMATE: data.estimates,
              topics.TOPIC_SMOOTHED: data.smoothed}
    measurements = {topics.TOPIC_MEASUREMENT: data.measurements,
                    topics.TOPIC_WITHHELD: data.withheld, topics.TOPIC_FORECAST: data.forecasts}
    undecodable: Counter[str] = Counter()
    refused: Counter[tuple[str, str]] = Counter()
    for m in bagio.read_records(path, undecodable=undecodable, refused=refused):
        data.counts[m.topic] = data.counts.get(m.topic, 0) + 1
        if m.topic in states:
            states[m.topic].append(estimate_from_msg(m.msg))
            data.frames.add(m.msg.header.frame_id)
        elif m.topic in measurements:
            measurements[m.topic].append(measurement_from_msg(m.msg))
        elif m.topic == topics.TOPIC_CONFIG:
            data.config.append(m.msg.data)
    data.counts.update(bagio.counts_left_out(undecodable, refused))
    for line in bagio.left_out(undecodable, refused):
        print(f"warning: {path}: {line}", file=sys.stderr)
    return data


@dataclass
class Settings:
    """The estimator settings an evaluation or replay runs with, and where they came from."""

    estimator: EstimatorConfig
    origin: str


def settings_for_bag(recorded: list[str], mix: DataMix, scenario: str = "",
                     params_file: Path | None = None, sites: tuple[Station, ...] = (),
                     setup: FilterSetup | None = None) -> Settings:
    """Return the estimator settings for a bag (see the module docstring for the order).

    `recorded`: the bag's /ssa/config messages; `mix`: its sensor measurements by station
    and kind, whose own set-up (`filter_setup`) a bag without settings gets, or every bag
    with `setup` (``--filter``). ValueError (one line): a bad params file, an unknown
    scenario, malformed recorded settings, a set-up that takes none of the data, stations
    no one knows.

    `sites`: stations of one's own (a sites file), which the settings then know besides the
    built-in ones and those recorded; with them, settings whose stations do not include the
    bag's take the bag's (`config.for_stations`).
    """
    chosen = _settings_for_bag(recorded, mix, scenario, params_file, sites, setup)
    c = chosen.estimator
    if sites:
        own = {s.name: s for s in (*c.sites, *sites)}  # the file's win
        c = c.with_(sites=tuple(own.values()))
    ids = mix.stations(config.STATION_KINDS)
    if not ids or not sites or not config.uncovered_stations(c, ids):
        return Settings(c, chosen.origin)
    known = [i for i in ids if find_station(i, c.site_map) is not None]
    if not known:
        return Settings(c, chosen.origin)
    c = config.for_stations(c, known)
    return Settings(c, f"{chosen.origin}, with the stations its measurements name "
                       f"({', '.join(known)})")


def _settings_for_bag(recorded: list[str], mix: DataMix, scenario: str,
                      params_file: Path | None, sites: tuple[Station, ...],
                      setup: FilterSetup | None) -> Settings:
    """Return the settings by the module docstring's order."""
    if params_file is not None:
        return Settings(load_params_file(params_file), f"params file {params_file}")
    if scenario in sky.SKY_SCENARIOS:
        return Settings(sky.SKY_SCENARIOS[scenario].estimator(), f"scenario {scenario}")
    if scenario:
        return Settings(scenarios.get(scenario).estimator(), f"scenario {scenario}")
    estimator = None if setup is not None else settings.recorded_estimator(recorded)
    if estimator is not None:
        return Settings(estimator, f"recorded with the bag ({topics.TOPIC_CONFIG})")
    c, why = chosen_estimator(mix, setup, sites)
    return Settings(c, why if setup is not None else
                    f"{why} (the bag has no {topics.TOPIC_CONFIG})")


class NoTruthError(ValueError):
    """The bag lacks what the arms are scored against: the simulated truth (/ssa/truth).

    Or (`NoOutageError`) a simulated outage to score them over.
    """


class NoOutageError(NoTruthError):
    """The bag has a truth but no outage to score the arms over (its estimates still are).

    No /ssa/withheld, or an outage that withheld a few measurements between two truth
    epochs.
    """


@dataclass
class Evaluation:
    """A bag's gap evaluation and the settings it ran with.

    For a station network (the real sky), also how the filter did after each pass and
    through the gaps, and what it published between passes (`gap_scores`).
    """

    gap: GapEvaluation
    settings: Settings
    passes: passes_.PassReport | None = None
    between: GapScores | None = None


def require_outage(data: BagData) -> None:
    """Raise NoTruthError (or NoOutageError) when `data` lacks a truth (or an outage)."""
    if not data.truth:
        raise NoTruthError("the bag has no /ssa/truth messages: nothing to compare against")
    if not data.withheld:
        raise NoOutageError("the bag has no /ssa/withheld messages: no outage to score the "
                            "arms over")


def evaluate(data: BagData, scenario: str = "", seed: int = 0,
             params_file: Path | None = None, setup: FilterSetup | None = None) -> Evaluation:
    """Every arm over the bag's gap (see the module docstring)."""
    require_outage(data)
    chosen = settings_for_bag(data.config, DataMix.of(data.measurements), scenario, params_file,
                              setup=setup)
    truth = {e.t: e.x for e in data.truth}
    t_gap = np.array(sorted({m.t for m in data.withheld}))
    network = chosen.estimator.is_network
    if network:  # stations measure off the truth's cadence: the truth epochs of the outage
        t_gap = passes_.outage_epochs(np.array(sorted(truth)), data.withheld)
        if not len(t_gap):
            w = [m.t for m in data.withheld]
            raise NoOutageError(f"the outage withheld {len(w)} measurement(s) over "
                                f"{max(w) - min(w):.0f} s, between two /ssa/truth epochs: no "
                                f"outage epoch to score the arms over")
    missing = [t for t in t_gap if t not in truth]
    if missing:
        raise ValueError(f"/ssa/truth lacks {len(missing)} gap epochs (first t={missing[0]})")
    x_true = np.array([truth[t] for t in t_gap])
    live = {e.t: e for e in data.estimates if e.update_source != types.UpdateSource.NONE}
    real = [m for m in data.measurements if m.source == types.Source.SENSOR]
    gap = evaluate_gap(chosen.estimator, live, real, data.withheld, t_gap, x_true, seed)
    passes, between = truth_scores(data, chosen.estimator) if network else (None, None)
    return Evaluation(gap, chosen, passes, between)


def truth_scores(data: BagData, c: EstimatorConfig
                 ) -> tuple[passes_.PassReport | None, GapScores | None]:
    """Score the bag's estimates against its /ssa/truth: after each pass, between passes.

    (None, None) without a truth or a fused estimate. `c`: the filter's settings (its
    motion model predicts from the last estimate to a truth epoch without one).
    """
    live = {e.t: e for e in data.estimates if e.update_source != types.UpdateSource.NONE}
    if not data.truth or not live:
        return None, None
    truth = {e.t: e.x for e in data.truth}
    t_all = np.array(sorted(truth))
    x_all = np.array([truth[t] for t in t_all])
    real = [m for m in data.measurements if m.source == types.Source.SENSOR]
    return (passes_.pass_report(c, live, real, t_all, x_all),
            score_gaps({e.t: e for e in data.estimates}, real, t_all, x_all))


def position_error(passes: passes_.PassReport | None, between: GapScores | None,
                   truth_states: int) -> dict[str, Any] | None:
    """Return what report.json holds of the position error against the truth (None: none).

    From `truth_scores`: its mean and largest over the truth epochs, its median after the
    passes and between them, the fraction of NEES in the 95 % band.
    """
    if passes is None:
        return None
    err = passes.pos_err_km
    after = [row[3] for row in passes.passes]
    return {"truth_states": truth_states, "epochs": len(err),
            "mean_km": float(np.mean(err)) if len(err) else None,
            "max_km": float(np.max(err)) if len(err) else None,
            "after_pass_median_km": float(np.median(after)) if after else None,
            "between_passes_median_km": (None if between is None or not between.gap_epochs
                                         else between.err_median_km),
            "nees_in_band": passes.nees_in_band if len(passes.nees) else None}


def between_line(b: GapScores) -> str:
    """Return what the filter published between passes, against the truth, as one line."""
    long = (f"gaps > 12 h: {b.long_err_median_km:.3g} km over {b.long_gap_epochs} epochs"
            if b.long_gap_epochs else "no gap > 12 h")
    return (f"between passes, what the filter published ({b.gap_epochs} truth epochs): "
            f"median position error {b.err_median_km:.3g} km ({long}); right "
            f"after each pass {b.after_pass_median_km:.3g} km (median); position NEES "
            f"inside chi2(3)'s 95 % bound at {100 * b.nees_in_95:.1f} % of the epochs, "
            f"median {b.nees_median:.2f} (chi2(3)'s median: 2.37)")


@dataclass
class LateForecasts:
    """Forecasts the surrogate published for the gap that the filter never fused.

    An epoch counts when the bag holds a forecast for it (on /ssa/forecast, epoch within the
    gap's span) but no estimate of the filter that fused anything at it (update_source
    SENSOR or FORECAST): it was scored from the filter's prediction although a forecast
    existed. The forecast reached the filter too late (after the history it can roll back)
    or was dropped (superseded by a newer model, gated out, invalid). A real measurement
    at the same epoch (an estimate from SENSOR) supersedes a forecast by design: not counted.
    """

    epochs: int
    """Gap epochs with a forecast that the filter never fused."""
    forecast_epochs: int
    """Gap epochs with at least one forecast in the bag."""
    first_t: float | None = None
    """The earliest such epoch, s (sim time), or None."""


def unfused_forecasts(data: BagData, t_gap: np.ndarray) -> LateForecasts:
    """Count the gap's forecasts the filter never fused (`LateForecasts`).

    `t_gap`: the gap epochs, s (as `evaluate` scores them; their first and last bound the
    span).
    """
    if not len(t_gap) or not data.forecasts:
        return LateForecasts(0, 0)
    lo, hi = float(np.min(t_gap)), float(np.max(t_gap))
    wanted = sorted({f.t for f in data.forecasts
                     if lo <= f.t <= hi or types.same_epoch(f.t, lo) or types.same_epoch(f.t, hi)})
    fused = sorted({e.t for e in data.estimates
                    if e.update_source != types.UpdateSource.NONE})
    late = []
    for t in wanted:
        k = int(np.searchsorted(fused, t))
        if not any(0 <= j < len(fused) and types.same_epoch(fused[j], t) for j in (k - 1, k)):
            late.append(t)
    # epochs that differ by round-off only are one epoch
    distinct = [t for i, t in enumerate(wanted) if i == 0 or not types.same_epoch(wanted[i - 1], t)]
    late = [t for i, t in enumerate(late) if i == 0 or not types.same_epoch(late[i - 1], t)]
    return LateForecasts(len(late), len(distinct), late[0] if late else None)


ARM_COLUMNS = ("arm", "ε over the gap", "mean position error [km]",
               "final position error [km]", "mean NEES")
"""The columns of the arms table (`arm_rows`)."""


def arm_rows(g: GapEvaluation) -> list[list[str]]:
    """Return the arms table's cells (`ARM_COLUMNS`), one row per scored arm, formatted."""
    rows = []
    for arm in ArmName:
        sc = g.scores.get(arm)
        if sc is None:
            continue
        v = sc.nees_mean
        nees = "n/a" if v is None else (f"{v:.2f}" if abs(v) < 1e4 else f"{v:.2e}")
        rows.append([str(arm), f"{sc.epsilon:.3e}", f"{sc.pos_err_mean_km:.3g}",
                     f"{sc.pos_err_final_km:.3g}", nees])
    return rows


def table(ev: Evaluation) -> str:
    """Markdown table of the arms."""
    g = ev.gap
    rows = ["| " + " | ".join(ARM_COLUMNS) + " |", "|---|---|---|---|---|"]
    rows += ["| " + " | ".join(cells) + " |" for cells in arm_rows(g)]
    rows.append(f"\ngap: {len(g.t)} epochs; live DMD-EKF estimates at "
                f"{100 * g.coverage:.0f} % of them"
                + (f"; dmd_ekf at the other {g.predicted} scored from the last estimate "
                   "before, propagated by the filter's model" if g.predicted else ""))
    surrogate, coast = g.scores.get(ArmName.DMD_EKF), g.scores.get(ArmName.COAST)
    if surrogate is not None and coast is not None and g.coverage > 0:
        rows.append(f"surrogate (the live graph's estimates in the gap, `dmd_ekf`) against the "
                    f"EKF coasting: mean position error {surrogate.pos_err_mean_km:.3g} km vs "
                    f"{coast.pos_err_mean_km:.3g} km "
                    f"({coast.pos_err_mean_km / surrogate.pos_err_mean_km:.2f}x smaller)")
    lo, hi = metrics.chi2_bounds(g.truth.shape[1])
    rows.append(f"NEES: mean over the gap's epochs; a consistent filter's per-epoch NEES lies "
                f"in [{lo:.2f}, {hi:.2f}] 95 % of the time (χ², {g.truth.shape[1]} dof), "
                "its mean near the dof")
    rows.append(f"settings: {ev.settings.origin}")
    if ev.passes is not None:
        rows.append("\n" + ev.passes.table())
    b = ev.between
    if b is not None and b.gap_epochs:
        rows.append("\n" + between_line(b))
    return "\n".join(rows)

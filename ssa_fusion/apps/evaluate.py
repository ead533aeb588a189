"""Evaluate a bag the graph recorded: every arm of `ssa_fusion.evaluation.arms` over the gap.

The arms (placeholder, coast, j2_coast, dmd_ekf, hypothetical_ekf) are defined and scored
once, in `evaluation.arms`, for the offline study and for bags alike. Here the DMD-EKF arm
is the filter's live estimates during the gap (`/ssa/estimate`); the gap epochs are the
`/ssa/withheld` stamps; the truth is `/ssa/truth`.

The estimator settings the other arms run with are, in this order: a ROS params file
(`--params-file`), a paper scenario (`--scenario`), the settings the nodes recorded with the
bag on `/ssa/config`, and for a bag without them (written by an older version or without
ROS) the paper scenario of the measurement kind, said in the output.
"""

from __future__ import annotations

import sys
from collections import Counter
from collections.abc import Iterable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

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


def settings_for_bag(recorded: list[str], kind: int, scenario: str = "",
                     params_file: Path | None = None, stations: Iterable[str] = (),
                     sites: tuple[Station, ...] = ()) -> Settings:
    """Return the estimator settings for a bag (see the module docstring for the order).

    `recorded`: the bag's /ssa/config messages; `kind`: its measurement kind, for a bag
    without them. ValueError: a bad params file, an unknown scenario or malformed recorded
    settings.

    `stations`: the station ids its measurements name (their frame_id); `sites`: stations
    of one's own (a sites file), which the settings then know besides the built-in ones and
    those recorded. With `sites`, or when the bag has no settings of its own, settings whose
    stations do not include the bag's take the bag's (`config.for_stations`); a bag without
    settings whose stations are not the default's gets the real-sky filter for them
    (`config.station_estimator`).
    """
    chosen, default = _settings_for_bag(recorded, kind, scenario, params_file)
    c = chosen.estimator
    if sites:
        own = {s.name: s for s in (*c.sites, *sites)}  # the file's win
        c = c.with_(sites=tuple(own.values()))
    ids = sorted(set(stations))
    if not ids or not (sites or default) or not config.uncovered_stations(c, ids):
        return Settings(c, chosen.origin)
    known = [i for i in ids if find_station(i, c.site_map) is not None]
    if not known:
        return Settings(c, chosen.origin)
    if default:
        c = config.station_estimator(types.Kind(kind), ",".join(known) + ",", c.sites)
        return Settings(c, f"the real-sky filter for the stations its measurements name "
                           f"({', '.join(known)}; the bag has no {topics.TOPIC_CONFIG})")
    c = config.for_stations(c, known)
    return Settings(c, f"{chosen.origin}, with the stations its measurements name "
                       f"({', '.join(known)})")


def _settings_for_bag(recorded: list[str], kind: int, scenario: str,
                      params_file: Path | None) -> tuple[Settings, bool]:
    """Return the settings by the module docstring's order; True if the kind's default."""
    if params_file is not None:
        return Settings(load_params_file(params_file),
                        f"params file {params_file}"), False
    if scenario in sky.SKY_SCENARIOS:
        return Settings(sky.SKY_SCENARIOS[scenario].estimator(), f"scenario {scenario}"), False
    if scenario:
        return Settings(scenarios.get(scenario).estimator(), f"scenario {scenario}"), False
    estimator = settings.recorded_estimator(recorded)
    if estimator is not None:
        return Settings(estimator, f"recorded with the bag ({topics.TOPIC_CONFIG})"), False
    s = scenarios.settings_for("", kind)
    return Settings(s.estimator(), f"scenario {s.name} (the bag has no {topics.TOPIC_CONFIG}; "
                                   f"the default for its measurement kind)"), True


class NoTruthError(ValueError):
    """The bag lacks what an evaluation scores against.

    A simulated outage's withheld measurements (/ssa/withheld) or the simulated truth
    (/ssa/truth).
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


def evaluate(data: BagData, scenario: str = "", seed: int = 0,
             params_file: Path | None = None) -> Evaluation:
    """Every arm over the bag's gap (see the module docstring)."""
    if not data.withheld:
        raise NoTruthError("the bag has no /ssa/withheld messages: no gap to evaluate")
    if not data.truth:
        raise NoTruthError("the bag has no /ssa/truth messages: nothing to compare against")
    kind = data.measurements[0].kind if data.measurements else types.Kind.POSITION
    chosen = settings_for_bag(data.config, kind, scenario, params_file)
    truth = {e.t: e.x for e in data.truth}
    t_gap = np.array(sorted({m.t for m in data.withheld}))
    network = chosen.estimator.is_network
    if network:  # stations measure off the truth's cadence: the truth epochs of the outage
        t_gap = passes_.outage_epochs(np.array(sorted(truth)), data.withheld)
    missing = [t for t in t_gap if t not in truth]
    if missing or not len(t_gap):
        raise ValueError(f"/ssa/truth lacks {len(missing)} gap epochs (first t="
                         f"{missing[0] if missing else 'none in the gap'})")
    x_true = np.array([truth[t] for t in t_gap])
    live = {e.t: e for e in data.estimates if e.update_source != types.UpdateSource.NONE}
    real = [m for m in data.measurements if m.source == types.Source.SENSOR]
    gap = evaluate_gap(chosen.estimator, live, real, data.withheld, t_gap, x_true, seed)
    passes, between = None, None
    if network:
        t_all = np.array(sorted(truth))
        x_all = np.array([truth[t] for t in t_all])
        passes = passes_.pass_report(chosen.estimator, live, real, t_all, x_all)
        between = score_gaps({e.t: e for e in data.estimates}, real, t_all, x_all)
    return Evaluation(gap, chosen, passes, between)


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
        long = (f"gaps > 12 h: {b.long_err_median_km:.3g} km over {b.long_gap_epochs} epochs"
                if b.long_gap_epochs else "no gap > 12 h")
        rows.append(f"\nbetween passes, what the filter published ({b.gap_epochs} truth epochs): "
                    f"median position error {b.err_median_km:.3g} km ({long}); right "
                    f"after each pass {b.after_pass_median_km:.3g} km (median); position NEES "
                    f"inside chi2(3)'s 95 % bound at {100 * b.nees_in_95:.1f} % of the epochs, "
                    f"median {b.nees_median:.2f} (chi2(3)'s median: 2.37)")
    return "\n".join(rows)

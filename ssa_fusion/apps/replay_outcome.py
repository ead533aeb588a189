"""What `ssa-fusion replay` says of a replay: what it will take, and what came of it.

Before: the replay to run next on a bag and about how long it takes (`suggestion`, said by
`import tdm`: the offline replay's duration from its measurements, `offline_seconds`, beside
the data's own time a replay over ROS takes at ``--rate 1``), and what a replay over ROS
will take, said as it starts (`live_duration`).

After an offline replay: why it estimated nothing (`why_no_estimate`: what the filter
refused, by cause, each with its fix), what its estimates were judged against
(`judged`: the bag's ``/ssa/truth`` where it has one, after each pass and between the
passes), and with ``--smooth`` the smoothed against the filtered position error
(`smoothing_summary`).
"""

from __future__ import annotations

import math
import statistics
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from ssa_fusion.apps import evaluate
from ssa_fusion.apps.filter_setup import DataMix, data_setup
from ssa_fusion.core.base import types
from ssa_fusion.core.base.types import KIND_NAMES, Cause
from ssa_fusion.core.earth.stations import find_station
from ssa_fusion.core.gaps.estimator import EstimatorConfig, uncovered_stations
from ssa_fusion.ros import bagio, messages
from ssa_fusion.ros.topics import TOPIC_MEASUREMENT, TOPIC_TRUTH

if TYPE_CHECKING:
    from ssa_fusion.apps.replay import OfflineResult


OFFLINE_START_S = 5.0
"""Wall s an offline replay takes before its first measurement (imports, the bag read)."""
OFFLINE_PER_S = 500.0
"""Measurements an offline replay estimates per wall s, smoothing included (5357 radar
measurements of 10 days took 11 s on a busy 2-core machine: 700/s after its start)."""


def offline_seconds(measurements: int) -> float:
    """Return about how long (wall s) an offline replay of `measurements` takes."""
    return OFFLINE_START_S + measurements / OFFLINE_PER_S


def said_seconds(s: float) -> str:
    """Return a duration in words: "40 s", "3.5 min", "12.3 h"."""
    if s < 120.0:
        return f"{s:.0f} s"
    return f"{s / 60.0:.1f} min" if s < 7200.0 else f"{s / 3600.0:.1f} h"


def live_duration(played: list[bagio.BagMessage], rate: float) -> str:
    """Return what a replay over ROS of the `played` messages at `rate` will take, in words.

    The data's span, its wall time at `rate`, and the offline replay's beside it.
    """
    span = (played[-1].t_ns - played[0].t_ns) * 1e-9 if played else 0.0
    n = sum(1 for m in played if m.topic == TOPIC_MEASUREMENT)
    return (f"{said_seconds(span)} of data, about {said_seconds(span / rate)} of wall time "
            f"(--offline gives the same estimates in about {said_seconds(offline_seconds(n))})")


def suggestion(bag: Path, measurements: int, span_s: float, sites: Path | None) -> str:
    """Return the replay to run next on a bag of `measurements` over `span_s` (s) of data.

    The offline one (the same estimates as over ROS, by design: `replay`'s docstring) with its
    expected duration, beside what a ROS replay at rate 1 would take.
    """
    with_sites = f" --sites {sites}" if sites else ""
    return (f"next: `ssa-fusion replay {bag} --offline --smooth{with_sites}` (about "
            f"{said_seconds(offline_seconds(measurements))}; a replay over ROS gives the same "
            f"estimates in the data's own time, {said_seconds(span_s)} at --rate 1)")


def bag_stations(stream: list[bagio.BagMessage]) -> list[str]:
    """Return the station ids (frame_id) the bag's sensor measurements name, sorted."""
    return sorted({str(m.msg.header.frame_id) for m in stream
                   if m.topic == TOPIC_MEASUREMENT and m.msg.source == types.Source.SENSOR})


def why_no_estimate(stream: list[bagio.BagMessage], result: OfflineResult,
                    c: EstimatorConfig) -> str:
    """Return why an offline replay of `stream` with estimator `c` gave no estimate.

    From what the filter refused (`OfflineResult.rejected`, by cause): no sensor
    measurement, measurements of stations or a kind the settings do not take, an initial
    orbit determination that never converged; else the refusals by cause.
    """
    n = sum(1 for m in stream if m.topic == TOPIC_MEASUREMENT
            and m.msg.source == types.Source.SENSOR)
    if not n:
        return f"the bag has no sensor measurement (source SENSOR) on {TOPIC_MEASUREMENT}"
    got = dict(result.rejected)
    reasons = []
    if got.get(Cause.REJECTED_FRAME):
        ids = uncovered_stations(c, bag_stations(stream))
        unknown = [i for i in ids if find_station(i, c.site_map) is None]
        hint = (f"station id(s) {', '.join(unknown)} are neither built in nor in a sites "
                f"file: define them in one and give it with --sites" if unknown else
                "give --sites (the filter then takes the stations the measurements name) or "
                "settings whose station includes them (--params-file, --scenario)")
        reasons.append(f"{got.pop(Cause.REJECTED_FRAME)} measurement(s) from stations the "
                       f"filter does not take ({', '.join(ids) or 'see the bag'}; its station "
                       f"setting is {c.station!r}): {hint}")
    if got.get(Cause.REJECTED_KIND):
        mix = DataMix.of(messages.measurement_from_msg(m.msg) for m in stream
                         if m.topic == TOPIC_MEASUREMENT)
        reasons.append(f"{got.pop(Cause.REJECTED_KIND)} measurement(s) of another kind than "
                       f"the settings' {KIND_NAMES[c.kind]} (the bag has {mix.said()}): "
                       f"replay with --filter {data_setup(mix)}")
    pending, failed = got.pop(Cause.IOD_PENDING, 0), got.pop(Cause.IOD_FAILED, 0)
    if pending or failed:
        iod = c.filter.iod
        span = ("" if math.isinf(iod.iod_max_span_s)
                else f" within {iod.iod_max_span_s:g} s (one pass)")
        reasons.append(f"the initial orbit determination never converged ({pending} "
                       f"measurement(s) waited for it, {failed} attempt(s) failed; it needs "
                       f"{iod.iod_samples} real measurements of one station{span}): a pass "
                       f"of the data too short or too sparse for it; a --params-file with a "
                       f"smaller iod_samples or a longer iod_max_span starts it")
    reasons += [f"{k} {v}" for k, v in sorted(got.items()) if v]
    return "; ".join(reasons) or (f"the filter took none of the {n} measurement(s): see its "
                                  f"causes with `ssa-fusion replay BAG` over ROS "
                                  f"(/diagnostics), or choose other settings (--filter, "
                                  f"--params-file)")


def judged(stream: list[bagio.BagMessage], result: OfflineResult, c: EstimatorConfig,
           out: Path) -> str:
    """Return what the replay's estimates were judged against, in one line.

    The bag's /ssa/truth where it has one (`evaluate.truth_scores`: after each pass, between
    the passes), else what `report` judges them by.
    """
    truth = [messages.estimate_from_msg(m.msg) for m in stream if m.topic == TOPIC_TRUTH]
    if not truth:
        return (f"no {TOPIC_TRUTH} in the bag: `ssa-fusion report {out}` judges the "
                f"estimates by their residuals, NIS and covariance")
    data = evaluate.BagData(truth=truth, estimates=[e for _, e in result.estimates],
                            measurements=[messages.measurement_from_msg(m.msg) for m in stream
                                          if m.topic == TOPIC_MEASUREMENT])
    error = evaluate.position_error(*evaluate.truth_scores(data, c), len(truth))
    if error is None:
        return f"against the bag's {TOPIC_TRUTH}: no fused estimate to judge"
    after, between = error["after_pass_median_km"], error["between_passes_median_km"]
    return (f"against the bag's {TOPIC_TRUTH} ({len(truth)} states): position error mean "
            f"{error['mean_km']:.3g} km, largest {error['max_km']:.3g} km over "
            f"{error['epochs']} truth epochs"
            + (f"; median {after:.3g} km after a pass" if after is not None else "")
            + (f", {between:.3g} km between passes" if between is not None else ""))


def smoothing_summary(stream: list[bagio.BagMessage], result: OfflineResult) -> str:
    """Return the smoothed against the filtered position error at the truth's fused epochs."""
    truth = {messages.stamp_to_seconds(m.msg.header.stamp): messages.estimate_from_msg(m.msg).x
             for m in stream if m.topic == TOPIC_TRUTH}
    filtered = {e.t: e for _, e in result.estimates
                if e.update_source != types.UpdateSource.NONE}
    both = [e for e in result.smoothed if e.t in truth and e.t in filtered]
    if not both:
        return ("smoothed: no fused epoch has a truth message in the bag (nothing to score; "
                "the smoothed estimates are on /ssa/estimate_smoothed)")
    err_s = [float(np.linalg.norm(e.x[:3] - truth[e.t][:3])) for e in both]
    err_f = [float(np.linalg.norm(filtered[e.t].x[:3] - truth[e.t][:3])) for e in both]
    return (f"smoothed against filtered, position error at the {len(both)} fused epochs with "
            f"truth: median {statistics.median(err_s):.4g} vs {statistics.median(err_f):.4g}, "
            f"largest {max(err_s):.4g} vs {max(err_f):.4g} (the bag's units: km for orbits)")

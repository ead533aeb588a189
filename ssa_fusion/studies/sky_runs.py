"""Real-sky runs: a scenario's filter and surrogate over its simulated measurements, scored.

`run_dmd_ekf` drives the surrogate and the filter as the live graph drives them;
`evaluate_sky` scores that run after each pass, at every truth epoch, and every evaluation arm
over the scheduled outage (`evaluation.passes`, `evaluation.arms`).

Units: km, km/s, rad, s; times are Unix seconds (UTC); states GCRF.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ssa_fusion.core.base.types import Measurement, StateEstimate
from ssa_fusion.core.gaps.estimator import make_surrogate, make_tracker
from ssa_fusion.evaluation import arms
from ssa_fusion.evaluation.passes import PassReport, outage_epochs, pass_report
from ssa_fusion.sim.sky import SkySimulation


@dataclass
class SkyDmdRun:
    """The filter's estimates fusing the surrogate's forecasts, and the forecasts issued.

    The estimates are the last per epoch, keyed by epoch (Unix s).
    """

    estimates: dict[float, StateEstimate]
    forecasts: list[Measurement]


def run_dmd_ekf(sim: SkySimulation) -> SkyDmdRun:
    """Run surrogate + filter over the delivered measurements as the live graph drives them.

    Every real measurement goes to the surrogate (whose forecasts still owed go to the
    filter first) and to the filter; at every truth epoch between measurements the
    surrogate's timer releases the forecasts due.
    """
    c = sim.scenario.estimator()
    tracker, surrogate = make_tracker(c), make_surrogate(c)
    run = SkyDmdRun({}, [])

    def feed(m: Measurement) -> None:
        out = tracker.process(m)
        for e in (out.estimate, *out.fused_again):
            if e is not None:
                run.estimates[e.t] = e

    events = sorted([(m.t, 0, m) for m in sim.real] + [(float(t), 1, None) for t in sim.t],
                    key=lambda e: (e[0], e[1]))
    for t, _, m in events:
        forecasts = surrogate.add(m) if m is not None else surrogate.due(t)
        run.forecasts.extend(forecasts)
        for f in forecasts:
            feed(f)
        if m is not None:
            feed(m)
    return run


@dataclass
class SkyEvaluation:
    """A real-sky run scored.

    The passes and gaps, the arms over the scheduled outage, and how many forecasts the
    surrogate made.
    """

    passes: PassReport
    outage: arms.GapEvaluation | None
    forecasts: int


def evaluate_sky(sim: SkySimulation, seed: int = 0,
                 only: tuple[arms.ArmName, ...] = tuple(arms.ArmName)) -> SkyEvaluation:
    """Run the scenario's filter and surrogate over the delivered measurements; score them.

    After each pass, at every truth epoch, and every arm over the scheduled outage
    (`outage_epochs`; None when it spans no truth epoch).
    """
    s = sim.scenario
    c = s.estimator()
    real, withheld = sim.real, sim.withheld_measurements
    run = run_dmd_ekf(sim)
    report = pass_report(c, run.estimates, real, sim.t, sim.x)
    outage = None
    t_gap = outage_epochs(sim.t, withheld) if s.outages else sim.t[:0]
    if t_gap.size:  # none: the outage withheld nothing, or less than a truth epoch apart
        outage = arms.evaluate_gap(c, run.estimates, real, withheld, t_gap,
                                   sim.x[np.isin(sim.t, t_gap)], seed, only=only)
    return SkyEvaluation(report, outage, len(run.forecasts))

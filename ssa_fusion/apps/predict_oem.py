"""`ssa-fusion export oem BAG --predict-until UTC`: the fitted orbit beyond the data.

The product a laser station points with: the batch least-squares fit of the bag's laser
ranges (`laser_run.fit`: the object's high-fidelity forces, Cr, a range bias per station)
propagated from its epoch (the last range) to ``--predict-until`` every ``--step`` s, each
state with the fit's realistic covariance mapped there (`batch_ls.BatchFit.predict`: the
formal covariance scaled by the fit's weighted RMS squared; on LAGEOS-2, 12 h on, the
ranges predicted from it miss by 2.7 times their sigma RMS: read it as a lower bound). GCRF
states, UTC epochs, as `export oem` writes the filter's estimates (`--frame` converts).

Bags of other measurements have no fit to predict: refused in one line.
"""

from __future__ import annotations

import math

import numpy as np

from ssa_fusion.apps import laser_run
from ssa_fusion.core.base import types
from ssa_fusion.core.earth.timescales import iso, parse_utc
from ssa_fusion.formats.ccsds.common import CcsdsError
from ssa_fusion.ros import bagio
from ssa_fusion.ros.laser_bag import is_laser, laser_bag

__all__ = ["MAX_STATES", "predicted"]

MAX_STATES = 100_000
"""Most states one prediction writes (a day at 1 s)."""


def predicted(bag_path: object, until_utc: str, step_s: float
              ) -> tuple[list[types.StateEstimate], str]:
    """Return the fitted orbit's states from its epoch to ``until_utc``, and a summary.

    CcsdsError (one line) for a bag without laser ranges, an epoch before the fit's, a step
    that is no positive number or that gives more than `MAX_STATES` states.
    """
    stream = list(bagio.read_records(str(bag_path)))
    if not is_laser(stream):
        raise CcsdsError(f"{bag_path}: --predict-until predicts a fitted orbit: only laser "
                         f"ranges (`ssa-fusion import crd`) are fitted here")
    try:
        until = parse_utc(until_utc)
        bag = laser_bag(stream)
        fit = laser_run.fit(bag)
    except ValueError as exc:
        raise CcsdsError(str(exc)) from None
    if not (step_s > 0.0 and math.isfinite(step_s)):
        raise CcsdsError(f"--step {step_s!r}: want a number of seconds > 0")
    if until <= fit.t:
        raise CcsdsError(f"--predict-until {until_utc}: not after the fit's epoch, its last "
                         f"range at {iso(fit.t)}")
    n = math.floor((until - fit.t) / step_s) + 1
    if n > MAX_STATES:
        raise CcsdsError(f"--predict-until {until_utc} every {step_s:g} s: {n} states, more "
                         f"than {MAX_STATES}; take a longer --step")
    t = fit.t + np.arange(n) * step_s
    if t[-1] < until:
        t = np.append(t, until)
    x, P = fit.predict(t)
    states = [types.StateEstimate(float(ti), xi, Pi, bag.object_id)
              for ti, xi, Pi in zip(t, x, P, strict=True)]
    sigma = math.sqrt(float(np.trace(P[-1][:3, :3]))) * 1000.0
    return states, (f"the fit of {len(fit.t_meas)} laser ranges ({fit.status}) from its epoch "
                    f"{iso(fit.t)} to {iso(float(t[-1]))}, position sigma at the end "
                    f"{sigma:.2f} m")

"""`ssa-fusion replay` of a laser-ranging bag (`import crd`): the laser filter, no surrogate.

A bag whose measurements are laser ranges is estimated by the filter of its object
(`laser_run.estimator`: the high-fidelity force model, the stations' range biases and k_R
as states, started from the bag's reference orbit's first state), never by the surrogate:
normal points minutes apart in passes hours apart are no stream to learn. Between passes
the filter publishes its own prediction every 300 s (`laser_run.GAPS`).

``--offline``: through the core (`replay.replay_offline`, the meteorological records fed to
the model as they come), with ``--smooth`` the RTS smoother; written as `replay.write_offline`
writes (the laser set-up, meteorological records and reference orbit kept). Printed beside:
the filter's NIS against its 95 % band, and the batch least-squares fit of every range
(`laser_run.fit`: residual RMS, each station's bias with its sigma, Cr).

Over ROS 2: recorder + filter processes, the filter set for laser ranges (`filter_params`),
the bag's ranges and meteorological records played with its clock (`replay_live`).
"""

from __future__ import annotations

import argparse
import sys

import numpy as np

from ssa_fusion.apps import laser_run, replay, replay_laser_live
from ssa_fusion.apps.partial import removed_if_unfinished
from ssa_fusion.core.base import types
from ssa_fusion.core.earth.timescales import iso
from ssa_fusion.core.od.batch_ls import BatchFit
from ssa_fusion.evaluation.laser_scores import nis_coverage
from ssa_fusion.params import settings as node_settings
from ssa_fusion.ros import bagio
from ssa_fusion.ros.laser_bag import laser_bag
from ssa_fusion.ros.topics import TOPIC_CONFIG

__all__ = ["fit_line", "nis_line", "run"]

M = 1000.0
"""m per km."""


def run(args: argparse.Namespace, stream: list[bagio.BagMessage]) -> int:
    """Replay a laser bag (module docstring); return the exit code."""
    try:
        bag = laser_bag(stream)
        c = laser_run.estimator(bag)
        tracker = laser_run.tracker(bag, c)
    except ValueError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    start = laser_run.apriori(bag).t
    print(f"replay: laser ranges of {bag.object_id} from {len(bag.network.ids)} station(s): "
          f"the laser filter ({c.filter.motion.motion_model}, range biases and k_R as states) "
          f"from the reference orbit's state at {iso(start)}")
    if not args.offline:
        return replay_laser_live.run(args, stream, bag, c)
    out = args.out or replay.sibling(args.bag, "_offline")
    if out.exists():
        print(f"error: {out} exists already; choose another --out", file=sys.stderr)
        return 2
    result = replay.replay_offline(stream, c, laser_run.GAPS, args.smooth, tracker)
    used = [m.msg.data for m in stream if m.topic == TOPIC_CONFIG]
    used.append(node_settings.config_message("filter", c, laser_run.GAPS))
    try:
        with removed_if_unfinished(out):
            replay.write_offline(out, stream, result, used)
    except OSError as exc:
        print(f"error: cannot write {out}: {exc}", file=sys.stderr)
        return 2
    print(f"offline replay of {args.bag}: {len(result.estimates)} estimates"
          + (f", {len(result.smoothed)} smoothed" if args.smooth else "") + f" -> {out}")
    print(nis_line([e for _, e in result.estimates]))
    print(fit_line(laser_run.fit(bag, c=c), c.filter.motion.motion_params["cr"]))
    return 0


def nis_line(estimates: list[types.StateEstimate]) -> str:
    """Return the NIS of the fused ranges against the two-sided 95 % band of chi2(1)."""
    c = nis_coverage([e.nis for e in estimates if e.update_source == types.UpdateSource.SENSOR])
    return (f"filter: {c.count} ranges fused, NIS inside its 95 % band [{c.band[0]:.4f}, "
            f"{c.band[1]:.2f}]: {100 * c.inside:.1f} % ({c.below} below, {c.above} above)")


def fit_line(fit: BatchFit, cr_nominal: float) -> str:
    """Return the batch fit's line: status, residual RMS, biases with sigma, Cr."""
    res = np.array([r[0] for r in fit.residuals]) * M * 100.0
    biases = ", ".join(f"{k.removeprefix('bias_')} {v * M * 100:+.1f} +- "
                       f"{fit.sigma(k, realistic=True) * M * 100:.1f} cm"
                       for k, v in fit.measurement_params.items())
    cr = fit.params["srp_scale"] * cr_nominal
    return (f"batch fit: {fit.status} ({fit.iterations} linearisations), residual RMS "
            f"{float(np.sqrt(np.mean(res**2))):.2f} cm over {res.size} ranges "
            f"({int(np.sum(~fit.accepted))} edited); range biases {biases}; Cr {cr:.3f}")

"""`ssa-fusion report BAG` for a laser-ranging bag (`import crd`, replayed or not): no truth.

What a laser-ranging analyst judges an orbit by, each computed here through the core:

* the batch least-squares fit of every range (`laser_run.fit`: the object's high-fidelity
  forces, Cr, a range bias per station): its residuals per station and pass (cm, mean and
  RMS; `evaluation.laser_scores.pass_rows`), each station's bias with its sigma (the
  realistic one), Cr;
* the filter's NIS of each range against the 95 % band of chi-square(1): what the bag's
  filter published (``/ssa/estimate``, a replay's), else the laser filter run here;
* the orbit against the bag's reference (``/ssa/reference``, RTN, m): the fit's at the
  reference's epochs, and the filter's estimates (the smoothed ones when the bag has them)
  at their epochs inside the reference's span.

Printed, and written to ``OUT/report.json`` (``OUT`` = ``BAG_report`` unless ``--out``).
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
from pathlib import Path
from typing import Any

import numpy as np

from ssa_fusion.apps import laser_run
from ssa_fusion.apps.replay import replay_offline
from ssa_fusion.core.base.types import StateEstimate, UpdateSource
from ssa_fusion.core.earth.timescales import iso
from ssa_fusion.evaluation import laser_scores as ls
from ssa_fusion.ros import bagio, messages
from ssa_fusion.ros.laser_bag import LaserBag, laser_bag
from ssa_fusion.ros.topics import TOPIC_ESTIMATE, TOPIC_SMOOTHED

__all__ = ["build", "run", "table"]

CM = 1e5
"""cm per km."""


def run(args: argparse.Namespace, stream: list[bagio.BagMessage], out: Path) -> int:
    """Report on a laser bag (module docstring); return the exit code."""
    try:
        rep = build(laser_bag(stream), stream)
        out.mkdir(parents=True, exist_ok=True)
        (out / "report.json").write_text(json.dumps(rep, indent=1, default=float) + "\n")
    except (ValueError, OSError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    print(f"{args.bag}: laser ranging, no simulated truth: the orbit judged by its residuals, "
          f"its NIS and the reference orbit\n")
    print(table(rep))
    print(f"\nwrote {out}/report.json")
    return 0


def _estimates(stream: list[bagio.BagMessage], topic: str) -> list[StateEstimate]:
    return [messages.estimate_from_msg(m.msg) for m in stream if m.topic == topic]


def _filter_nis(bag: LaserBag, stream: list[bagio.BagMessage]) -> tuple[list[float], str]:
    """Return the NIS of the fused ranges and where they come from."""
    got = [e.nis for e in _estimates(stream, TOPIC_ESTIMATE)
           if e.update_source == UpdateSource.SENSOR]
    if got:
        return got, "the bag's filter (/ssa/estimate)"
    c = laser_run.estimator(bag)
    result = replay_offline(stream, c, laser_run.GAPS, False, laser_run.tracker(bag, c))
    return ([e.nis for _, e in result.estimates if e.update_source == UpdateSource.SENSOR],
            "the laser filter run on the bag's ranges")


def _orbit_rows(bag: LaserBag, stream: list[bagio.BagMessage],
                fit_x: np.ndarray) -> dict[str, Any]:
    """Return the fit's and the filter's orbits against the reference."""
    out: dict[str, Any] = {}
    if not bag.reference_t.size:
        return out
    out["batch fit"] = ls.against_reference(bag.reference_t, fit_x, bag.reference_t,
                                            bag.reference_x)
    smoothed = _estimates(stream, TOPIC_SMOOTHED)
    filtered = [e for e in _estimates(stream, TOPIC_ESTIMATE)
                if e.update_source == UpdateSource.SENSOR]
    for name, es in (("smoothed", smoothed), ("filter (fused)", filtered)):
        if es:
            out[name] = ls.against_reference([e.t for e in es], [e.x for e in es],
                                             bag.reference_t, bag.reference_x)
    return {k: dataclasses.asdict(v) for k, v in out.items()}


def build(bag: LaserBag, stream: list[bagio.BagMessage]) -> dict[str, Any]:
    """Return the report's numbers (module docstring) as a JSON-ready dict."""
    c = laser_run.estimator(bag)
    fit = laser_run.fit(bag, c=c)
    res = np.array([r[0] for r in fit.residuals])
    nis, source = _filter_nis(bag, stream)
    fit_x = fit.predict(bag.reference_t, realistic=False)[0] if bag.reference_t.size else None
    cr = fit.params["srp_scale"] * c.filter.motion.motion_params["cr"]
    return {
        "object": bag.object_id, "ranges": len(bag.measurements),
        "span": [iso(bag.measurements[0].t), iso(bag.measurements[-1].t)],
        "fit": {"status": str(fit.status), "reason": fit.reason,
                "residual_rms_cm": float(np.sqrt(np.mean(res * res))) * CM,
                "edited": int(np.sum(~fit.accepted)), "cr": cr,
                "biases_cm": {k.removeprefix("bias_"): [v * CM, fit.sigma(k, True) * CM]
                              for k, v in fit.measurement_params.items()}},
        "passes": [dataclasses.asdict(p) for p in ls.pass_rows(bag.measurements, res)],
        "nis": {**dataclasses.asdict(ls.nis_coverage(nis)), "source": source},
        "against_reference": _orbit_rows(bag, stream, fit_x) if fit_x is not None else {},
    }


def table(rep: dict[str, Any]) -> str:
    """Return the report as text tables."""
    f = rep["fit"]
    lines = [f"batch fit of {rep['ranges']} ranges of {rep['object']} ({rep['span'][0]} .. "
             f"{rep['span'][1]}): {f['status']}, residual RMS {f['residual_rms_cm']:.2f} cm, "
             f"{f['edited']} edited, Cr {f['cr']:.3f}", "",
             "| station | bias (cm) | sigma (cm) |", "|---|---|---|"]
    lines += [f"| {s} | {b:+.2f} | {sb:.2f} |" for s, (b, sb) in f["biases_cm"].items()]
    lines += ["", "| station | pass (UTC) | ranges | mean (cm) | RMS (cm) |",
              "|---|---|---|---|---|"]
    lines += [f"| {p['station']} | {iso(p['first'])[:16]} .. {iso(p['last'])[11:16]} | "
              f"{p['count']} | {p['mean_cm']:+.2f} | {p['rms_cm']:.2f} |" for p in rep["passes"]]
    n = rep["nis"]
    lines += ["", f"NIS ({n['source']}): {n['count']} ranges, {100 * n['inside']:.1f} % inside "
                  f"[{n['band'][0]:.4f}, {n['band'][1]:.2f}] ({n['below']} below, {n['above']} "
                  f"above), mean {n['mean']:.2f}"]
    if rep["against_reference"]:
        lines += ["", "| orbit - reference | epochs | R (m) | T (m) | N (m) | 3D RMS (m) | "
                      "3D max (m) |", "|---|---|---|---|---|---|---|"]
        lines += [f"| {k} | {d['count']} | {d['rtn_rms_m'][0]:.3f} | {d['rtn_rms_m'][1]:.3f} | "
                  f"{d['rtn_rms_m'][2]:.3f} | {d['rms_3d_m']:.3f} | {d['max_3d_m']:.3f} |"
                  for k, d in rep["against_reference"].items()]
    return "\n".join(lines)

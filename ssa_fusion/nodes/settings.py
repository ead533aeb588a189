"""The estimator settings of the filter and surrogate nodes as ROS parameters, and back.

ROS parameters are in SI units (m, m/s, rad, s; docs/NODES.md); `core.config.EstimatorConfig`
is in the core's (km, km/s). This module is the one translation between the two, used by
the nodes (their declared parameters), by `ssa-fusion live` (the parameters that run a
scenario), by `replay`/`report --params-file` (a ROS params YAML) and for the settings the
nodes record with every bag on ``/ssa/config`` (`config_message`, `recorded_estimator`).
No rclpy here: the apps read params files and bags without ROS.
"""

from __future__ import annotations

import dataclasses
import json
import math
from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import Any

from ssa_fusion.core import config
from ssa_fusion.core.config import EstimatorConfig, Lift, MotionModel
from ssa_fusion.core.surrogate import LIVE_SURROGATE
from ssa_fusion.core.timescales import UNIX_EPOCH_JD
from ssa_fusion.core.tracker import TrackerConfig
from ssa_fusion.core.types import KIND_NAMES, Kind
from ssa_fusion.nodes.defaults import FILTER, SURROGATE

KM = 1000.0
"""m per km."""
FILTER_KEYS = ("kind", "station", "motion_model", "p0_sigma", "q", "gate", "iod_samples",
               "iod_max_span", "reinit_after", "sigma_bound", "light_time", "refraction")
"""The filter's parameters that are estimator settings."""
SURROGATE_KEYS = ("kind", "station", "buffer_length", "retrain_period", "delays", "rank",
                  "max_horizon", "grace", "cadence", "lift")
"""The surrogate's parameters that are estimator settings."""
NODE_MOTION_MODELS = (MotionModel.KEPLER, MotionModel.J2)
"""Motion models the filter node offers (Earth orbits on the Unix clock)."""


def filter_params(c: EstimatorConfig) -> dict[str, Any]:
    """The filter's parameters (SI) for estimator `c`."""
    t = c.tracker
    return {"kind": KIND_NAMES[c.kind], "station": c.station, "motion_model": str(c.motion_model),
            "p0_sigma": [v * KM for v in t.p0_sigma], "q": t.q * KM * KM,
            "gate": t.gate or 0.0, "iod_samples": t.iod_samples,
            "iod_max_span": 0.0 if math.isinf(t.iod_max_span_s) else t.iod_max_span_s,
            "reinit_after": t.reinit_after, "sigma_bound": t.sigma_bound,
            "light_time": c.light_time, "refraction": c.refraction}


def surrogate_params(c: EstimatorConfig) -> dict[str, Any]:
    """The surrogate's parameters (SI) for estimator `c`."""
    s = c.surrogate
    return {"kind": KIND_NAMES[c.kind], "station": c.station, "buffer_length": s.buffer_s,
            "retrain_period": 0.0 if math.isinf(s.retrain_period_s) else s.retrain_period_s,
            "delays": s.delays, "rank": s.rank or 0, "max_horizon": s.max_horizon_s,
            "grace": s.grace, "cadence": s.cadence_s, "lift": str(c.lift)}


def _stream(filt: Mapping[str, Any], surr: Mapping[str, Any], key: str, default: str) -> str:
    values = {str(p[key]) for p in (filt, surr) if key in p}
    if len(values) > 1:
        raise ValueError(f"filter and surrogate disagree on '{key}': {sorted(values)}")
    return values.pop() if values else default


def estimator_from(filt: Mapping[str, Any], surr: Mapping[str, Any]) -> EstimatorConfig:
    """The `EstimatorConfig` of the filter's and the surrogate's parameters (SI); a missing
    parameter takes the node's default (`defaults`), except that `lift` defaults to eci
    only for range/az/el (none for positions and right ascension/declination). ValueError
    names a bad value."""
    f = {**dataclasses.asdict(FILTER), **filt}
    s = {**dataclasses.asdict(SURROGATE), **surr}
    kinds = {name: kind for kind, name in KIND_NAMES.items()}
    kind_name = _stream(filt, surr, "kind", FILTER.kind)
    if kind_name not in kinds:
        raise ValueError(f"kind {kind_name!r} unknown; known: {', '.join(kinds)}")
    motion = str(f.get("motion_model", MotionModel.KEPLER))
    if motion not in NODE_MOTION_MODELS:
        raise ValueError(f"motion_model {motion!r}: must be one of "
                         f"{', '.join(map(str, NODE_MOTION_MODELS))}")
    tracker = TrackerConfig(p0_sigma=tuple(float(v) / KM for v in f["p0_sigma"]),
                            q=float(f["q"]) / (KM * KM), gate=float(f["gate"]) or None,
                            iod_samples=int(f["iod_samples"]),
                            iod_max_span_s=float(f["iod_max_span"]) or math.inf,
                            reinit_after=int(f["reinit_after"]),
                            sigma_bound=float(f["sigma_bound"]))
    surrogate = dataclasses.replace(
        LIVE_SURROGATE, buffer_s=float(s["buffer_length"]),
        retrain_period_s=float(s["retrain_period"]) or math.inf, delays=int(s["delays"]),
        rank=int(s["rank"]) or None, max_horizon_s=float(s["max_horizon"]),
        grace=float(s["grace"]), cadence_s=float(s["cadence"]))
    return EstimatorConfig(kind=kinds[kind_name],
                           station=_stream(filt, surr, "station", FILTER.station),
                           motion_model=MotionModel(motion), jd0=UNIX_EPOCH_JD,
                           light_time=bool(f["light_time"]),
                           refraction=bool(f["refraction"]),
                           lift=Lift(str(s["lift"]) if "lift" in surr
                                     or kind_name == KIND_NAMES[Kind.RANGE_AZ_EL] else Lift.NONE),
                           tracker=tracker, surrogate=surrogate)


DEFAULT_ESTIMATOR = estimator_from({}, {})
"""The estimator the nodes run with every parameter at its default."""


def node_section(params_file: Mapping[str, Any], node: str) -> dict[str, Any]:
    """The ``ros__parameters`` of `node` in a loaded ROS params file: wildcard sections
    (``/**``, ``**``, ``/*``, ``*``) first, then the node's own (``node`` or ``/node``), as
    rcl applies them."""
    out: dict[str, Any] = {}
    for key in ("/**", "**", "/*", "*", node, f"/{node}"):
        section = params_file.get(key)
        if isinstance(section, Mapping):
            out.update(section.get("ros__parameters") or {})
    return out


def load_params_file(path: Path | str) -> EstimatorConfig:
    """The estimator a ROS params YAML (``--ros-args --params-file``'s format) gives the
    filter and the surrogate. ValueError (naming the file) if it cannot be read or holds a
    bad value; parameters that are not estimator settings are ignored."""
    import yaml

    try:
        loaded = yaml.safe_load(Path(path).read_text())
    except (OSError, yaml.YAMLError) as exc:
        raise ValueError(f"cannot read params file {path}: {exc}") from exc
    if not isinstance(loaded, Mapping):
        raise ValueError(f"params file {path}: not a mapping of node names to ros__parameters")
    filt = {k: v for k, v in node_section(loaded, "filter").items() if k in FILTER_KEYS}
    surr = {k: v for k, v in node_section(loaded, "surrogate").items() if k in SURROGATE_KEYS}
    try:
        return estimator_from(filt, surr)
    except (ValueError, TypeError, KeyError) as exc:
        raise ValueError(f"params file {path}: {exc}") from exc


_OWN = {"filter": ("tracker", "motion_model", "motion_params"), "surrogate": ("surrogate", "lift")}
"""The parts of the estimator settings each node owns (and records)."""


def config_message(node: str, c: EstimatorConfig) -> str:
    """The JSON a node publishes on ``/ssa/config``: its part of `c` (core units; the
    measurement stream and what `_OWN` lists for the node)."""
    d = config.to_dict(c)
    other = next(n for n in _OWN if n != node)
    for key in _OWN[other]:
        d.pop(key)
    return json.dumps({"node": node, "estimator": d}, sort_keys=True)


def recorded_estimator(messages: Iterable[str]) -> EstimatorConfig | None:
    """The estimator recorded on ``/ssa/config`` (JSON strings in recording order): the last
    filter's and the last surrogate's message merged; None if there is none. A part
    without its node's message keeps `DEFAULT_ESTIMATOR`'s. ValueError on a malformed one."""
    last: dict[str, dict[str, Any]] = {}
    for text in messages:
        try:
            msg = json.loads(text)
            last[str(msg["node"])] = dict(msg["estimator"])
        except (ValueError, KeyError, TypeError) as exc:
            raise ValueError(f"malformed /ssa/config message {text[:80]!r}: {exc}") from exc
    if not last:
        return None
    merged = {**last.get("surrogate", {}), **last.get("filter", {})}
    if "lift" not in merged and merged.get("kind") == "position":
        merged["lift"] = str(Lift.NONE)
    return config.from_dict(merged, DEFAULT_ESTIMATOR)

"""The estimator settings of the filter and surrogate nodes as ROS parameters, and back.

ROS parameters are in SI units (m, m/s, rad, s; docs/NODES.md);
`core.gaps.estimator.EstimatorConfig` is in the core's (km, km/s). This module is the one
translation between the two (its units by the rows' scales: `units.convert`), used by the
nodes (their declared parameters), by `ssa-fusion live` (the parameters that run a
scenario), by `replay`/`report --params-file` (`params_file`) and for the settings the
nodes record with every bag on ``/ssa/config`` (`config_message`, `recorded_estimator`).
No rclpy here: the apps read params files and bags without ROS.
"""

from __future__ import annotations

import dataclasses
import json
import math
from collections.abc import Iterable, Mapping
from typing import Any

from ssa_fusion.core.base.types import KIND_NAMES, Kind, MotionModel
from ssa_fusion.core.earth.timescales import UNIX_EPOCH_JD
from ssa_fusion.core.filter.options import FilterOptions
from ssa_fusion.core.gaps import estimator as config
from ssa_fusion.core.gaps.estimator import EstimatorConfig, Lift
from ssa_fusion.core.gaps.surrogate import LIVE_SURROGATE
from ssa_fusion.formats.sites import load_stations
from ssa_fusion.params.defaults import CATALOG_FILTER, FILTER, SURROGATE
from ssa_fusion.params.shared import filter_rows
from ssa_fusion.params.units import Units, convert

FILTER_KEYS = ("kind", "station", "sites", "motion_model", "p0_sigma", "q", "gate", "iod_samples",
               "iod_max_span", "reinit_after", "sigma_bound", "light_time", "refraction")
"""The filter's parameters that are estimator settings."""
GAP_KEYS = ("predict_period", "gap_forecast")
"""The filter's parameters that say what it publishes in a gap (`core.gaps.publisher`)."""
SURROGATE_KEYS = ("kind", "station", "sites", "buffer_length", "retrain_period", "delays", "rank",
                  "max_horizon", "grace", "cadence", "lift")
"""The surrogate's parameters that are estimator settings."""
CATALOG_NODE = "catalog_filter"
"""The ``node`` of the catalog filter's ``/ssa/config`` message (`catalog_config_message`)."""
CATALOG_KEYS = ("station", "sites", "motion_model", "p0_sigma", "q", "gate", "iod_samples",
                "iod_max_span", "reinit_after", "sigma_bound", "max_objects", "evict_after",
                "batch_rows", "max_clock_lead", "shards", "shard")
"""The catalog_filter's parameters it records: what its tracks and its estimates depend on
(``batch_period``, the wall time between fusions, does not: `core.catalog.fusion`)."""
NODE_MOTION_MODELS = (MotionModel.KEPLER, MotionModel.J2)
"""Motion models the filter node offers (Earth orbits on the Unix clock)."""
FILTER_ROWS = filter_rows(FILTER, runtime=True, unlimited_span=True)
"""The rows of a filter's settings (the object filter's and the catalog's scale alike)."""


def filter_params(c: EstimatorConfig) -> dict[str, Any]:
    """Return the filter's parameters (SI) for estimator `c`."""
    noise, iod = c.filter.noise, c.filter.iod
    core = {"kind": KIND_NAMES[c.kind], "station": c.station,
            "motion_model": str(c.filter.motion.motion_model),
            "p0_sigma": list(iod.p0_sigma), "q": noise.q,
            "gate": noise.gate or 0.0, "iod_samples": iod.iod_samples,
            "iod_max_span": 0.0 if math.isinf(iod.iod_max_span_s) else iod.iod_max_span_s,
            "reinit_after": iod.reinit_after, "sigma_bound": noise.sigma_bound,
            "light_time": c.light_time, "refraction": c.refraction}
    return convert(FILTER_ROWS, core, Units.SI)


def surrogate_params(c: EstimatorConfig) -> dict[str, Any]:
    """Return the surrogate's parameters (SI) for estimator `c`."""
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


def filter_settings(f: Mapping[str, Any]) -> dict[str, Any]:
    """Return the settings a filter's parameters `f` (SI) give, in core units (km, km/s).

    By the names of `FilterOptions`' fields (its ``with_``); the object filter's and the
    catalog filter's parameters alike (``gate`` 0 and ``iod_max_span`` 0 mean none).
    """
    c = convert(FILTER_ROWS, {k: f[k] for k in ("p0_sigma", "q")}, Units.CORE)
    return {"p0_sigma": tuple(c["p0_sigma"]), "q": c["q"], "gate": float(f["gate"]) or None,
            "iod_samples": int(f["iod_samples"]),
            "iod_max_span_s": float(f["iod_max_span"]) or math.inf,
            "reinit_after": int(f["reinit_after"]), "sigma_bound": float(f["sigma_bound"])}


def filter_options(f: Mapping[str, Any]) -> FilterOptions:
    """Return the `FilterOptions` of a filter's parameters `f` (SI; the catalog's too)."""
    return FilterOptions().with_(motion_model=MotionModel(str(f["motion_model"])),
                                 **filter_settings(f))


def estimator_from(filt: Mapping[str, Any], surr: Mapping[str, Any]) -> EstimatorConfig:
    """Return the `EstimatorConfig` of the filter's and the surrogate's parameters (SI).

    A missing parameter takes the node's default (`defaults`), except that `lift` defaults
    to eci only for range/az/el (none for positions and right ascension/declination).
    ``sites`` is a sites file's path (`formats.sites`; '' = none), read here. ValueError
    names a bad value.
    """
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
    surrogate = dataclasses.replace(
        LIVE_SURROGATE, buffer_s=float(s["buffer_length"]),
        retrain_period_s=float(s["retrain_period"]) or math.inf, delays=int(s["delays"]),
        rank=int(s["rank"]) or None, max_horizon_s=float(s["max_horizon"]),
        grace=float(s["grace"]), cadence_s=float(s["cadence"]))
    return EstimatorConfig(kind=kinds[kind_name],
                           station=_stream(filt, surr, "station", FILTER.station),
                           sites=load_stations(_stream(filt, surr, "sites", FILTER.sites)),
                           jd0=UNIX_EPOCH_JD,
                           light_time=bool(f["light_time"]),
                           refraction=bool(f["refraction"]),
                           lift=Lift(str(s["lift"]) if "lift" in surr
                                     or kind_name == KIND_NAMES[Kind.RANGE_AZ_EL] else Lift.NONE),
                           filter=filter_options(f), surrogate=surrogate)


DEFAULT_ESTIMATOR = estimator_from({}, {})
"""The estimator the nodes run with every parameter at its default."""


def node_estimator(node: str, values: Mapping[str, Any]) -> EstimatorConfig:
    """Return the `EstimatorConfig` of one node's parameters (SI), the other's at their defaults.

    `node` is "filter" (its `FILTER_KEYS` of `values`) or "surrogate" (`SURROGATE_KEYS`).
    ValueError names a bad value.
    """
    if node == "filter":
        return estimator_from({k: values[k] for k in FILTER_KEYS}, {})
    if values.get("kind") == KIND_NAMES[Kind.LASER_RANGE]:
        raise ValueError("the surrogate does not forecast laser ranges (normal points "
                         "minutes apart in passes hours apart: no stream to learn)")
    return estimator_from({}, {k: values[k] for k in SURROGATE_KEYS})


def estimator_problem(node: str, values: Mapping[str, Any]) -> str | None:
    """Return why `node`'s estimator parameters in `values` do not go together, or None.

    The rule of the filter's and the surrogate's parameter tables (`node_estimator`).
    """
    try:
        node_estimator(node, values)
    except ValueError as exc:
        return str(exc)
    return None


_OWN = {"filter": ("tracker", "motion_model", "motion_params"), "surrogate": ("surrogate", "lift")}
"""The parts of the estimator settings each node owns (and records)."""


def config_message(node: str, c: EstimatorConfig,
                   gaps: Mapping[str, Any] | None = None) -> str:
    """Return the JSON a node publishes on ``/ssa/config``.

    Its part of `c` (core units; the measurement stream and what `_OWN` lists for the
    node), and the filter's `gaps` parameters (`GAP_KEYS`: what it publishes in a gap,
    which a replay repeats).
    """
    d = config.to_dict(c)
    other = next(n for n in _OWN if n != node)
    for key in _OWN[other]:
        d.pop(key)
    msg: dict[str, Any] = {"node": node, "estimator": d}
    if gaps is not None:
        msg["gaps"] = dict(gaps)
    return json.dumps(msg, sort_keys=True)


def catalog_config_message(values: Mapping[str, Any]) -> str:
    """Return the JSON the catalog_filter publishes on ``/ssa/config``.

    ``{"node": "catalog_filter", "parameters": ...}``: its `CATALOG_KEYS` parameters of
    `values` (SI units, as declared), from which `catalog_parameters` gives them back.
    """
    params = {k: list(v) if isinstance(v, (tuple, list)) else v
              for k, v in values.items() if k in CATALOG_KEYS}
    return json.dumps({"node": CATALOG_NODE, "parameters": params}, sort_keys=True)


def recorded_catalog(messages: Iterable[str]) -> list[dict[str, Any]]:
    """Return the catalog_filter parameters recorded on ``/ssa/config``, one per shard.

    From the `catalog_config_message` of each shard (the last of a shard), in shard order;
    a missing parameter at its default (`defaults.CATALOG_FILTER`). Empty when no
    catalog_filter recorded its settings. ValueError on a malformed message.
    """
    shards: dict[int, dict[str, Any]] = {}
    for text in messages:
        try:
            msg = json.loads(text)
            if msg["node"] == CATALOG_NODE:
                params = {**dataclasses.asdict(CATALOG_FILTER), **dict(msg["parameters"])}
                shards[int(params["shard"])] = params
        except (ValueError, KeyError, TypeError) as exc:
            raise ValueError(f"malformed /ssa/config message {text[:80]!r}: {exc}") from exc
    return [shards[k] for k in sorted(shards)]


def recorded_gaps(messages: Iterable[str]) -> dict[str, Any]:
    """Return the filter's `GAP_KEYS` parameters recorded on ``/ssa/config``.

    Those of its last message that has them, else the filter's defaults (bags recorded
    before they were recorded). ValueError on a malformed message.
    """
    gaps = gap_params(dataclasses.asdict(FILTER))
    for text in messages:
        try:
            msg = json.loads(text)
            if msg["node"] == "filter" and "gaps" in msg:
                gaps = {k: msg["gaps"][k] for k in GAP_KEYS}
        except (ValueError, KeyError, TypeError) as exc:
            raise ValueError(f"malformed /ssa/config message {text[:80]!r}: {exc}") from exc
    return gaps


def gap_params(values: Mapping[str, Any]) -> dict[str, Any]:
    """Return the `GAP_KEYS` of a filter's parameter `values`."""
    return {k: values[k] for k in GAP_KEYS}


def recorded_estimator(messages: Iterable[str]) -> EstimatorConfig | None:
    """Return the estimator recorded on ``/ssa/config`` (JSON strings in recording order).

    The last filter's and the last surrogate's message merged; None if there is none. A
    part without its node's message keeps `DEFAULT_ESTIMATOR`'s. ValueError on a malformed
    one.
    """
    last: dict[str, dict[str, Any]] = {}
    for text in messages:
        try:
            msg = json.loads(text)
            if msg["node"] == CATALOG_NODE or "estimator" not in msg:
                continue  # the catalog's (`recorded_catalog`), an importer's (no estimator)
            last[str(msg["node"])] = dict(msg["estimator"])
        except (ValueError, KeyError, TypeError) as exc:
            raise ValueError(f"malformed /ssa/config message {text[:80]!r}: {exc}") from exc
    if not last:
        return None
    merged = {**last.get("surrogate", {}), **last.get("filter", {})}
    if "lift" not in merged and merged.get("kind") == "position":
        merged["lift"] = str(Lift.NONE)
    return config.from_dict(merged, DEFAULT_ESTIMATOR)

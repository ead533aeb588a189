"""What runs together: the nodes of a graph, their names and their parameters.

One place for the processes `ssa-fusion live` starts and the launch files start (`ros2
launch ssa_fusion ssa_fusion.launch.py`, `catalog.launch.py`): the single-object graph of a
scenario (`node_parameters`: sensor_sim, surrogate, filter, recorder) and a catalog's graph
(`catalog_graph`: recorder, filter and surrogate shards, sensor_sim). Parameters are in SI
units, as the nodes declare them (`params.settings` translates the estimator's settings).

It knows the simulated world (`sim`) for the scenarios' settings and the nodes' settings;
the apps and the launch files import it, nothing below them does.
"""

from __future__ import annotations

import math
import time
from pathlib import Path
from typing import Any, NamedTuple

from ssa_fusion.core.earth import timescales
from ssa_fusion.core.gaps.publisher import GapFill
from ssa_fusion.formats.element_sets import Progress
from ssa_fusion.params import settings
from ssa_fusion.params.defaults import BAG_PATTERN
from ssa_fusion.ros.readiness import LOCKSTEP_READERS, OUTPUT, READERS
from ssa_fusion.ros.topics import (
    TOPIC_ASSOCIATED,
    TOPIC_CONJUNCTIONS,
    TOPIC_DETECTION_TRUTH,
    TOPIC_ESTIMATE_BATCH,
    TOPIC_MEASUREMENT_BATCH,
)
from ssa_fusion.sim import scenarios, sky

LIVE_SCENARIOS = [*(n for n, s in scenarios.SCENARIOS.items() if s.is_orbit), *sky.SKY_SCENARIOS]
"""The paper's orbit scenarios and the real-sky ones (`sim.sky`)."""
WAIT_FOR = ["/ssa/measurement=3", "/ssa/forecast=2", "/ssa/estimate=1", "/ssa/truth=1",
            "/ssa/withheld=1", "/clock=3"]
"""What sensor_sim waits for before it starts: every node's subscriptions."""
OBJECT_LOCKSTEP = ["filter", "surrogate", "recorder"]
"""The consumers one object's simulator waits for in lockstep."""


def sim_seconds(s: scenarios.Scenario | sky.SkyScenario) -> float:
    """Sim time the scenario runs, s."""
    if isinstance(s, sky.SkyScenario):
        return s.duration_s
    return s.track_s + s.gap_s + s.after_s


def object_name(s: scenarios.Scenario | sky.SkyScenario) -> str:
    """Return the ``object_id`` of the scenario's object: its own name where it has one.

    An element set's object is named by its name line or ``OBJECT_NAME`` (its catalogue
    number without one); a scenario's own object by the scenario's name.
    """
    entry = s.element_set if isinstance(s, sky.SkyScenario) else None
    if entry is None:
        return s.name
    return entry.name.strip() or entry.object_id


def node_parameters(s: scenarios.Scenario | sky.SkyScenario, time_scale: float, seed: int,
                    bag: Path, geometry_seed: int = -1, *,
                    lockstep: bool = True) -> dict[str, dict[str, Any]]:
    """Per-node parameters (SI units) that run scenario `s` live.

    In lockstep (`nodes.kit.progress`: sim time waits for the filter, the surrogate and
    the recorder; `time_scale` is a ceiling) unless `lockstep` is False (open loop: sim time
    follows the wall clock). `geometry_seed`: a real-sky object's orbit turned as that
    case's (`sky.case_geometry`; -1: its own).
    """
    sensor: dict[str, Any] = {"scenario": s.name, "object_id": object_name(s),
                              "time_scale": time_scale, "seed": seed, "wait_for": WAIT_FOR,
                              "wait_for_readers": READERS + (LOCKSTEP_READERS if lockstep
                                                             else []),
                              "lockstep": OBJECT_LOCKSTEP if lockstep else [""]}
    if isinstance(s, sky.SkyScenario):  # the truth's cadence; the filter publishes at it
        sensor.update({"cadence": s.truth_cadence_s, "start": timescales.iso(s.t0),
                       "duration": s.duration_s, "truth": str(s.truth),
                       "geometry_seed": geometry_seed})
        extra = {"predict_period": s.truth_cadence_s, "gap_forecast": str(s.gap_fill)}
    else:
        sensor.update({"cadence": s.cadence_s, "gap_start": s.track_s, "gap_length": s.gap_s,
                       "after_gap": s.after_s})
        extra = {}
    estimator = s.estimator()
    surrogate = {"use_sim_time": True, **settings.surrogate_params(estimator),
                 "lockstep": lockstep}
    filt = {"use_sim_time": True, **settings.filter_params(estimator), **extra,
            "lockstep": lockstep}
    if isinstance(s, sky.SkyScenario) and s.sites_file:  # stations of a sites file
        for node in (sensor, surrogate, filt):
            node["sites"] = s.sites_file
    if isinstance(s, sky.SkyScenario) and s.elements_file:  # the object of an element set
        sensor["elements"] = s.elements_file
    recorder = {"use_sim_time": True, "bag": str(bag)}
    return {"sensor_sim": sensor, "surrogate": surrogate, "filter": filt, "recorder": recorder}


def default_bag() -> str:
    """Return a recorder output directory named like ``ros2 bag record``'s (`BAG_PATTERN`, now)."""
    return time.strftime(BAG_PATTERN)


def catalog_scenario(name: str) -> sky.SkyScenario:
    """Return the real-sky scenario `name`, whose radars observe a catalog.

    Raises ValueError naming the real-sky scenarios with radars when `name` is not one.
    """
    scenario = sky.SKY_SCENARIOS.get(name)
    if scenario is None or not scenario.radars:
        radar = [n for n, s in sky.SKY_SCENARIOS.items() if s.radars]
        raise ValueError(f"scenario {name!r} is not a real-sky scenario with radars; known: "
                         f"{', '.join(radar)}")
    return scenario


def live_scenario(name: str, start: str = "", duration_h: float = 0.0, sites: str = "",
                  elements: str = "", progress: Progress | None = None
                  ) -> scenarios.Scenario | sky.SkyScenario:
    """Return the scenario `name` of `LIVE_SCENARIOS` from `start` for `duration_h`.

    `sites`: a sites file whose sites observe a real-sky scenario's object instead of its
    sensors ('' = its own; `sky.SkyScenario.with_sites`). `elements`: an element set file
    whose first object they observe instead ('' = the scenario's; `with_elements`: from
    its epoch unless `start`; `progress`: of reading it, `formats.element_sets.read_catalog`'s).

    `start`: ISO 8601 UTC ('' = the scenario's epoch); a real-sky scenario's object starts
    from its initial GCRF state at it (`sky.SkyScenario.t0`). `duration_h`: hours of sim
    time (0 = the scenario's); a paper scenario keeps its tracking and gap and tracks after
    the gap for the rest. ValueError with one line: an unknown name, a bad epoch, a start
    for a paper scenario (it keeps the paper's epoch), a paper scenario shorter than its
    tracking and gap.
    """
    if name not in LIVE_SCENARIOS:
        raise ValueError(f"scenario {name!r} unknown; known: {', '.join(LIVE_SCENARIOS)}")
    if not (math.isfinite(duration_h) and duration_h >= 0.0):
        raise ValueError(f"--duration {duration_h!r}: hours of sim time, a number >= 0")
    real_sky = sky.SKY_SCENARIOS.get(name)
    if real_sky is not None:
        if elements:
            real_sky = real_sky.with_elements(elements, progress)
        t0 = timescales.parse_utc(start) if start else real_sky.t0
        real_sky = real_sky.with_window(t0, duration_h * 3600.0 or real_sky.duration_s)
        return real_sky.with_sites(sites) if sites else real_sky
    paper = scenarios.get(name)
    if sites or elements:
        raise ValueError(f"--sites and --elements apply to the real-sky scenarios "
                         f"({', '.join(sky.SKY_SCENARIOS)}); {name} keeps the paper's station")
    if start:
        raise ValueError(f"--start applies to the real-sky scenarios "
                         f"({', '.join(sky.SKY_SCENARIOS)}) and catalogs; {name} keeps the "
                         "paper's epoch")
    if not duration_h:
        return paper
    after = duration_h * 3600.0 - paper.track_s - paper.gap_s
    if after <= 0.0:
        raise ValueError(f"--duration {duration_h:g} h: {name} tracks {paper.track_s:g} s, then "
                         f"has a gap of {paper.gap_s:g} s; its duration must exceed "
                         f"{(paper.track_s + paper.gap_s) / 3600:g} h")
    return paper.with_(after_s=after)


DEFAULT_SCENARIO = "iss_network"
"""Whose radars observe a catalog when `--scenario` is not a real-sky scenario."""


def node_names(shards: int, node: str = "catalog_filter") -> list[str]:
    """Return the node names of `shards` shards of `node`: node_0, node_1, ..."""
    return [f"{node}_{k}" for k in range(shards)]


class NodeSpec(NamedTuple):
    """One process of a catalog graph: executable, node name, parameters."""

    executable: str
    name: str
    params: dict[str, Any]


MAX_TIME_SCALE = 1e9
"""The time scale of ``--time-scale max`` (a catalog in lockstep as fast as its slowest
consumer): sim time a billion times faster than the wall clock is no ceiling at all."""


def catalog_graph(scenario: sky.SkyScenario, catalog: Path, objects: int, synthetic: int,
                  sim_s: float, time_scale: float, seed: int, shards: int, surrogate: bool,
                  surrogate_extra: dict[str, Any], bag: Path | None,
                  start: str = "", lockstep: bool = True,
                  unlabelled: bool = False,
                  conjunctions: Path | None = None) -> list[NodeSpec]:
    """Return the processes of a catalog run, in start order.

    The recorder (`bag`, None: its default), `shards` catalog_filter and, with `surrogate`,
    as many catalog_surrogate (`surrogate_extra` over their defaults), and sensor_sim
    simulating `scenario`'s radars measuring the catalog for `sim_s` from `start` (ISO 8601
    UTC; '' = the catalog's first epoch) (last: it waits for the others), in lockstep with
    the shards and the recorder (`nodes.kit.progress`; `time_scale` a ceiling) unless
    `lockstep` is False (open loop: sim time follows the wall clock). Measurements and
    estimates go as batches (``/ssa/measurement_batch``, ``/ssa/estimate_batch``), one
    measurement batch per shard per step. In lockstep the surrogates fit every gap
    (``fit_budget`` 0 unless `surrogate_extra` says otherwise). The same for
    `ssa-fusion live --catalog` and `ros2 launch ssa_fusion catalog.launch.py`. With
    `unlabelled`, the measurements go without object ids (the truth on
    ``/ssa/detection_truth``) and the one filter shard associates them, publishing what it
    associated on ``/ssa/measurement_associated``: the recorder hears both. ValueError
    with one line for a `start` that is not an epoch ssa_fusion represents, or for
    `unlabelled` with several `shards` (detections without ids have no shard to go to).
    With `conjunctions` (a directory: its CDMs), the conjunction node re-screens the
    shards' estimates (in the lockstep; the recorder hears its ``/ssa/conjunctions``).
    """
    if start:
        timescales.parse_utc(start)
    if unlabelled and shards != 1:
        raise ValueError(f"unlabelled detections need one filter shard, not {shards}: they "
                         "carry no object id to route them by")
    names = node_names(shards)
    gaps = node_names(shards, "catalog_surrogate") if surrogate else []
    # surrogates that fit the measurements hear them from the first, as the shards do
    fitting = gaps if surrogate_extra.get("gap_forecast") == str(GapFill.BATCH_FIT) else []
    # the recorder hears every estimate publisher (shards and surrogates) from the first
    readers = ["recorder:" + TOPIC_MEASUREMENT_BATCH,
               f"recorder:{TOPIC_ESTIMATE_BATCH}={len(names) + len(gaps)}",
               *(f"{n}:{TOPIC_MEASUREMENT_BATCH}" for n in [*names, *fitting]),
               # every surrogate hears every estimate publisher (its own too) from the first
               *(f"{n}:{TOPIC_ESTIMATE_BATCH}={len(names) + len(gaps)}" for n in gaps),
               # and their side of it: the recorder and every surrogate hear each of them
               *(f"{n}:{OUTPUT}{TOPIC_ESTIMATE_BATCH}={1 + len(gaps)}" for n in [*names, *gaps])]
    watch = ["conjunction"] if conjunctions is not None else []
    readers += [*(f"{n}:{TOPIC_ESTIMATE_BATCH}={len(names) + len(gaps)}" for n in watch),
                *(f"{n}:{OUTPUT}{TOPIC_CONJUNCTIONS}" for n in watch)]
    if unlabelled:
        readers += [f"recorder:{TOPIC_DETECTION_TRUTH}", f"recorder:{TOPIC_ASSOCIATED}={shards}",
                    *(f"{n}:{OUTPUT}{TOPIC_ASSOCIATED}" for n in names)]
    recorder: dict[str, Any] = {"use_sim_time": True}
    if bag is not None:
        recorder["bag"] = str(bag)
    station = ",".join(st.station.name for st in scenario.radars)
    # lockstep waits for the fits: every gap fitted, whatever the machine (`core.catalog.gap_bank`)
    budget = {"fit_budget": 0.0} if lockstep else {}
    own = {"sites": scenario.sites_file} if scenario.sites_file else {}  # radars of a file
    return [
        NodeSpec("recorder", "recorder", recorder),
        *(NodeSpec("catalog_filter", n, {"use_sim_time": True, "shards": shards, "shard": k,
                                         "station": station, **own})
          for k, n in enumerate(names)),
        *(NodeSpec("catalog_surrogate", n, {**budget, "station": station, **own,
                                            **surrogate_extra, "use_sim_time": True,
                                            "shards": shards, "shard": k})
          for k, n in enumerate(gaps)),
        *(NodeSpec("conjunction", n, {"use_sim_time": True, "cdm_dir": str(conjunctions)})
          for n in watch),
        NodeSpec("sensor_sim", "sensor_sim", {
            "scenario": scenario.name, "catalog": str(Path(catalog).resolve()),
            "objects": objects, "synthetic": synthetic, "duration": float(sim_s),
            "time_scale": min(float(time_scale), MAX_TIME_SCALE), "seed": seed,
            "start": start, **own, "shards": shards, "unlabelled": unlabelled,
            "lockstep": [*names, *gaps, *watch, "recorder"] if lockstep else [""],
            "wait_for": [f"{TOPIC_MEASUREMENT_BATCH}={shards + 1}",
                         f"{TOPIC_ESTIMATE_BATCH}={len(gaps) + 1}"],
            "wait_for_readers": readers}),
    ]

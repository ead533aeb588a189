"""The sensor_sim's parameters (docs/NODES.md, "sensor_sim", says more of each).

The scenarios it takes, and their defaults of the computed parameters, come from
`params.scenarios` (the parameters do not import the simulated world).
"""

from __future__ import annotations

from ssa_fusion.core.earth import timescales
from ssa_fusion.core.measure.validation import MAX_CLOCK_LEAD_S
from ssa_fusion.formats import element_sets
from ssa_fusion.params import scenarios
from ssa_fusion.params.checks import (
    NON_NEGATIVE,
    POSITIVE,
    SITES,
    Check,
    ParamValue,
    Values,
    all_non_negative,
    at_least,
    check_needs,
    one_of,
    read_by,
)
from ssa_fusion.params.defaults import SENSOR_SIM
from ssa_fusion.params.rows import Computed, Param, ParameterTable, Rule


def _cadence(values: Values) -> float:
    """Return the chosen scenario's cadence (real sky: of its truth samples), s."""
    return scenarios.cadence(str(values["scenario"]))


def _from_scenario(field: str) -> Computed:
    """Return the default of a paper scenario's `field` (s; a real-sky one: the default's)."""
    def compute(values: Values) -> float:
        return float(getattr(scenarios.timing(str(values["scenario"])), field))

    default = float(getattr(scenarios.timing(SENSOR_SIM.scenario), field))
    return Computed(compute, f"the scenario's ({default:g})", default)


def _gaps(value: ParamValue) -> str | None:
    if not isinstance(value, list) or value == [0.0]:
        return None
    if len(value) % 2:
        return "needs pairs [start_s, length_s, ...]"
    if not all_non_negative(value):
        return "starts and lengths must be finite numbers >= 0"
    return None


def _noise(value: ParamValue) -> str | None:
    if value == [-1.0] or (isinstance(value, list) and len(value) == 3
                           and all_non_negative(value)):
        return None
    return "needs 3 values, each a finite number >= 0 (or [-1.0])"


def _wait(value: ParamValue) -> str | None:
    assert isinstance(value, list)
    for item in value:
        topic, _, count = str(item).partition("=")
        if item and (not topic.startswith("/") or not count.isdigit()):
            return f"{item!r} is not '/topic=count'"
    return None


def _readers(value: ParamValue) -> str | None:
    assert isinstance(value, list)
    return check_needs([str(x) for x in value if x])


def _needs_sky(name: str, why: str) -> Rule:
    """Return the rule that parameter `name`, when set, needs a real-sky `scenario` (`why`)."""
    def test(values: Values) -> str | None:
        if values[name] and values["scenario"] not in scenarios.SKY_SCENARIOS:
            return (f"needs a real-sky scenario ({why}); known: "
                    f"{list(scenarios.SKY_SCENARIOS)}")
        return None

    return Rule((name, "scenario"), test)


def _one_object_or_a_catalog(values: Values) -> str | None:
    if values["elements"] and values["catalog"]:
        return "one object or a catalog: not both (`catalog` simulates every object)"
    return None


def _step(value: ParamValue) -> str | None:
    ok = isinstance(value, float) and 0.0 < value <= MAX_CLOCK_LEAD_S / 2
    return None if ok else f"must be in (0, {MAX_CLOCK_LEAD_S / 2:g}]"


def _unlabelled_needs_a_catalog_of_one_shard(values: Values) -> str | None:
    if not values["unlabelled"]:
        return None
    if not values["catalog"]:
        return "unlabelled detections are a catalog's (`catalog`)"
    if values["shards"] != 1:
        return ("unlabelled detections carry no object id to route them by: one filter "
                "shard takes them all (`shards` 1)")
    return None


DEFAULT_CADENCE = scenarios.cadence(SENSOR_SIM.scenario)
"""The default scenario's cadence, s."""

_SCENARIO_ROWS = (
    Param("scenario", SENSOR_SIM.scenario,
          "orbit scenario (truth model, orbit, measurement kind, noise): a paper one (see "
          "`sim/scenarios.py`) or a real-sky one (`sim/sky.py`)",
          check=one_of(*scenarios.NAMES)),
    Param("object_id", Computed(lambda v: str(v["scenario"]),
                                f"the scenario's name (`{SENSOR_SIM.scenario}`)",
                                SENSOR_SIM.scenario),
          "object id put in every message"),
    Param("cadence", Computed(_cadence, f"the scenario's ({DEFAULT_CADENCE:g}; real sky: its "
                                        "truth cadence)", DEFAULT_CADENCE),
          "time between measurements (real sky: between truth samples)", unit="s",
          check=POSITIVE),
    Param("duration", SENSOR_SIM.duration,
          "real-sky scenarios and catalogs: sim time to run (a scenario's outages keep "
          "their place in the run: `sky.SkyScenario.with_window`); 0 = the scenario's (3 days)",
          unit="s", check=NON_NEGATIVE),
    Param("start", SENSOR_SIM.start,
          "real-sky scenarios and catalogs: the first epoch, ISO 8601 UTC (e.g. "
          "`2025-06-01T00:00:00Z`); '' = the scenario's epoch (a catalog: its first element "
          "set's)",
          check=Check("ISO 8601 UTC, 1972..2038", read_by(timescales.parse_utc, empty_ok=True))),
    Param("sites", SENSOR_SIM.sites,
          "real-sky scenarios: a sites file (YAML, docs/SITES.md) whose sites observe the "
          "object instead of the scenario's sensors; '' = the scenario's", check=SITES),
    Param("elements", SENSOR_SIM.elements,
          "real-sky scenarios: an element set file (TLE, 3LE, OMM XML/CSV) whose first object "
          "the scenario's sensors observe instead of the scenario's; '' = the scenario's",
          check=Check("'' or a readable element set file",
                      read_by(element_sets.read_catalog, empty_ok=True))),
    Param("truth", SENSOR_SIM.truth,
          "real-sky scenarios: the object's truth, `sgp4` (SGP4 with the scenario's B*) or "
          "`high_fidelity` (`sim/world.py`: EGM96 20 x 20, Sun, Moon, SRP, NRLMSISE-00 drag "
          "under space weather drawn from `seed`)",
          check=one_of(*scenarios.TRUTHS)),
    Param("geometry_seed", SENSOR_SIM.geometry_seed,
          "real-sky scenarios: turn the object's orbit plane and phase as the benchmarks' "
          "case of this seed does (`sky.case_geometry`); -1 = the scenario's own orbit",
          check=at_least(-1)),
)
"""The rows that choose what is simulated."""

_SCHEDULE_ROWS = (
    Param("gap_start", _from_scenario("track_s"),
          "tracking before the gap, from the first epoch; ignored when `gaps` is set",
          unit="s", check=NON_NEGATIVE),
    Param("gap_length", _from_scenario("gap_s"), "length of the sensor outage", unit="s",
          check=NON_NEGATIVE),
    Param("gaps", SENSOR_SIM.gaps, "outages as pairs `[start, length, start, length, …]` "
          "after the first epoch; `[0.0]` = one gap from `gap_start`/`gap_length`", unit="s",
          check=Check("pairs, each ≥ 0", _gaps)),
    Param("after_gap", _from_scenario("after_s"), "tracking after the (last) gap", unit="s",
          check=NON_NEGATIVE),
    Param("noise_sigma", SENSOR_SIM.noise_sigma,
          "measurement noise standard deviation per channel; `[-1.0]` = the scenario's noise "
          "(iss_j2_rae: 1000 m, 0.01 rad, 0.01 rad)",
          unit="m (position); m, rad, rad (range/az/el)",
          check=Check("3 values, each ≥ 0", _noise)),
    Param("time_scale", SENSOR_SIM.time_scale, "simulation speed", unit="sim s per wall s",
          check=POSITIVE),
    Param("seed", SENSOR_SIM.seed, "noise random seed"),
    Param("wait_for", SENSOR_SIM.wait_for, "start only when each `/topic=count` has that "
          "many subscribers (e.g. `/ssa/measurement=3`); `[\"\"]` = none",
          check=Check("`/topic=count` entries", _wait)),
    Param("wait_for_readers", SENSOR_SIM.wait_for_readers,
          "start only when each `node:/topic[=count]` reports that many matched publishers on "
          "`/diagnostics`, each `node:>/topic[=count]` that many readers of its output; "
          "`[\"\"]` = none", check=Check("`node:[>]/topic[=count]` entries", _readers)),
    Param("tick", SENSOR_SIM.tick, "period of the publication timer", unit="wall s",
          check=POSITIVE),
)
"""The rows of one object's schedule and of the start."""

_CATALOG_ROWS = (
    Param("catalog", SENSOR_SIM.catalog,
          "element sets (TLE, 3LE, OMM XML/CSV) of the objects to simulate instead of the "
          "scenario's one object, observed by the real-sky `scenario`'s radars; '' = off"),
    Param("objects", SENSOR_SIM.objects, "catalog: only the first N objects (0 = all)",
          check=at_least(0)),
    Param("synthetic", SENSOR_SIM.synthetic,
          "catalog: spread its first element set into N objects of the same regime "
          "(`survey.synthetic_catalog`, seeded by `seed`; 0 = the catalog's own)",
          check=at_least(0)),
    Param("shards", SENSOR_SIM.shards,
          "catalog: the measurements of a step (or tick) go out as this many batches, one "
          "per shard key range, each for one filter shard", check=at_least(1)),
    Param("lockstep", SENSOR_SIM.lockstep,
          "the consumers (node names) sim time waits for, each to take all it was sent, as "
          "long as it lives (a catalog: steps of `lockstep_step`; one object: epoch to "
          "epoch); `[\"\"]` = open loop"),
    Param("lockstep_step", SENSOR_SIM.lockstep_step,
          "a catalog's lockstep: sim time per step (its measurements run ahead of the clock "
          "by up to this: keep it below the consumers' `max_clock_lead`)", unit="s",
          check=Check(f"in (0, {MAX_CLOCK_LEAD_S / 2:g}]", _step)),
    Param("batch_rows", SENSOR_SIM.batch_rows,
          "a catalog's measurements go in batches of at most this many rows (a shard's step "
          "is split: DDS keeps buffers as large as the largest message)",
          check=at_least(1)),
    Param("unlabelled", SENSOR_SIM.unlabelled,
          "catalog: publish each scan's detections without object ids, as a radar reports "
          "them; their true ids go to `/ssa/detection_truth` (evaluation only); needs "
          "`shards` 1"),
)
"""The rows of a catalog's run."""

PARAMETERS = ParameterTable("sensor_sim", (*_SCENARIO_ROWS, *_SCHEDULE_ROWS, *_CATALOG_ROWS),
                            rules=(Rule(("unlabelled", "catalog", "shards"),
                                        _unlabelled_needs_a_catalog_of_one_shard),
                                   _needs_sky("catalog", "its radars observe the catalog"),
                                   _needs_sky("start", "a paper scenario keeps the paper's "
                                                       "epoch"),
                                   _needs_sky("sites", "its object is what the sites observe"),
                                   _needs_sky("elements", "its sensors observe the object"),
                                   Rule(("elements", "catalog"), _one_object_or_a_catalog)))
"""The sensor_sim's parameters."""

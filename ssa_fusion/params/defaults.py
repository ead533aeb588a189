"""Default parameter values of the nodes, one dataclass per node.

In the parameters' units (SI: m, m/s, rad, s; each node's parameter table in
`ssa_fusion.params.tables`, and docs/NODES.md, say what each means). Every field is named
like the ROS parameter it is the default of, and the nodes declare their parameters with
these values; ``config/default.yaml`` holds the same values (a few differ on purpose, for
the default *run*: test/nodes/test_config.py lists them and keeps the rest equal). The
estimator defaults are those of the default live scenario (the ISS, two-body + J2,
range/az/el from Columbus every 30 s, ten orbits of tracking): the same numbers `ssa-fusion
live` derives from that scenario (the same test checks it), written out here so that the
parameters need nothing from the simulated world (`ssa_fusion.sim`).

A field whose default is ``None`` is computed when the node starts (said per field).
Plain values, and the core's where the core has them in a module this one may import
without weight (every node imports them anyway): the catalog filter's are the real-sky
filter (`filter_options.SKY_FILTER`, which the real-sky scenarios run too) in SI, the gate
`filter_options.DEFAULT_GATE`, the clock lead `validation.MAX_CLOCK_LEAD_S`. Other core
defaults written here (`surrogate.LIVE_SURROGATE.grace`) are checked against them by the
test.
"""

from __future__ import annotations

from dataclasses import dataclass

from ssa_fusion.core.earth.timescales import DAY_S
from ssa_fusion.core.filter.options import DEFAULT_GATE, SKY_FILTER
from ssa_fusion.core.measure.validation import MAX_CLOCK_LEAD_S, MAX_OBJECTS

KM = 1000.0
"""m per km: the parameters' SI against the core's km (the scale of their rows: `units`)."""


def _si(value: float) -> float:
    """Return a value converted to SI as a default is written: to 15 significant digits.

    The conversion's last bit is no digit of the parameter (1e-13 km²/s³ x 1e6 is
    1.0000000000000001e-07 m²/s³; the parameter is 1e-07, as it would be given).
    """
    return float(f"{value:.15g}")

KIND = "range_az_el"
"""Measurement kind filter and surrogate expect (``position`` | ``range_az_el`` | ``ra_dec``)."""
STATION = "columbus"
"""Station (a `core.earth.stations.STATIONS` id) of their range/az/el measurements, or a network.

``sites`` (a sites file, `formats.sites`) adds stations of one's own; '' = none."""


@dataclass(frozen=True)
class SensorSimDefaults:
    """sensor_sim's defaults.

    ``object_id``, ``cadence``, ``gap_start``, ``gap_length`` and ``after_gap`` default to
    the chosen scenario's (its name; cadence_s, track_s, gap_s, after_s), so they are None
    here.
    """

    scenario: str = "iss_j2_rae"
    object_id: str | None = None
    cadence: float | None = None
    gap_start: float | None = None
    gap_length: float | None = None
    gaps: tuple[float, ...] = (0.0,)
    after_gap: float | None = None
    duration: float = 0.0
    start: str = ""
    sites: str = ""
    elements: str = ""
    truth: str = "sgp4"
    geometry_seed: int = -1
    noise_sigma: tuple[float, ...] = (-1.0,)
    time_scale: float = 100.0
    seed: int = 0
    wait_for: tuple[str, ...] = ("",)
    wait_for_readers: tuple[str, ...] = ("",)
    tick: float = 0.01
    catalog: str = ""
    objects: int = 0
    synthetic: int = 0
    shards: int = 1
    lockstep: tuple[str, ...] = ("",)
    lockstep_step: float = 300.0
    batch_rows: int = 20_000
    unlabelled: bool = False


@dataclass(frozen=True)
class SurrogateDefaults:
    """surrogate's defaults: the Hankel-DMD settings of the default scenario.

    Buffer = its ten-orbit tracking window, delays = two orbits of samples.
    """

    kind: str = KIND
    station: str = STATION
    sites: str = ""
    buffer_length: float = 55770.0
    retrain_period: float = 0.0
    delays: int = 2 * 186  # two orbits of 30 s samples (186 an orbit)
    rank: int = 0
    max_horizon: float = 7200.0
    grace: float = 2.0
    cadence: float = 0.0
    lift: str = "eci"
    check_period: float = 0.02
    object_id: str = ""
    max_clock_lead: float = MAX_CLOCK_LEAD_S
    lockstep: bool = False


@dataclass(frozen=True)
class FilterDefaults:
    """filter's defaults: the EKF settings of the default scenario.

    P0 floor 1 km and 1 m/s per axis, q = 1e-7 km^2/s^3 for the J2 the Keplerian model
    leaves out.
    """

    kind: str = KIND
    station: str = STATION
    sites: str = ""
    motion_model: str = "kepler"
    p0_sigma: tuple[float, ...] = (1000.0, 1000.0, 1000.0, 1.0, 1.0, 1.0)
    q: float = 0.1
    gate: float = DEFAULT_GATE
    object_id: str = ""
    iod_samples: int = 3
    iod_max_span: float = 0.0
    reinit_after: int = 0
    sigma_bound: float = 0.0
    light_time: bool = False
    refraction: bool = False
    predict_period: float = 300.0
    max_clock_lead: float = MAX_CLOCK_LEAD_S
    gap_forecast: str = "none"
    laser: str = ""
    apriori: tuple[float, ...] = (0.0,) * 7
    lockstep: bool = False


@dataclass(frozen=True)
class CatalogFilterDefaults:
    """catalog_filter's defaults: the real-sky scenarios' filter (`filter_options.SKY_FILTER`).

    Two-body + J2, P0 floor 1 km / 1 m/s, q = 1e-7 m^2/s^3 = 1e-13 km^2/s^3, IOD from 7
    measurements within 300 s, initialised again after 10 gate misses, covariance bounded
    by the orbit; no light time.
    """

    station: str = "radar_network"
    sites: str = ""
    motion_model: str = str(SKY_FILTER.motion.motion_model)
    q: float = _si(SKY_FILTER.noise.q * KM * KM)
    gate: float = SKY_FILTER.noise.gate or 0.0
    p0_sigma: tuple[float, ...] = tuple(_si(v * KM) for v in SKY_FILTER.iod.p0_sigma)
    iod_samples: int = SKY_FILTER.iod.iod_samples
    iod_max_span: float = SKY_FILTER.iod.iod_max_span_s
    reinit_after: int = SKY_FILTER.iod.reinit_after
    sigma_bound: float = SKY_FILTER.noise.sigma_bound
    shards: int = 1
    shard: int = 0
    batch_period: float = 0.05
    max_clock_lead: float = MAX_CLOCK_LEAD_S
    max_objects: int = MAX_OBJECTS
    evict_after: float = 7 * 86400.0
    batch_rows: int = 5_000
    max_unacked_rows: int = 0


@dataclass(frozen=True)
class CatalogSurrogateDefaults:
    """catalog_surrogate's defaults: residual gap forecasts of a catalog (`core.catalog.gap_bank`).

    For the catalog_filter's two-body + J2 tracks; the residual model is the live filter's
    (`core.gaps.residual.LIVE_RESIDUAL`: 5 pass ends over a day at least, in a 2-day window).
    """

    motion_model: str = "j2"
    predict_period: float = 600.0
    pass_break: float = 600.0
    hold: float = 120.0
    fit_budget: float = 0.5
    min_anchors: int = 5
    min_span: float = DAY_S
    physics_fit: bool = True
    gap_forecast: str = "residual"
    station: str = "radar_network"
    sites: str = ""
    shards: int = 1
    shard: int = 0
    max_clock_lead: float = MAX_CLOCK_LEAD_S
    max_objects: int = MAX_OBJECTS


@dataclass(frozen=True)
class ConjunctionDefaults:
    """conjunction's defaults: the catalog's estimates re-screened (`core.conjunction.watch`).

    Approaches within 5 km over the next day, re-screened every sim hour for the objects
    whose estimates changed; a 20 m combined hard-body radius (CARA's default); CDMs of the
    approaches with Pc >= 1e-5 when ``cdm_dir`` names a directory.
    """

    distance: float = 5000.0
    horizon: float = DAY_S
    rescreen_period: float = 3600.0
    hard_body_radius: float = 20.0
    motion_model: str = "j2"
    cdm_dir: str = ""
    cdm_min_pc: float = 1e-5
    max_clock_lead: float = MAX_CLOCK_LEAD_S


BAG_PATTERN = "out/bags/ssa_%Y%m%d_%H%M%S"
"""`time.strftime` pattern of the recorder's default bag directory (start time), under the
working directory's ``out/`` (never the repository's tracked ``bags/``)."""


@dataclass(frozen=True)
class RecorderDefaults:
    """recorder's defaults.

    ``bag`` defaults to `BAG_PATTERN` at the node's start time, so it is None here.
    """

    bag: str | None = None
    topics: tuple[str, ...] = ("/clock",)
    prefix: str = "/ssa/"
    flush_period: float = 1.0
    discover_period: float = 0.1


@dataclass(frozen=True)
class FoxgloveBridgeDefaults:
    """foxglove_bridge's defaults: a scene on the loopback at Foxglove's usual port."""

    host: str = "127.0.0.1"
    port: int = 8765
    station: str = STATION
    scene_period: float = 0.2
    trail_length: int = 600
    points: int = 300
    marker_size: float = 150.0
    object_id: str = ""
    ros_topics: bool = True


SENSOR_SIM = SensorSimDefaults()
SURROGATE = SurrogateDefaults()
FILTER = FilterDefaults()
RECORDER = RecorderDefaults()
CATALOG_FILTER = CatalogFilterDefaults()
CATALOG_SURROGATE = CatalogSurrogateDefaults()
CONJUNCTION = ConjunctionDefaults()
FOXGLOVE_BRIDGE = FoxgloveBridgeDefaults()

NODES = {"sensor_sim": SENSOR_SIM, "surrogate": SURROGATE, "filter": FILTER,
         "recorder": RECORDER}
"""Every node's defaults by node name (the names config/default.yaml uses)."""

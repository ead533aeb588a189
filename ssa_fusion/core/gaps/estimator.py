"""One object's estimator settings in one place: `EstimatorConfig`.

The live nodes build it from their ROS parameters (`ssa_fusion.params.settings`), the paper's
study from a scenario (`ssa_fusion.sim.scenarios.Scenario.estimator`), and ``replay`` /
``report`` from a ROS params file or from the settings the nodes recorded with the bag
(``/ssa/config``, the JSON of `to_dict`). Everything then goes through the same builders
(`make_tracker`, `make_surrogate`), so the filter node, the surrogate node, the offline
replay and the experiments run the same estimator for the same settings. It composes the
measurement stream with the filter's options (`filter_options.FilterOptions`, the catalog
filter's too) and the surrogate's (`surrogate.SurrogateConfig`).

Units are the core's: km, km/s, rad, s.
"""

from __future__ import annotations

import enum
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field, fields, replace
from typing import Any

import numpy as np

from ssa_fusion.core.base.constants import MU_EARTH
from ssa_fusion.core.base.types import KIND_NAMES, Kind, MotionModel, StateEstimate
from ssa_fusion.core.earth import frames
from ssa_fusion.core.earth.frames import Frame, Station
from ssa_fusion.core.earth.stations import NETWORKS, find_station, network_stations
from ssa_fusion.core.earth.timescales import DAY_S, UNIX_EPOCH_JD
from ssa_fusion.core.filter.options import SKY_FILTER, FilterOptions
from ssa_fusion.core.filter.tracker import Tracker
from ssa_fusion.core.gaps.surrogate import LIVE_SURROGATE, EciLift, Surrogate, SurrogateConfig
from ssa_fusion.core.measure.laser_model import LaserModels, LaserNetwork
from ssa_fusion.core.measure.measurement import (
    MeasurementModel,
    PositionModel,
    RadecModel,
    RazelModel,
    StationModels,
)
from ssa_fusion.core.motion import dynamics, kepler
from ssa_fusion.core.motion.contexts import augmented_motion
from ssa_fusion.core.motion.force_spec import ForceSpec
from ssa_fusion.core.motion.propagation import INTEGRATED_MODELS, integrate_stm
from ssa_fusion.core.od import laser_od

MotionFunction = Callable[[np.ndarray, float, float], tuple[np.ndarray, np.ndarray]]
"""f(x, dt, t0) -> (x1, F): a motion model and its state transition matrix, from the state
``x`` at ``t0`` (s on the clock of `EstimatorConfig.jd0`) to ``t0 + dt``."""


ORBIT_MODELS = (MotionModel.KEPLER, *INTEGRATED_MODELS)
"""Motion models of an Earth orbit (GCRF states on a UTC clock)."""


class Lift(enum.StrEnum):
    """What the surrogate's DMD learns."""

    NONE = "none"
    """The measurement itself."""
    ECI = "eci"
    """Range/az/el lifted to the inertial (GCRF) position it implies (`surrogate.EciLift`)."""


@dataclass
class EstimatorConfig:
    """Everything one object's estimator needs.

    The measurement stream, the filter's options and the surrogate's settings.

    Attributes
    ----------
    kind : Kind
        Measurement kind the filter and the surrogate take.
    station : str
        Station id (`stations.STATIONS`) of range/az/el or ra/dec measurements, or a station
        network (a `stations.NETWORKS` id, or station ids separated by commas: the filter
        then fuses every station of the network, radar and optical); unused for positions.
    observed : tuple of int
        State channels a position measurement observes (`measurement.PositionModel`).
    n : int
        State dimension.
    jd0 : float
        UTC Julian date of t = 0 of the clock the measurements are stamped on (Unix time:
        `stations.UNIX_EPOCH_JD`; 0 for the non-orbit problems, whose clock has no epoch).
    lift : Lift
        What the surrogate learns.
    light_time : bool
        Light-time correction in the station measurement models (`measurement`).
    refraction : bool
        Refracted elevation in the radar measurement models (`refraction`).
    filter : FilterOptions
        The EKF's options: noise, IOD, and its motion model ("placeholder" in the paper;
        ``filter.motion``).
    surrogate : SurrogateConfig
        Surrogate settings (`kind`, `frame_id` and `lift` are set by `make_surrogate`).
    sites : tuple of frames.Station
        Stations of one's own (a sites file, `site_file`) that `station` may name besides
        the built-in ones; each ``name`` is its id (the ``frame_id`` of its measurements).
    laser : LaserNetwork or None
        The laser stations and the object (kind LASER_RANGE; from the bag's or the topic's
        ``/ssa/config``, never in the recorded settings). The filter's state is then
        ``[r, v, the stations' range biases, k_R]`` (`laser_filter`).
    force : ForceSpec or None
        The object's forces (motion model "high_fidelity"; built from ``motion_params``
        by `formats.force_choice`, never in the recorded settings themselves).
    """

    kind: Kind = Kind.RANGE_AZ_EL
    station: str = "columbus"
    observed: tuple[int, ...] = (0, 1, 2)
    n: int = 6
    jd0: float = UNIX_EPOCH_JD
    lift: Lift = Lift.NONE
    light_time: bool = False
    refraction: bool = False
    filter: FilterOptions = field(default_factory=FilterOptions)
    surrogate: SurrogateConfig = field(default_factory=SurrogateConfig)
    sites: tuple[Station, ...] = ()
    laser: LaserNetwork | None = None
    force: ForceSpec | None = None

    def __post_init__(self) -> None:
        """Coerce the enums and check the combination (ValueError naming the field)."""
        self.kind = Kind(self.kind)
        self.lift = Lift(self.lift)
        self.observed = tuple(int(i) for i in self.observed)
        self.sites = tuple(self.sites)
        if self.kind in (Kind.RANGE_AZ_EL, Kind.RA_DEC):
            network_stations(self.station, self.site_map)  # ValueError naming the known ids
        if self.lift == Lift.ECI and self.kind != Kind.RANGE_AZ_EL:
            raise ValueError("lift 'eci' needs kind range_az_el")
        model = self.filter.motion.motion_model
        if model in ORBIT_MODELS and self.n != 6:
            raise ValueError(f"motion model {model} needs n = 6, got {self.n}")

    @property
    def site_map(self) -> dict[str, Station]:
        """`sites` by id."""
        return {s.name: s for s in self.sites}

    @property
    def is_network(self) -> bool:
        """True when `station` names a network (several stations, any sensor type)."""
        return self.station in NETWORKS or "," in self.station

    @property
    def frame_id(self) -> str:
        """The frame_id the measurements carry.

        The station id, "" for a network (any of its stations), or "gcrf" for positions.
        """
        if self.kind == Kind.POSITION:
            return Frame.GCRF
        return "" if self.is_network else self.station

    def with_(self, **changes: Any) -> EstimatorConfig:  # noqa: ANN401
        """Return a copy with `changes` (`dataclasses.replace`)."""
        return replace(self, **changes)


STATION_KINDS = (Kind.RANGE_AZ_EL, Kind.RA_DEC)
"""Measurement kinds taken at a station (their ``frame_id`` is the station id)."""


def uncovered_stations(c: EstimatorConfig, frame_ids: Iterable[str]) -> list[str]:
    """Return the station ids among `frame_ids` that `c`'s stations do not include (sorted).

    Empty for positions (they have no station).
    """
    if c.kind not in STATION_KINDS:
        return []
    return sorted(set(frame_ids) - set(network_stations(c.station, c.site_map)))


def for_stations(c: EstimatorConfig, frame_ids: Iterable[str]) -> EstimatorConfig:
    """Return `c` taking the measurements of the stations `frame_ids` (their ids).

    `c` itself when its stations include them all (so a bag replays with the settings it
    was recorded with). Otherwise its ``station`` becomes the ids among `frame_ids` that are
    known (built in, or in ``c.sites``): the one id, or "a,b," for several (or when `c`
    was a network). Unknown ids stay out: the filter refuses their measurements
    (``rejected_frame``); `c` is returned as it is when none is known.
    """
    ids = sorted(set(frame_ids))
    if c.kind not in STATION_KINDS or not uncovered_stations(c, ids):
        return c
    known = [i for i in ids if find_station(i, c.site_map) is not None]
    if not known:
        return c
    one = len(known) == 1 and not c.is_network
    return c.with_(station=known[0] if one else ",".join(known) + ",")


def station_estimator(kind: Kind, station: str,
                      sites: tuple[Station, ...] = ()) -> EstimatorConfig:
    """Return the estimator for measurements of real stations whose settings are unknown.

    The real sky's filter (`filter_options.SKY_FILTER`: two-body + J2, IOD from one pass,
    initialised again when it loses the object, covariance bounded by the orbit), light
    time in the station models, the live surrogate's settings; `station` and `sites` as
    `EstimatorConfig` takes them.
    """
    return EstimatorConfig(kind=kind, station=station, light_time=True, filter=SKY_FILTER,
                           surrogate=LIVE_SURROGATE, sites=sites)


def measurement_model(c: EstimatorConfig) -> MeasurementModel:
    """Return h(x, t) of the configured measurement kind, or a network's models.

    t is on the clock whose t = 0 is `c.jd0`.
    """
    if c.kind == Kind.POSITION:
        return PositionModel(c.observed)
    if c.kind == Kind.LASER_RANGE:
        if c.laser is None:
            raise ValueError("laser ranges need their network (stations, object): the "
                             "/ssa/config of `ssa-fusion import crd`")
        return LaserModels(c.laser)
    if c.is_network:
        return StationModels(network_stations(c.station, c.site_map), c.jd0, c.light_time,
                             c.refraction)
    station = network_stations(c.station, c.site_map)[c.station]
    if c.kind == Kind.RA_DEC:
        return RadecModel(station, c.jd0, c.light_time)
    return RazelModel(station, c.jd0, c.light_time, c.refraction)


def laser_filter(network: LaserNetwork, force: ForceSpec,
                 motion_params: dict[str, float]) -> EstimatorConfig:
    """Return the filter of a laser network's ranges of one object (`laser_od`'s physics).

    Its state ``[r, v, the stations' range biases (network order), k_R]``; the motion model
    "high_fidelity" of ``force`` (whose ``motion_params`` are recorded with the settings,
    `formats.force_choice`), steps of `laser_od.MAX_STEP_S`; process noise
    `laser_od.FILTER_Q` on the orbit; the a-priori sigma `laser_od.PRIOR_SIGMA`, each
    bias's prior sigma, k_R's `laser_od.CR_SIGMA` (``p0_sigma``: the prior of
    `Tracker.set_prior`); the default gate (gross errors only).
    """
    nb = len(network.ids)
    _, bias_sigma = network.prior(network.ids)
    pos, vel = laser_od.PRIOR_SIGMA
    p0 = (pos,) * 3 + (vel,) * 3 + tuple(bias_sigma.tolist()) + (laser_od.CR_SIGMA,)
    options = FilterOptions().with_(q=laser_od.FILTER_Q, p0_sigma=p0,
                                    motion_model=MotionModel.HIGH_FIDELITY,
                                    motion_params=motion_params,
                                    max_step_s=laser_od.MAX_STEP_S)
    return EstimatorConfig(kind=Kind.LASER_RANGE, station=",".join(network.ids) + ",",
                           n=7 + nb, filter=options, laser=network, force=force)


def laser_prior(c: EstimatorConfig, guess: StateEstimate) -> StateEstimate:
    """Return the a-priori estimate of `laser_filter` ``c`` at ``guess.t``.

    ``guess``'s orbit, each bias's prior mean, k_R = 1, the covariance of ``p0_sigma``.
    """
    assert c.laser is not None
    mean, _ = c.laser.prior(c.laser.ids)
    x = np.concatenate([np.asarray(guess.x, dtype=float)[:6], mean, [1.0]])
    P = np.diag(np.square(np.asarray(c.filter.iod.p0_sigma, dtype=float)))
    return StateEstimate(float(guess.t), x, P, guess.object_id)


def motion(c: EstimatorConfig) -> MotionFunction:
    """Return the motion model f(x, dt, t0) -> (x1, F) of `c` (``c.filter.motion``).

    Analytic Kepler, or a `dynamics` model integrated with its state transition matrix:
    the orbit models ("two_body", "j2", "drag") with the catalog filter's fixed-step DOP853
    (`propagation.integrate_stm`, steps of at most ``max_step_s``; ~100x cheaper per
    prediction than scipy's adaptive DOP853 and within ~1e-10 relative of it), the others
    (pendulum, Van der Pol, CR3BP) with scipy's (`dynamics.propagate_stm`). The orbit
    models' states are GCRF; J2 acts about the Earth's pole at ``t0`` (`frames.pole_frame`,
    the clock being Unix time for orbits).
    """
    m = c.filter.motion
    model, params = m.motion_model, dict(m.motion_params)
    if model == MotionModel.HIGH_FIDELITY:
        if c.force is None:
            raise ValueError("motion model high_fidelity needs its forces "
                             "(EstimatorConfig.force, `formats.force_choice`)")
        return augmented_motion(c.force, c.n, ("srp_scale",) if c.n > 6 else (), m.max_step_s)
    if model == MotionModel.KEPLER:
        mu = float(params.get("mu", MU_EARTH))

        def kepler_motion(x: np.ndarray, dt: float,
                          _t0: float) -> tuple[np.ndarray, np.ndarray]:
            return kepler.propagate(x, dt, mu)

        return kepler_motion
    if model in INTEGRATED_MODELS:
        unix, step = (c.jd0 - UNIX_EPOCH_JD) * DAY_S, m.max_step_s

        def compiled(x: np.ndarray, dt: float, t0: float) -> tuple[np.ndarray, np.ndarray]:
            x1, F, ok = integrate_stm(model, np.asarray(x, float)[None], np.array([dt]), step,
                                      pole_frame=frames.pole_frame(t0 + unix), **params)
            if not ok[0]:
                raise RuntimeError(f"propagation failed: the {model} orbit is not finite "
                                   f"{dt} s on")
            return x1[0], F[0]

        return compiled

    def f(x: np.ndarray, dt: float, _t0: float) -> tuple[np.ndarray, np.ndarray]:
        return dynamics.propagate_stm(model, x, dt, **params)

    return f


def make_tracker(c: EstimatorConfig, object_id: str = "") -> Tracker:
    """Build the EKF of `c` (its frame_id set from the stream).

    Its options are `c.filter` (frozen): change settings at run time by replacing
    `Tracker.config`.
    """
    return Tracker(motion(c), measurement_model(c), c.filter, n=c.n, object_id=object_id,
                   frame_id=c.frame_id, dynamic=6 if c.kind == Kind.LASER_RANGE else None)


def make_surrogate(c: EstimatorConfig) -> Surrogate:
    """Build the surrogate of `c`.

    It holds its own copy of `c.surrogate` (kind, frame_id and lift set from the stream):
    change settings at run time through `Surrogate.config`.
    """
    model = measurement_model(c)
    lift = EciLift(model) if c.lift == Lift.ECI and isinstance(model, RazelModel) else None
    sc = replace(c.surrogate, kind=c.kind, frame_id=c.frame_id, lift=lift)
    return Surrogate(sc)


_STREAM_KEYS = ("kind", "station", "observed", "n", "jd0", "lift", "light_time", "refraction")
_MOTION_KEYS = ("motion_model", "motion_params")
"""Filter options at the top level of the JSON; the others are under ``tracker`` (the
layout of the settings recorded with earlier bags, which read back)."""
_NOT_SERIALISED = ("kind", "frame_id", "lift")
"""Surrogate fields set from the stream by `make_surrogate`, so not part of the JSON."""


def _plain(d: dict[str, Any]) -> dict[str, Any]:
    """Return ``d`` with its tuples as lists (for JSON)."""
    return {k: list(v) if isinstance(v, tuple) else v for k, v in d.items()}


def _tuples(d: dict[str, Any]) -> dict[str, Any]:
    """Return ``d`` with its lists as tuples (from JSON)."""
    return {k: tuple(v) if isinstance(v, list) else v for k, v in d.items()}


def to_dict(c: EstimatorConfig) -> dict[str, Any]:
    """JSON-ready dict of `c` (kind and enums by name; what `from_dict` reads back).

    ``frame`` names the inertial frame of the estimator's states ("gcrf"), so that settings
    recorded with a bag say it.
    """
    out: dict[str, Any] = {"frame": Frame.GCRF}
    out.update({k: getattr(c, k) for k in _STREAM_KEYS})
    out["kind"] = KIND_NAMES[c.kind]
    out["lift"] = str(c.lift)
    out["observed"] = list(c.observed)
    options = c.filter.flat()
    out["motion_model"] = str(options.pop("motion_model"))
    out["motion_params"] = dict(options.pop("motion_params"))
    out["tracker"] = _plain(options)
    out["surrogate"] = _plain({f.name: getattr(c.surrogate, f.name) for f in fields(c.surrogate)
                               if f.name not in _NOT_SERIALISED})
    if c.sites:  # stations of one's own: recorded, so that the bag alone replays
        out["sites"] = [{"id": s.name, "lat_rad": s.lat_rad, "lon_rad": s.lon_rad,
                         "alt_km": s.alt_km} for s in c.sites]
    return out


def _sites_from(raw: object) -> tuple[Station, ...]:
    """Return the stations of the ``sites`` of a `to_dict` dict (ValueError if malformed)."""
    try:
        if isinstance(raw, list):
            return tuple(Station(str(d["id"]), float(d["lat_rad"]), float(d["lon_rad"]),
                                 float(d["alt_km"])) for d in raw)
    except (KeyError, TypeError, ValueError):
        pass
    raise ValueError(f"malformed sites setting {str(raw)[:80]!r}: want a list of "
                     f"{{id, lat_rad, lon_rad, alt_km}}")


def from_dict(d: dict[str, Any], base: EstimatorConfig | None = None) -> EstimatorConfig:
    """Read an `EstimatorConfig` from a `to_dict` dict.

    Keys it lacks keep `base`'s values (default: `EstimatorConfig()`); unknown keys or
    values raise ValueError naming them.
    """
    base = base or EstimatorConfig()
    unknown = set(d) - {*_STREAM_KEYS, *_MOTION_KEYS, "tracker", "surrogate", "frame", "sites"}
    if unknown:
        raise ValueError(f"unknown estimator setting(s): {', '.join(sorted(unknown))}")
    if d.get("frame", Frame.GCRF) != Frame.GCRF:
        raise ValueError(f"estimator settings of frame {d['frame']!r}: this version estimates "
                         f"in the GCRF")
    stream: dict[str, Any] = {k: d[k] for k in _STREAM_KEYS if k in d}
    if "sites" in d:
        stream["sites"] = _sites_from(d["sites"])
    if "kind" in stream:
        names = {name: kind for kind, name in KIND_NAMES.items()}
        if stream["kind"] not in names:
            raise ValueError(f"kind {stream['kind']!r} unknown; known: {', '.join(names)}")
        stream["kind"] = names[stream["kind"]]
    options, surrogate = dict(d.get("tracker", {})), dict(d.get("surrogate", {}))
    for part, given, names_ok in (
            ("tracker", options, set(base.filter.flat()) - set(_MOTION_KEYS)),
            ("surrogate", surrogate, {f.name for f in fields(SurrogateConfig)}
             - set(_NOT_SERIALISED))):
        bad = set(given) - names_ok
        if bad:
            raise ValueError(f"unknown {part} setting(s): {', '.join(sorted(bad))}")
    options.update({k: d[k] for k in _MOTION_KEYS if k in d})
    return replace(base, **stream, filter=base.filter.with_(**_tuples(options)),
                   surrogate=replace(base.surrogate, **_tuples(surrogate)))

"""One object's estimator settings in one place: `EstimatorConfig`.

The live nodes build it from their ROS parameters (`ssa_fusion.nodes.settings`), the paper's
study from a scenario (`ssa_fusion.sim.scenarios.Scenario.estimator`), and ``replay`` /
``report`` from a ROS params file or from the settings the nodes recorded with the bag
(``/ssa/config``, the JSON of `to_dict`). Everything then goes through the same builders
(`make_tracker`, `make_surrogate`), so the filter node, the surrogate node, the offline
replay and the experiments run the same estimator for the same settings.

Units are the core's: km, km/s, rad, s.
"""

from __future__ import annotations

import enum
from collections.abc import Callable
from dataclasses import dataclass, field, fields, replace
from typing import Any

import numpy as np

from . import dynamics, frames, kepler
from .batch_ekf import integrate_stm
from .frames import Frame
from .measurement import MeasurementModel, PositionModel, RadecModel, RazelModel, StationModels
from .stations import NETWORKS, STATIONS, network_stations
from .surrogate import EciLift, Surrogate, SurrogateConfig
from .timescales import DAY_S, UNIX_EPOCH_JD
from .tracker import Tracker, TrackerConfig
from .types import KIND_NAMES, Kind

MotionFunction = Callable[[np.ndarray, float, float], tuple[np.ndarray, np.ndarray]]
"""f(x, dt, t0) -> (x1, F): a motion model and its state transition matrix, from the state
``x`` at ``t0`` (s on the clock of `EstimatorConfig.jd0`) to ``t0 + dt``."""


class MotionModel(enum.StrEnum):
    """The EKF's motion model (what the filter predicts with)."""

    KEPLER = "kepler"
    """Analytic two-body (universal variables, `kepler.propagate`), GCRF km, km/s."""
    J2 = "j2"
    """Two-body + J2, integrated with its state transition matrix (`batch_ekf.integrate_stm`:
    compiled fixed-step DOP853, steps of at most 60 s)."""
    TWO_BODY = "two_body"
    """Two-body, integrated (the Keplerian model by numerical integration, as J2)."""
    PENDULUM = "pendulum"
    """Damped pendulum [theta rad, theta_dot rad/s] (the paper's toy problem)."""
    VDP = "vdp"
    """Van der Pol oscillator (nondimensional)."""
    CR3BP = "cr3bp"
    """Circular restricted three-body problem, Earth-Moon, rotating frame, nondimensional."""


ORBIT_MODELS = (MotionModel.KEPLER, MotionModel.J2, MotionModel.TWO_BODY)
"""Motion models of an Earth orbit (GCRF states on a UTC clock)."""


ORBIT_TOLERANCES = {"rtol": 1e-10, "atol": 1e-9}
"""DOP853 tolerances of an integrated orbit motion model (km, km/s and the STM's entries)."""


class Lift(enum.StrEnum):
    """What the surrogate's DMD learns."""

    NONE = "none"
    """The measurement itself."""
    ECI = "eci"
    """Range/az/el lifted to the inertial (GCRF) position it implies (`surrogate.EciLift`)."""


@dataclass
class EstimatorConfig:
    """Everything one object's estimator needs.

    The measurement stream, the motion model, the tracker's and the surrogate's settings.

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
    motion_model : MotionModel
        The EKF's motion model ("placeholder" in the paper).
    motion_params : dict of str to float
        Parameters of a `dynamics` motion model (e.g. the pendulum's m, c, L).
    jd0 : float
        UTC Julian date of t = 0 of the clock the measurements are stamped on (Unix time:
        `stations.UNIX_EPOCH_JD`; 0 for the non-orbit problems, whose clock has no epoch).
    lift : Lift
        What the surrogate learns.
    light_time : bool
        Light-time correction in the station measurement models (`measurement`).
    refraction : bool
        Refracted elevation in the radar measurement models (`refraction`).
    tracker : TrackerConfig
        EKF settings (its `frame_id` is set from `kind`/`station` by `make_tracker`).
    surrogate : SurrogateConfig
        Surrogate settings (`kind`, `frame_id` and `lift` are set by `make_surrogate`).
    """

    kind: Kind = Kind.RANGE_AZ_EL
    station: str = "columbus"
    observed: tuple[int, ...] = (0, 1, 2)
    n: int = 6
    motion_model: MotionModel = MotionModel.KEPLER
    motion_params: dict[str, float] = field(default_factory=dict)
    jd0: float = UNIX_EPOCH_JD
    lift: Lift = Lift.NONE
    light_time: bool = False
    refraction: bool = False
    tracker: TrackerConfig = field(default_factory=TrackerConfig)
    surrogate: SurrogateConfig = field(default_factory=SurrogateConfig)

    def __post_init__(self) -> None:
        """Coerce the enums and check the combination (ValueError naming the field)."""
        self.kind = Kind(self.kind)
        self.motion_model = MotionModel(self.motion_model)
        self.lift = Lift(self.lift)
        self.observed = tuple(int(i) for i in self.observed)
        if self.kind in (Kind.RANGE_AZ_EL, Kind.RA_DEC):
            network_stations(self.station)  # ValueError naming the known ids
        if self.lift == Lift.ECI and self.kind != Kind.RANGE_AZ_EL:
            raise ValueError("lift 'eci' needs kind range_az_el")
        if self.motion_model in ORBIT_MODELS and self.n != 6:
            raise ValueError(f"motion model {self.motion_model} needs n = 6, got {self.n}")

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


def measurement_model(c: EstimatorConfig) -> MeasurementModel:
    """Return h(x, t) of the configured measurement kind, or a network's models.

    t is on the clock whose t = 0 is `c.jd0`.
    """
    if c.kind == Kind.POSITION:
        return PositionModel(c.observed)
    if c.is_network:
        return StationModels(network_stations(c.station), c.jd0, c.light_time, c.refraction)
    station = STATIONS[c.station]
    if c.kind == Kind.RA_DEC:
        return RadecModel(station, c.jd0, c.light_time)
    return RazelModel(station, c.jd0, c.light_time, c.refraction)


def motion(c: EstimatorConfig) -> MotionFunction:
    """Return the motion model f(x, dt, t0) -> (x1, F) of `c`.

    Analytic Kepler, or a `dynamics` model integrated with its state transition matrix. The
    orbit models' states are GCRF; J2 acts about the Earth's pole at ``t0``
    (`frames.pole_frame`, the clock being Unix time for orbits).
    """
    if c.motion_model == MotionModel.KEPLER:
        def kepler_motion(x: np.ndarray, dt: float,
                          _t0: float) -> tuple[np.ndarray, np.ndarray]:
            return kepler.propagate(x, dt)

        return kepler_motion
    name, params = str(c.motion_model), dict(c.motion_params)
    if c.motion_model in (MotionModel.J2, MotionModel.TWO_BODY):
        # compiled fixed-step DOP853 (steps <= 60 s): the catalog filter's, ~100x cheaper per
        # prediction than scipy's adaptive DOP853 and within ~1e-10 relative of it
        unix = (c.jd0 - UNIX_EPOCH_JD) * DAY_S

        def compiled(x: np.ndarray, dt: float, t0: float) -> tuple[np.ndarray, np.ndarray]:
            x1, F, ok = integrate_stm(name, np.asarray(x, float)[None], np.array([dt]),
                                      pole_frame=frames.pole_frame(t0 + unix), **params)
            if not ok[0]:
                raise RuntimeError(f"propagation failed: the {name} orbit is not finite "
                                   f"{dt} s on")
            return x1[0], F[0]

        return compiled
    # orbits: 1e-9 km (1 µm) absolute, 1e-10 relative; 4x faster than the default 1e-12
    # for differences below 1e-11 km over a 30 s step
    tol = ORBIT_TOLERANCES if c.motion_model in ORBIT_MODELS else {}

    def f(x: np.ndarray, dt: float, _t0: float) -> tuple[np.ndarray, np.ndarray]:
        return dynamics.propagate_stm(name, x, dt, **tol, **params)

    return f


def make_tracker(c: EstimatorConfig, object_id: str = "") -> Tracker:
    """Build the EKF of `c`.

    It holds its own copy of `c.tracker` (frame_id set from the stream): change settings at
    run time through `Tracker.config`.
    """
    tc = replace(c.tracker, frame_id=c.frame_id)
    return Tracker(motion(c), measurement_model(c), tc, n=c.n, object_id=object_id)


def make_surrogate(c: EstimatorConfig) -> Surrogate:
    """Build the surrogate of `c`.

    It holds its own copy of `c.surrogate` (kind, frame_id and lift set from the stream):
    change settings at run time through `Surrogate.config`.
    """
    model = measurement_model(c)
    lift = EciLift(model) if c.lift == Lift.ECI and isinstance(model, RazelModel) else None
    sc = replace(c.surrogate, kind=c.kind, frame_id=c.frame_id, lift=lift)
    return Surrogate(sc)


_STREAM_KEYS = ("kind", "station", "observed", "n", "motion_model", "motion_params", "jd0",
                "lift", "light_time", "refraction")
_NOT_SERIALISED = {"tracker": ("frame_id",), "surrogate": ("kind", "frame_id", "lift")}
"""Component fields set from the stream by the builders, so not part of the JSON."""


def to_dict(c: EstimatorConfig) -> dict[str, Any]:
    """JSON-ready dict of `c` (kind and enums by name; what `from_dict` reads back).

    ``frame`` names the inertial frame of the estimator's states ("gcrf"), so that settings
    recorded with a bag say it.
    """
    out: dict[str, Any] = {"frame": Frame.GCRF}
    out.update({k: getattr(c, k) for k in _STREAM_KEYS})
    out["kind"] = KIND_NAMES[c.kind]
    out["motion_model"] = str(c.motion_model)
    out["lift"] = str(c.lift)
    out["observed"] = list(c.observed)
    for part in ("tracker", "surrogate"):
        d = {f.name: getattr(getattr(c, part), f.name) for f in fields(getattr(c, part))}
        for k in _NOT_SERIALISED[part]:
            d.pop(k)
        out[part] = {k: list(v) if isinstance(v, tuple) else v for k, v in d.items()}
    return out


def from_dict(d: dict[str, Any], base: EstimatorConfig | None = None) -> EstimatorConfig:
    """Read an `EstimatorConfig` from a `to_dict` dict.

    Keys it lacks keep `base`'s values (default: `EstimatorConfig()`); unknown keys or
    values raise ValueError naming them.
    """
    base = base or EstimatorConfig()
    unknown = set(d) - {*_STREAM_KEYS, "tracker", "surrogate", "frame"}
    if unknown:
        raise ValueError(f"unknown estimator setting(s): {', '.join(sorted(unknown))}")
    if d.get("frame", Frame.GCRF) != Frame.GCRF:
        raise ValueError(f"estimator settings of frame {d['frame']!r}: this version estimates "
                         f"in the GCRF")
    stream: dict[str, Any] = {k: d[k] for k in _STREAM_KEYS if k in d}
    if "kind" in stream:
        names = {name: kind for kind, name in KIND_NAMES.items()}
        if stream["kind"] not in names:
            raise ValueError(f"kind {stream['kind']!r} unknown; known: {', '.join(names)}")
        stream["kind"] = names[stream["kind"]]
    parts: dict[str, Any] = {}
    for part, cls in (("tracker", TrackerConfig), ("surrogate", SurrogateConfig)):
        given = dict(d.get(part, {}))
        names_ok = {f.name for f in fields(cls)} - set(_NOT_SERIALISED[part])
        bad = set(given) - names_ok
        if bad:
            raise ValueError(f"unknown {part} setting(s): {', '.join(sorted(bad))}")
        given = {k: tuple(v) if isinstance(v, list) else v for k, v in given.items()}
        parts[part] = replace(getattr(base, part), **given)
    return replace(base, **stream, **parts)

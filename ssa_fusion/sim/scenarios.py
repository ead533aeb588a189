"""Scenarios of the paper (docs/RESULTS.md, "Settings") and the pieces built from them.

A `Scenario` fixes everything an experiment needs: the true dynamics, what is observed and
how noisily, the cadence, the tracking window before the gap, the gap, and the estimator
settings (placeholder model, P0 floor, process noise, surrogate delays/rank). No setting
reads the true trajectory of the gap.

Orbit scenarios run on a UTC clock: times are Unix seconds (so the epoch of every
measurement fixes the Earth's rotation); the others start at t = 0.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from ssa_fusion.core.base.types import Kind
from ssa_fusion.core.earth import frames
from ssa_fusion.core.earth.frames import Station
from ssa_fusion.core.earth.stations import STATIONS
from ssa_fusion.core.earth.timescales import UNIX_EPOCH_JD
from ssa_fusion.core.filter.options import FilterOptions
from ssa_fusion.core.gaps import estimator as config
from ssa_fusion.core.gaps.estimator import EstimatorConfig, Lift
from ssa_fusion.core.gaps.surrogate import LIVE_SURROGATE
from ssa_fusion.core.measure.laser_model import LaserModels
from ssa_fusion.core.measure.measurement import PositionModel, RadecModel, RazelModel, StationModels
from ssa_fusion.core.motion import dynamics

ISS_ELEMENTS: dict[str, float] = {
    "a_km": 6796.9,
    "e": 0.0007,
    "i_rad": math.radians(51.639),
    "raan_rad": math.radians(113.73),
    "argp_rad": math.radians(51.197),
    "nu_rad": math.radians(358.89),
}
"""ISS osculating elements (paper Table 1); ``elements_to_state(**ISS_ELEMENTS)`` gives GCRF km."""

MOLNIYA_ELEMENTS: dict[str, float] = {
    "a_km": 26555.94,
    "e": 0.7294,
    "i_rad": math.radians(63.324),
    "raan_rad": math.radians(295.46),
    "argp_rad": math.radians(282.69),
    "nu_rad": math.radians(357.32),
}
"""Molniya-3-50 osculating elements (paper Table 2)."""

HALO_L1_STATE = np.array([0.87592, 0.0, 0.19175, 0.0, 0.23080, 0.0])
"""Earth-Moon L1 halo initial state, CR3BP rotating frame, nondimensional (paper Table 3)."""


ORBIT_EPOCH_UNIX = 1735689600.0
"""2025-01-01T00:00:00 UTC: epoch of the orbit scenarios' initial elements."""

Placeholder = Callable[[np.ndarray, float, float], tuple[np.ndarray, np.ndarray]]

ORBIT_TRUTHS = ("j2", "drag", "two_body", "sgp4")
"""True dynamics that are Earth orbits."""


@dataclass(frozen=True)
class Scenario:
    """One experiment. Units: km, km/s, rad, s (nondimensional for cr3bp).

    Attributes
    ----------
    truth : str
        True dynamics: "j2", "drag", "two_body", "sgp4", "pendulum", "vdp", "cr3bp".
    x0 : tuple
        True initial state at `t0`.
    placeholder : str
        The EKF's model: "kepler" (analytic two-body) or a `dynamics` model name.
    kind, observed, station
        Measurement: Kind.POSITION of state channels `observed`, or Kind.RANGE_AZ_EL from `station`.
    noise_sigma : tuple
        Measurement noise standard deviation per channel (km or rad); all zero = noise-free.
    noise_rel : float
        Alternatively noise as a fraction of each channel's RMS over the tracking window
        (the paper's "5 %" and "1 %"); resolved into `noise_sigma` by `resolve_noise`.
    cadence_s, track_s, gap_s, after_s
        Measurement interval; tracking before the gap (the surrogate's training window);
        the gap; tracking after the gap (live runs only).
    delays, rank
        Hankel-DMD delay count and rank (None: automatic).
    p0_sigma : tuple
        Standard deviation floor added to the IOD covariance, per state (n,).
    q : float
        White-noise acceleration spectral density of the process noise, (km/s^2)^2 s.
        Chosen from the size of what the placeholder leaves out, never from the gap:
        q ~ a^2 tau with a the unmodelled acceleration and tau a quarter period (ISS and
        Molniya: J2, a ~ 1.2e-5 km/s^2 -> 1e-7, which also makes the range/az/el
        tracking-window NIS ~ 3; pendulum: damping (c/m) theta_dot ~ 5e-3 rad/s^2 -> 1e-5).
    iod_samples : int
        Real measurements used by the initial orbit determination.
    buffer_s, retrain_period_s
        Surrogate training buffer (0: the tracking window) and refit period (a gap always
        starts from a fit up to the last real measurement).
    lift : str
        "" (DMD learns the measurement) or "eci" (range/az/el lifted to the inertial (GCRF)
        position it implies, see `surrogate.EciLift`).
    """

    name: str
    truth: str
    x0: tuple[float, ...]
    placeholder: str
    kind: int = Kind.POSITION
    observed: tuple[int, ...] = (0, 1, 2)
    station: str = ""
    noise_sigma: tuple[float, ...] = (0.0, 0.0, 0.0)
    noise_rel: float = 0.0
    cadence_s: float = 30.0
    track_s: float = 21600.0
    gap_s: float = 5580.0
    after_s: float = 1800.0
    delays: int = 120
    rank: int | None = None
    p0_sigma: tuple[float, ...] = (1.0, 1.0, 1.0, 1e-3, 1e-3, 1e-3)
    q: float = 1e-12
    iod_samples: int = 3
    buffer_s: float = 0.0
    retrain_period_s: float = math.inf
    lift: str = ""
    t0: float = ORBIT_EPOCH_UNIX
    truth_params: dict[str, float] = field(default_factory=dict)
    placeholder_params: dict[str, float] = field(default_factory=dict)
    finding: str = ""

    @property
    def n(self) -> int:
        """The state dimension."""
        return len(self.x0)

    @property
    def is_orbit(self) -> bool:
        """Whether this is an Earth orbit (GCRF states, UTC clock).

        Decided by the truth, never by the filter's model (a J2 filter on the ISS is still
        an orbit).
        """
        return self.truth in ORBIT_TRUTHS

    @property
    def jd0(self) -> float:
        """UTC Julian date of t = 0 of the clock this scenario's times are on."""
        return UNIX_EPOCH_JD if self.is_orbit else 0.0

    @property
    def unix0(self) -> float:
        """Unix time (s) of t = 0 of this scenario's clock (orbits: 0, the clock is Unix)."""
        return (self.jd0 - UNIX_EPOCH_JD) * 86400.0

    @property
    def gap_start(self) -> float:
        """The gap's first instant, s on the scenario's clock."""
        return self.t0 + self.track_s

    @property
    def gap_end(self) -> float:
        """The end of the gap (the first instant after it), s on the scenario's clock."""
        return self.gap_start + self.gap_s

    def with_(self, **changes: object) -> Scenario:
        """Return a copy with `changes` (`dataclasses.replace`)."""
        # arg-type: `changes` are fields of different types by name, which mypy cannot match
        # to `object`; replace itself rejects a name that is no field
        return replace(self, **changes)  # type: ignore[arg-type]

    def estimator(self) -> EstimatorConfig:
        """Return the estimator this scenario runs (the live nodes' and the experiments').

        Motion model, measurement stream, P0 floor, q, IOD samples and the Hankel-DMD
        settings (buffer = the tracking window, forecasts up to one cadence past the gap).
        """
        return EstimatorConfig(
            kind=Kind(self.kind), station=self.station or "columbus", observed=self.observed,
            n=self.n, jd0=self.jd0, lift=Lift(self.lift or "none"),
            filter=FilterOptions().with_(motion_model=self.placeholder,
                                         motion_params=self.placeholder_params,
                                         p0_sigma=self.p0_sigma, q=self.q,
                                         iod_samples=self.iod_samples),
            surrogate=replace(LIVE_SURROGATE, buffer_s=self.buffer_s or self.track_s,
                              delays=self.delays, rank=self.rank, cadence_s=self.cadence_s,
                              max_horizon_s=self.gap_s + self.cadence_s,
                              retrain_period_s=self.retrain_period_s))


def _iss_state() -> tuple[float, ...]:
    """Return the ISS's initial GCRF state (`ISS_ELEMENTS`), km, km/s."""
    return tuple(dynamics.elements_to_state(**ISS_ELEMENTS))


def _molniya_state() -> tuple[float, ...]:
    """Return the Molniya's initial GCRF state (`MOLNIYA_ELEMENTS`), km, km/s."""
    return tuple(dynamics.elements_to_state(**MOLNIYA_ELEMENTS))


ISS_BSTAR = 1.0270e-4
"""SGP4 drag term of a real ISS element set, 1/earth radii: ISS (ZARYA), NORAD 25544, epoch
2020-01-01 19:42 UTC, B* field ``10270-3`` (the element set of the `sgp4` package's test
suite, sgp4/tests.py)."""
MOLNIYA_BSTAR = 1.1873e-4
"""SDP4 drag term of a real Molniya element set, 1/earth radii: MOLNIYA 2-14, NORAD 08195,
epoch 2006-06-25, B* field ``11873-3`` (Vallado et al., "Revisiting Spacetrack Report #3",
AIAA 2006-6753, verification set SGP4-VER.TLE, shipped with the `sgp4` package)."""

ISS_PERIOD_S = 2 * math.pi * math.sqrt(6796.9**3 / 398600.4418)
HALO_PERIOD = 2.17831
"""Period of the L1 halo orbit, nondimensional time."""

# Training window: ten periods, as in the paper ("for the ISS, 10 periods correspond to
# approximately 15 hours"; Molniya: 5 days); the halo orbit gets the same. Delays: chosen
# on the training window only, by `bench/holdout_delays.py` (fit on all but the last gap
# length of the window, forecast that stretch, error against its measurements): two
# periods for the ISS (372) and Molniya (144), one period for the halo orbit (200); the
# pendulum's 60 is its holdout minimum; Van der Pol keeps 100 (100-200 all forecast to
# ~1e-6, far below what its placeholder error lets show). Never on the gap. `_ISS` and
# `_PENDULUM` are keyword arguments of `Scenario`, of the types of its fields.
_ISS: dict[str, Any] = dict(
    x0=_iss_state(), placeholder="kepler", cadence_s=30.0,
    track_s=30.0 * round(10 * ISS_PERIOD_S / 30.0), gap_s=186 * 30.0,
    delays=round(2 * ISS_PERIOD_S / 30.0),
    p0_sigma=(0.1, 0.1, 0.1, 1e-4, 1e-4, 1e-4), q=1e-7,
)

# The damped pendulum of the paper; only the initial angle differs between its two rows.
_PENDULUM: dict[str, Any] = dict(
    truth="pendulum", placeholder="pendulum", observed=(0,), noise_sigma=(0.0,),
    cadence_s=0.1, track_s=100.0, gap_s=400.0, after_s=20.0, delays=60, t0=0.0,
    p0_sigma=(1e-3, 1e-2), q=1e-5, truth_params={"m": 0.5, "c": 2e-3, "L": 1.0},
    placeholder_params={"m": 0.5, "c": 0.0, "L": 1.0},
)

SCENARIOS: dict[str, Scenario] = {
    s.name: s
    for s in [
        Scenario(name="pendulum", x0=(0.1, 0.0), **_PENDULUM,
                 finding="DMD-EKF ≈ hypothetical for ~200 s, then diverges"),
        Scenario(name="pendulum_0.5", x0=(0.5, 0.0), **_PENDULUM,
                 finding="(not in the paper: θ0 = 0.5 rad, where the frequency drifts with "
                         "the amplitude)"),
        Scenario(name="iss_j2_pos", truth="j2", **_ISS,
                 finding="DMD-EKF ≈ hypothetical"),
        Scenario(name="iss_drag_pos", truth="drag", **_ISS,
                 finding="DMD misses dissipation; worse"),
        Scenario(name="iss_sgp4_pos", truth="sgp4", **_ISS,
                 truth_params={"bstar": ISS_BSTAR},
                 finding="DMD-EKF ≈ hypothetical"),
        Scenario(name="iss_sgp4_pos_nodrag", truth="sgp4", **_ISS,
                 truth_params={"bstar": 0.0},
                 finding="(not in the paper: SGP4 without drag, bstar = 0)"),
        Scenario(name="iss_j2_pos_noisy", truth="j2", noise_rel=0.05,
                 **{**_ISS, "p0_sigma": (10.0, 10.0, 10.0, 1e-2, 1e-2, 1e-2)},
                 finding="close to hypothetical, within 3σ"),
        Scenario(name="iss_j2_rae", truth="j2", kind=Kind.RANGE_AZ_EL, station="columbus",
                 noise_sigma=(1.0, 0.01, 0.01), lift="eci",
                 **{**_ISS, "p0_sigma": (1.0, 1.0, 1.0, 1e-3, 1e-3, 1e-3)},
                 finding="≈ hypothetical"),
        Scenario(
            name="molniya_sdp4_pos", truth="sgp4", x0=_molniya_state(), placeholder="kepler",
            cadence_s=600.0, track_s=720 * 600.0, gap_s=72 * 600.0, after_s=6 * 600.0,
            delays=144, p0_sigma=(1.0, 1.0, 1.0, 1.0, 1.0, 1.0), q=1e-7,
            truth_params={"bstar": MOLNIYA_BSTAR},
            finding="~100× worse than hypothetical",
        ),
        Scenario(
            name="vdp", truth="vdp", x0=(2.0, 0.0), placeholder="vdp", observed=(0,),
            noise_sigma=(0.0,), cadence_s=0.05, track_s=40.0, gap_s=40.0, after_s=5.0,
            delays=100, t0=0.0, p0_sigma=(1e-3, 1e-2), q=1e-6,
            truth_params={"mu": 2.0}, placeholder_params={"mu": 1.0},
            finding="both EKFs fail away from μ_p≈2",
        ),
        Scenario(
            name="cr3bp_halo_noisy", truth="cr3bp", x0=tuple(HALO_L1_STATE),
            placeholder="cr3bp", noise_rel=0.01, cadence_s=HALO_PERIOD / 200,
            track_s=10 * HALO_PERIOD, gap_s=HALO_PERIOD, after_s=0.1, delays=200, t0=0.0,
            # q: the exact placeholder leaves out only the EKF's linearisation error,
            # 1/2 |d2a/dr2| |dr|^2 ~ 2e-3 at perilune (r 0.046) for |dr| ~ 5e-4 -> a^2 tau
            p0_sigma=(1e-3, 1e-3, 1e-3, 1e-2, 1e-2, 1e-2), q=1e-6,
            finding="≈ hypothetical, within 3σ",
        ),
    ]
}

DEFAULT_LIVE = SCENARIOS["iss_j2_rae"]
"""The live graph's default: ISS, two-body + J2, range/az/el from Columbus, a one-orbit gap
after ten orbits (15.5 h) of tracking."""


def get(name: str) -> Scenario:
    """Return the scenario `name`; ValueError listing the known names otherwise."""
    try:
        return SCENARIOS[name]
    except KeyError:
        raise ValueError(
            f"unknown scenario {name!r}; known: {', '.join(SCENARIOS)}"
        ) from None


def settings_for(name: str = "", kind: int = Kind.RANGE_AZ_EL) -> Scenario:
    """Return the scenario whose estimator settings fit recorded data.

    Scenario `name`, else the default orbit scenario of the measurement `kind` (range/az/el:
    iss_j2_rae, position: iss_j2_pos).
    """
    if name:
        return get(name)
    return get("iss_j2_rae" if kind == Kind.RANGE_AZ_EL else "iss_j2_pos")


def measurement_model(s: Scenario) -> PositionModel | RazelModel | RadecModel:
    """Return h(x, t) of the scenario; t on the scenario's clock (Unix s for orbits).

    ValueError when its station names a network: a scenario is measured from one station.
    """
    model = config.measurement_model(s.estimator())
    if isinstance(model, StationModels | LaserModels):
        raise ValueError(f"scenario {s.name!r}: station {s.station!r} is a network; a "
                         "scenario is measured from one station")
    return model


def station(s: Scenario) -> Station | None:
    """Return the scenario's station (`STATIONS`), None when it has none (positions)."""
    return STATIONS.get(s.station)


def placeholder_model(s: Scenario) -> Placeholder:
    """Return the EKF's model f(x, dt, t0) -> (x1, F): analytic Kepler or `dynamics` + STM."""
    return config.motion(s.estimator())


def truth_states(s: Scenario, t: np.ndarray) -> np.ndarray:
    """Return the true states (len(t), n) at times `t` on the scenario clock (t[0] == s.t0)."""
    if s.truth == "sgp4":
        return dynamics.sgp4_ephemeris(np.array(s.x0), s.unix0 + s.t0, t - s.t0,
                                       **s.truth_params)
    pole = frames.pole_frame(s.unix0 + s.t0) if s.is_orbit else None
    return dynamics.propagate(s.truth, np.array(s.x0), t - s.t0, pole_frame=pole,
                              **s.truth_params)

"""The real sky: scenarios where stations see an object only above their masks.

A `SkyScenario` puts a network of sensors (`core.earth.stations.SENSORS`: radars measuring range,
azimuth and elevation; optical sites measuring right ascension and declination at night, of
a sunlit object) under an object whose truth is SGP4 with the drag term of a real element
set, or (`SkyScenario.truth` = `world.TruthModel.HIGH_FIDELITY`) the numerical propagation
of a world richer than any filter's model (`world`: EGM96 20 x 20, the Sun and the Moon,
solar radiation pressure, NRLMSISE-00's air under synthetic space weather, optionally
unannounced manoeuvres). The natural gaps are those between passes (hours, in low orbit); on
top of them a scheduled outage of one station or of the whole network withholds what it
would have measured (the hypothetical arm fuses it). The truth is sampled at a regular
cadence through every gap, where `evaluation.passes` and `evaluation.arms` score a filter
(the study that runs both is `studies.sky_runs`).

Optical sites and the seasons: an optical site sees an object only while the site is dark
(Sun below -12 deg) and the object sunlit and above the 20 deg mask. A 400 km orbit is
sunlit over a dark site only near the terminator, and the ISS state of these scenarios has
its orbit plane far from the terminator in early January: over `iss_network`'s three days
from 2025-01-01 the object is in the Earth's shadow whenever a GEODSS site is dark, and the
optical sites measure nothing. The plane turns against the Sun (nodal regression ~5 deg/day,
the Sun ~1 deg/day): in 85 of 122 three-day windows of 2025 (every third day) the optical
sites see it, and from day 105 (2025-04-16, `iss_network_april`) all three do, ~100
measurements in three days.

Units: km, km/s, rad, s; times are Unix seconds (UTC).
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass, field, replace

import numpy as np

from ssa_fusion.core.base.types import Measurement
from ssa_fusion.core.earth import frames, lighttime, refraction, timescales, visibility
from ssa_fusion.core.earth.stations import SENSORS, Sensor, SensorType
from ssa_fusion.core.earth.timescales import UNIX_EPOCH_JD
from ssa_fusion.core.filter.options import SKY_FILTER, FilterOptions
from ssa_fusion.core.gaps.estimator import EstimatorConfig
from ssa_fusion.core.gaps.publisher import GapFill
from ssa_fusion.core.gaps.surrogate import LIVE_SURROGATE
from ssa_fusion.core.motion import dynamics
from ssa_fusion.core.motion.element_sets import CatalogEntry, catalog_states
from ssa_fusion.formats import element_sets as catalog
from ssa_fusion.formats import sites as site_file
from ssa_fusion.sim.scenarios import ISS_BSTAR, ISS_ELEMENTS, ORBIT_EPOCH_UNIX
from ssa_fusion.sim.world import TruthModel, World, world_truth

SKY_Q = SKY_FILTER.noise.q
"""Process noise of the real-sky filters (`filter_options.SKY_FILTER`'s), (km/s^2)^2 s: 1e-13,
the value of {1e-12, 3e-13, 1e-13, 3e-14} whose mean NEES over every truth epoch (gaps
included) is nearest its 6 degrees of freedom on the tuning seeds 1-3 of iss_radar_columbus
(5.9-6.5, 92-95 % of epochs in the per-epoch 95 % band; 1e-12, the rule-of-thumb
q ~ a^2 tau with a ~ 3e-8 km/s^2, gave 1.3-1.6: too cautious). The evaluation seeds never
saw it (docs/HISTORY.md, 2026-11-24: the real sky)."""

ISS_STANDARD_MAGNITUDE = -1.3
"""The ISS's standard magnitude (1000 km, 90 deg phase), the usual catalogue value; every
scenario's object has it unless set (a sensor without a limiting magnitude ignores it)."""

ALL_STATIONS = "*"
"""The station id of an outage of the whole network."""


def _iss_state() -> tuple[float, ...]:
    return tuple(dynamics.elements_to_state(**ISS_ELEMENTS))


SSO_ELEMENTS = {"a_km": 7178.0, "e": 0.001, "i_rad": math.radians(98.6),
                "raan_rad": math.radians(191.0), "argp_rad": 0.0, "nu_rad": 0.0}
"""A sun-synchronous orbit at 800 km whose plane lies near the terminator on 2025-01-01
(the Sun's right ascension then is ~281 deg): sunlit 84 % of the time and seen at dusk and
dawn, the geometry optical sites can track. (The ISS, at 400 km, is sunlit over a dark
site only for minutes around twilight: over these sites and these three days, never.)"""


@dataclass(frozen=True)
class SkyScenario:
    """One real-sky experiment.

    Attributes
    ----------
    name : str
        Scenario id.
    sensors : tuple of str
        Sensor preset ids (`stations.SENSORS`); their stations form the filter's network.
    x0 : tuple of float
        True GCRF state at `t0`, km, km/s (osculating; SGP4 mean elements are fitted to it,
        in TEME).
    bstar : float
        SGP4 drag term of the truth, 1/earth radii.
    t0, duration_s, truth_cadence_s
        Start (Unix s), length, and the cadence of the truth and of the filter's published
        estimates (s).
    outages : tuple of (str, float, float)
        Scheduled outages: (sensor id, or `ALL_STATIONS`; start s after t0; length s).
    motion_model, q, p0_sigma, iod_samples, iod_max_span_s, reinit_after, sigma_bound,
    light_time
        The filter (by default `filter_options.SKY_FILTER`, which the catalog filter node
        has too): motion model, process noise spectral density (km/s^2)^2 s, IOD
        covariance floor, IOD batch size and span (one pass), real measurements beyond the
        gate in a row after which it initialises again, the bound on its standard
        deviations relative to |r| and |v| (`ekf.bound_covariance`), light-time correction
        (in the simulated measurements too).
    refraction
        Radar elevations refracted by the standard atmosphere (`core.earth.refraction`), in the
        simulated measurements and in the filter's model alike.
    gap_fill
        What the live filter publishes in the gaps between passes (its ``gap_forecast``
        parameter), chosen on the real-sky tuning runs (seeds 1-3 x start 0/8/16 h,
        `bench/bench_sky.py --tuning`, at 3aa8138): the smallest median error at all gap
        epochs. The ISS scenarios: ``batch_init``, the batch fit of the passes of the last
        24 h, from which the EKF also starts each pass (0.062 / 0.029 / 0.030 km against
        ``fit_residual``'s 0.070 / 0.033 / 0.033 and ``residual``'s 0.39 / 0.11 / 0.092;
        position NEES coverage 97 / 93 / 91 %); leo_optical: ``fit_residual``, its fit of
        three passes of angles corrected by the residual surrogate (0.035 km against
        ``batch_init``'s 0.037; gaps > 12 h 0.041 against 0.051; coverage 89 % against
        87 %).
    finding : str
        What the scenario shows.
    own_sensors, sites_file
        Sensors of a sites file (`with_sites`) that `sensors` may name besides the built-in
        presets, and that file's path ('' = none).
    element_set, elements_file
        The object's element set and the file it came from (`with_elements`): the truth is
        its SGP4/SDP4 instead of `x0`/`bstar` (None, '': the scenario's object).
    standard_magnitude
        The object's visual magnitude at 1000 km and a 90 deg phase angle, for sensors with a
        limiting magnitude (`visibility.apparent_magnitude`).
    site_pool
        Sensor ids a study case may observe with instead of `sensors` (`network_choices`,
        `with_sensors`); empty (a single station): the case keeps `sensors`.
    truth
        The object's truth: SGP4 (`bstar`; an element set's own) or the high-fidelity
        world (`world`).
    world
        What acts on the object in a high-fidelity truth (`world.World`).
    """

    name: str
    sensors: tuple[str, ...]
    x0: tuple[float, ...] = field(default_factory=_iss_state)
    bstar: float = ISS_BSTAR
    t0: float = ORBIT_EPOCH_UNIX
    duration_s: float = 3 * 86400.0
    truth_cadence_s: float = 60.0
    outages: tuple[tuple[str, float, float], ...] = ()
    motion_model: str = str(SKY_FILTER.motion.motion_model)
    q: float = SKY_Q
    p0_sigma: tuple[float, ...] = SKY_FILTER.iod.p0_sigma
    iod_samples: int = SKY_FILTER.iod.iod_samples
    iod_max_span_s: float = SKY_FILTER.iod.iod_max_span_s
    reinit_after: int = SKY_FILTER.iod.reinit_after
    sigma_bound: float = SKY_FILTER.noise.sigma_bound
    light_time: bool = True
    refraction: bool = False
    gap_fill: GapFill = GapFill.BATCH_INIT
    finding: str = ""
    own_sensors: tuple[Sensor, ...] = ()
    sites_file: str = ""
    element_set: CatalogEntry | None = None
    elements_file: str = ""
    standard_magnitude: float = ISS_STANDARD_MAGNITUDE
    site_pool: tuple[str, ...] = ()
    truth: TruthModel = TruthModel.SGP4
    world: World = field(default_factory=World)

    def sensor(self, name: str) -> Sensor:
        """Return sensor `name`: a site of the scenario's sites file, else a built-in preset."""
        for own in self.own_sensors:
            if own.station.name == name:
                return own
        return SENSORS[name]

    @property
    def radars(self) -> list[Sensor]:
        """The scenario's radar sensors (those a catalog run simulates)."""
        return [r for r in map(self.sensor, self.sensors) if r.type == SensorType.RADAR]

    @property
    def network(self) -> str:
        """The filter's ``station`` setting: the sensors' station ids, comma-separated."""
        return ",".join(dict.fromkeys(self.sensor(s).station.name for s in self.sensors)) + ","

    def estimator(self) -> EstimatorConfig:
        """Return the filter of this scenario (the surrogate settings are the live defaults)."""
        kind = self.sensor(self.sensors[0]).kind
        return EstimatorConfig(
            kind=kind, station=self.network,
            jd0=UNIX_EPOCH_JD, light_time=self.light_time, refraction=self.refraction,
            filter=self.filter_options(),
            surrogate=LIVE_SURROGATE, sites=tuple(o.station for o in self.own_sensors))

    def with_sites(self, path: str) -> SkyScenario:
        """Return this scenario observed by the sites of the sites file `path` instead.

        Every site of the file (`formats.sites`), in its order (and no `site_pool`: a
        study case keeps them); an outage of one of the scenario's stations becomes an
        outage of the whole network at the same time.
        SiteFileError (a ValueError) with one line when the file is wrong.
        """
        own = site_file.load_sites(path)
        return self.with_(sensors=tuple(own), own_sensors=tuple(own.values()),
                          sites_file=str(path), site_pool=(),
                          outages=tuple((ALL_STATIONS, a, b) for _, a, b in self.outages))

    def with_elements(self, path: str,
                      progress: catalog.Progress | None = None) -> SkyScenario:
        """Return this scenario's sensors observing the object of the element set file `path`.

        Its first object (TLE, 3LE, OMM XML/CSV: `formats.element_sets.read_catalog`, which says its
        `progress`; ValueError naming the file and line when it is wrong); the truth is its
        SGP4/SDP4, from the first whole minute at or after its epoch (as a catalog run
        starts).
        """
        entry = catalog.read_catalog(path, progress)[0]
        start = 60.0 * math.ceil(entry.epoch_unix / 60.0)
        return self.with_window(start, self.duration_s).with_(element_set=entry,
                                                              elements_file=str(path))

    def with_geometry(self, d_raan_rad: float, d_phase_rad: float) -> SkyScenario:
        """Return this scenario with its object's orbit turned: another plane and phase.

        `x0` rotated by `d_phase_rad` about its angular momentum (the argument of latitude
        moves along the same orbit), then by `d_raan_rad` about the GCRF z axis (the
        ascending node moves; inclination, shape and energy stay). ValueError for an
        object of an element set (its orbit is the element set's).
        """
        if self.element_set is not None:
            raise ValueError("the orbit of an element set's object is its own: not turned")
        x = np.array(self.x0, dtype=float)
        h = np.cross(x[:3], x[3:])
        phase = _rotation(h / np.linalg.norm(h), d_phase_rad)
        node = _rotation(np.array([0.0, 0.0, 1.0]), d_raan_rad)
        turn = node @ phase
        return self.with_(x0=tuple(np.concatenate([turn @ x[:3], turn @ x[3:]]).tolist()))

    def network_choices(self) -> list[tuple[str, ...]]:
        """Return every network a study case may observe with (`site_pool`), in a fixed order.

        Each keeps the scenario's make-up: as many radars as `sensors` has, drawn from the
        pool's radars, and as many optical sites from its optical ones, each slot of
        `sensors` taken by a site of its type (`with_sensors`); every combination once, the
        pool's order within it. Only `sensors` itself without a pool.
        """
        if not self.site_pool:
            return [self.sensors]
        by_type = {t: [n for n in self.site_pool if self.sensor(n).type == t]
                   for t in SensorType}
        slots = [self.sensor(n).type for n in self.sensors]
        picks = {t: list(itertools.combinations(by_type[t], slots.count(t)))
                 for t in SensorType}
        out = []
        for combo in itertools.product(*(picks[t] for t in SensorType)):
            left = {t: iter(c) for t, c in zip(SensorType, combo, strict=True)}
            out.append(tuple(next(left[t]) for t in slots))
        return out

    def with_sensors(self, sensors: tuple[str, ...]) -> SkyScenario:
        """Return this scenario observed by `sensors` instead, slot by slot.

        The k-th of `sensors` takes the place of the k-th of the scenario's: an outage of
        that one becomes its outage (an outage of the whole network stays). ValueError
        when the count or a slot's sensor type differs (a network of the same make-up).
        """
        if len(sensors) != len(self.sensors) or any(
                self.sensor(a).type != self.sensor(b).type
                for a, b in zip(self.sensors, sensors, strict=True)):
            raise ValueError(f"{sensors} does not take the places of {self.sensors} "
                             f"(the same count and sensor type per slot)")
        name = {self.sensor(a).station.name: b for a, b in zip(self.sensors, sensors,
                                                                strict=True)}
        return self.with_(sensors=tuple(sensors), outages=tuple(
            (who if who == ALL_STATIONS else name[self.sensor(who).station.name], a, b)
            for who, a, b in self.outages))

    def with_window(self, t0: float, duration_s: float) -> SkyScenario:
        """Return this scenario from `t0` (Unix s) for `duration_s` (s).

        The object starts from `x0` at `t0`. ValueError (one line) when the start or the end
        is outside the epochs ssa_fusion represents. The outages keep their place in the run: their
        start and length scale with the duration (the scenario's 36 h outage of a 72 h run
        falls at 12 h of a 24 h one), so every run has its outage to evaluate.
        """
        timescales.check_window(t0, duration_s)
        f = duration_s / self.duration_s
        return self.with_(t0=t0, duration_s=duration_s,
                          outages=tuple((who, a * f, b * f) for who, a, b in self.outages))

    def filter_options(self) -> FilterOptions:
        """Return the options of this scenario's filter (the per-object and the batched one)."""
        return FilterOptions().with_(
            motion_model=self.motion_model, q=self.q, p0_sigma=self.p0_sigma,
            iod_samples=self.iod_samples, iod_max_span_s=self.iod_max_span_s,
            reinit_after=self.reinit_after, sigma_bound=self.sigma_bound)

    def with_(self, **changes: object) -> SkyScenario:
        """Return a copy with `changes` (`dataclasses.replace`)."""
        # arg-type: `changes` are fields of different types by name, which mypy cannot match
        # to `object`; replace itself rejects a name that is no field
        return replace(self, **changes)  # type: ignore[arg-type]


_DAY = 86400.0
SSO_WORLD = World(area_to_mass=0.01, cr=1.3, bc=60.0)
"""The high-fidelity world of leo_optical's 800 km object: a small satellite (A/m 0.01
m^2/kg, ballistic coefficient 60 kg/m^2); the ISS scenarios' is `world.World`'s default
(A/m 0.004 m^2/kg, 120 kg/m^2: ~420 t, Cd 2.2, ~1600 m^2)."""
NETWORK_SENSORS = ("millstone", "tira", "altair", "socorro", "maui", "diego_garcia")
"""The radar + optical network of `iss_network`: three radars and the three GEODSS sites."""
SITE_POOL = ("millstone", "tira", "altair", "goldstone", "fylingdales", "socorro", "maui",
             "diego_garcia", "ogs_tenerife", "zimmerwald", "xinglong", "calar_alto",
             "siding_spring", "la_silla")
"""The real sites (`stations.SENSORS`) the ISS networks' study cases draw their networks
from (`SkyScenario.network_choices`): five radars, all within sight of a 51.6 deg orbit,
and nine optical sites in both hemispheres; three of five radars and three of nine optical
sites make 840 networks like iss_network's."""
TWILIGHT_SITE_POOL = ("socorro", "maui", "ogs_tenerife", "zimmerwald", "xinglong",
                      "calar_alto", "diego_garcia")
"""The optical sites leo_optical's study cases draw from: those that see its
sun-synchronous object's twilight passes in January (the southern ones, in their summer's
short nights, see none); three of seven make 35 networks. Diego Garcia, near the equator,
sees few: last in the pool, it never takes the outage's slot (the second)."""
OPTICAL_SEASON_DAY = 105
"""Day of 2025 (2025-04-16) from which `iss_network_april` runs."""
SKY_SCENARIOS: dict[str, SkyScenario] = {
    s.name: s
    for s in [
        SkyScenario(
            name="iss_radar_columbus", sensors=("columbus",),
            outages=(("columbus", 1.5 * _DAY, 0.5 * _DAY),),
            finding="one radar, 10 deg mask: ~5 passes a day, gaps of 1.5-16 h"),
        SkyScenario(
            name="iss_network", sensors=NETWORK_SENSORS, site_pool=SITE_POOL,
            outages=((ALL_STATIONS, 1.5 * _DAY, 0.25 * _DAY),),
            finding="radar + optical network, whole-network outage of 6 h; in these three "
                    "days of January the optical sites see nothing (module docstring)"),
        SkyScenario(
            name="iss_network_april", sensors=NETWORK_SENSORS, site_pool=SITE_POOL,
            t0=ORBIT_EPOCH_UNIX + OPTICAL_SEASON_DAY * _DAY,
            outages=((ALL_STATIONS, 1.5 * _DAY, 0.25 * _DAY),),
            finding="the same network and orbit from 2025-04-16, when the optical sites see "
                    "the object at dusk and dawn (module docstring)"),
        SkyScenario(
            name="leo_optical", sensors=("socorro", "maui", "diego_garcia"),
            site_pool=TWILIGHT_SITE_POOL,
            x0=tuple(dynamics.elements_to_state(**SSO_ELEMENTS)),
            outages=(("maui", 1.0 * _DAY, 1.0 * _DAY),), gap_fill=GapFill.FIT_RESIDUAL,
            world=SSO_WORLD,
            finding="optical sites only, a sun-synchronous LEO object: twilight passes"),
    ]
}


@dataclass
class SkySimulation:
    """Truth on a regular grid and what the sensors measured (or would have, in an outage).

    t, x : (N,), (N, 6) truth epochs (Unix s) and GCRF states; measurements : every
    measurement in epoch order; withheld : (M,) True where a scheduled outage withheld it.
    """

    scenario: SkyScenario
    t: np.ndarray
    x: np.ndarray
    measurements: list[Measurement]
    withheld: np.ndarray

    @property
    def real(self) -> list[Measurement]:
        """The measurements the sensors delivered."""
        return [m for m, w in zip(self.measurements, self.withheld, strict=True) if not w]

    @property
    def withheld_measurements(self) -> list[Measurement]:
        """What the sensors would have measured during the scheduled outages."""
        return [m for m, w in zip(self.measurements, self.withheld, strict=True) if w]


RAAN_SPREAD_DEG = 15.0
"""How far (deg, either way) a seeded case turns its orbit's plane about the pole: far
enough that the passes and the gaps differ from seed to seed, near enough that a scenario
keeps its character (leo_optical's plane near the terminator, where optical sites see it)."""


def case_geometry(seed: int) -> tuple[float, float]:
    """Return the orbit turn of case `seed`: (node shift, phase shift), rad.

    The node shift uniform in +-`RAAN_SPREAD_DEG`, the phase uniform in [0, 360) deg, from a
    generator of its own (the measurement noise of `seed` is not disturbed).
    """
    rng = np.random.default_rng([seed, 7])
    return (math.radians(rng.uniform(-RAAN_SPREAD_DEG, RAAN_SPREAD_DEG)),
            rng.uniform(0.0, 2.0 * math.pi))


def case_start_offset_s(seed: int) -> float:
    """Return the start offset of live case `seed`: whole minutes uniform in [0, 24) h, s.

    From a generator of its own (neither the noise nor the turn of `seed` is disturbed).
    """
    return 60.0 * float(np.random.default_rng([seed, 29]).integers(0, 24 * 60))


def seeded_case(s: SkyScenario, seed: int) -> SkyScenario:
    """Return scenario `s` from a start and with an orbit of its own for seed `seed`.

    Its start `case_start_offset_s` later, its orbit turned (`case_geometry`), the world's
    space weather drawn from `seed`: what `ssa-fusion live --seed` runs unless
    ``--same-geometry``. An element set's object keeps its orbit (ValueError from
    `SkyScenario.with_geometry`).
    """
    moved = s.with_window(s.t0 + case_start_offset_s(seed), s.duration_s)
    return moved.with_geometry(*case_geometry(seed)).with_(
        world=s.world.with_(weather_seed=seed))


def _rotation(axis: np.ndarray, angle_rad: float) -> np.ndarray:
    """Return the 3x3 rotation by `angle_rad` about the unit vector `axis` (Rodrigues)."""
    k = np.array([[0.0, -axis[2], axis[1]], [axis[2], 0.0, -axis[0]],
                  [-axis[1], axis[0], 0.0]])
    out: np.ndarray = np.eye(3) + math.sin(angle_rad) * k + (1.0 - math.cos(angle_rad)) * (k @ k)
    return out


def truth(s: SkyScenario, t: np.ndarray) -> np.ndarray:
    """Return the true GCRF states (len(t), 6) at Unix epochs `t`.

    High-fidelity truth (`SkyScenario.truth`): the world's propagation from the object's
    state at `t0` (`x0`, or its element set's SGP4/SDP4 state there), tabulated once per
    scenario (`world.world_truth`). SGP4 truth: SGP4/SDP4 of the scenario's element set
    (`SkyScenario.with_elements`), else SGP4 from `x0` at `t0` with the scenario's bstar.
    ValueError when SGP4 cannot propagate the element set to an epoch (a decayed object),
    or the world's truth cannot be propagated.
    """
    if s.truth == TruthModel.HIGH_FIDELITY:
        x0 = s.x0 if s.element_set is None else tuple(
            catalog_states([s.element_set], np.array([s.t0])).x[0, 0].tolist())
        return world_truth(tuple(float(v) for v in x0), float(s.t0), float(s.duration_s),
                           s.world).states(np.asarray(t, float))
    if s.element_set is not None:
        x: np.ndarray = catalog_states([s.element_set], np.asarray(t, float)).x[0]
        if not np.isfinite(x).all():
            bad = float(np.asarray(t, float)[~np.isfinite(x).all(axis=1)][0])
            raise ValueError(f"{s.element_set.source or s.element_set.object_id}: SGP4 cannot "
                             f"propagate the element set to {timescales.iso(bad)} (decayed?)")
        return x
    return dynamics.sgp4_ephemeris(np.array(s.x0), s.t0, np.asarray(t, float) - s.t0,
                                   bstar=s.bstar)


def _visible(sensor: Sensor, t: np.ndarray, x: np.ndarray,
             standard_magnitude: float) -> np.ndarray:
    """Where `sensor` measures the object at epochs `t` with states `x` (N, 6).

    An optical sensor with a limiting magnitude sees the object only as bright as that
    (`visibility.apparent_magnitude` of its `standard_magnitude`).
    """
    up = sensor.in_view(frames.razel_gcrs(x, t, sensor.station))
    if sensor.type == SensorType.OPTICAL:
        up &= visibility.station_dark(t, sensor.station, math.radians(sensor.dark_below_deg)) \
            & visibility.sunlit(x[:, :3], t)
        if math.isfinite(sensor.limiting_magnitude):
            up &= visibility.apparent_magnitude(x, t, sensor.station, standard_magnitude) \
                <= sensor.limiting_magnitude
    return np.asarray(up, dtype=bool)


def _observe(s: SkyScenario, sensor: Sensor, rng: np.random.Generator,
             object_id: str) -> list[Measurement]:
    """Return the noisy measurements of `sensor` over the scenario (light time in the truth)."""
    t = s.t0 + sensor.cadence_s * np.arange(int(s.duration_s // sensor.cadence_s) + 1)
    x = truth(s, t)
    up = _visible(sensor, t, x, s.standard_magnitude)
    t, x = t[up], x[up]
    if not len(t):
        return []
    station = sensor.station
    if s.light_time:
        x = lighttime.retarded_states(lambda tt: truth(s, tt), t, station)
    if sensor.type == SensorType.RADAR:
        z = frames.razel_gcrs(x, t, station)
        if s.refraction:
            z[:, 2] += refraction.refraction(z[:, 2])
    else:
        z = frames.radec_gcrs(x, t, station)
    sigma = np.asarray(sensor.sigma, dtype=float)
    z = z + rng.standard_normal(z.shape) * sigma + np.asarray(sensor.bias or 0.0)
    angle = [1] if sensor.type == SensorType.RADAR else [0]
    z[:, angle] = np.mod(z[:, angle], 2 * math.pi)
    if sensor.type == SensorType.OPTICAL:
        z[:, 1] = np.clip(z[:, 1], -0.5 * math.pi, 0.5 * math.pi)
    R = sensor.R
    return [Measurement(t=float(ti), z=zi, R=R, kind=sensor.kind, object_id=object_id,
                        frame_id=station.name) for ti, zi in zip(t, z, strict=True)]


def _withheld(s: SkyScenario, sensor_of: list[str], t: np.ndarray) -> np.ndarray:
    out = np.zeros(len(t), dtype=bool)
    names = np.array(sensor_of)
    for who, start, length in s.outages:
        inside = (t >= s.t0 + start) & (t < s.t0 + start + length)
        out |= inside & ((names == s.sensor(who).station.name) if who != ALL_STATIONS else True)
    return out


def simulate_sky(s: SkyScenario, seed: int = 0, object_id: str = "") -> SkySimulation:
    """Truth and measurements of `s`, reproducible by `seed` (one noise stream per sensor)."""
    rngs = np.random.default_rng(seed).spawn(len(s.sensors))
    meas = [m for name, rng in zip(s.sensors, rngs, strict=True)
            for m in _observe(s, s.sensor(name), rng, object_id or s.name)]
    meas.sort(key=lambda m: (m.t, m.frame_id))
    t_meas = np.array([m.t for m in meas])
    withheld = _withheld(s, [m.frame_id for m in meas], t_meas)
    t = s.t0 + s.truth_cadence_s * np.arange(int(s.duration_s // s.truth_cadence_s) + 1)
    return SkySimulation(s, t, truth(s, t), meas, withheld)

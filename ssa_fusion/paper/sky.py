"""The real sky: scenarios where stations see an object only above their masks.

A `SkyScenario` puts a network of sensors (`core.stations.SENSORS`: radars measuring range,
azimuth and elevation; optical sites measuring right ascension and declination at night, of
a sunlit object) under an object whose truth is SGP4 with the drag term of a real element
set. The natural gaps are those between passes (hours, in low orbit); on top of them a
scheduled outage of one station or of the whole network withholds what it would have
measured (the hypothetical arm fuses it). The truth is sampled at a regular cadence through
every gap, and the filter is scored there: after each pass, through the gaps, and with the
honest arms of `arms` over the scheduled outage.

Units: km, km/s, rad, s; times are Unix seconds (UTC).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np

from ssa_fusion.core import dynamics, frames, lighttime, refraction, visibility
from ssa_fusion.core.config import EstimatorConfig, MotionModel, make_surrogate, make_tracker
from ssa_fusion.core.metrics import chi2_bounds, nees
from ssa_fusion.core.stations import SENSORS, Sensor, SensorType
from ssa_fusion.core.surrogate import LIVE_SURROGATE
from ssa_fusion.core.timescales import UNIX_EPOCH_JD
from ssa_fusion.core.tracker import TrackerConfig
from ssa_fusion.core.types import Measurement, StateEstimate
from ssa_fusion.paper import arms
from ssa_fusion.paper.scenarios import ISS_BSTAR, ORBIT_EPOCH_UNIX

SKY_Q = 1e-13
"""Process noise of the real-sky filters, (km/s^2)^2 s: the value of {1e-12, 3e-13, 1e-13,
3e-14} whose mean NEES over every truth epoch (gaps included) is nearest its 6 degrees of
freedom on the tuning seeds 1-3 of iss_radar_columbus (5.9-6.5, 92-95 % of epochs in the
per-epoch 95 % band; 1e-12, the rule-of-thumb q ~ a^2 tau with a ~ 3e-8 km/s^2, gave 1.3-1.6:
too cautious). The evaluation seeds never saw it (docs/HISTORY.md, session 9)."""

ALL_STATIONS = "*"
"""The station id of an outage of the whole network."""

PASS_BREAK_S = 600.0
"""Measurements further apart than this (s) belong to different passes."""


def _iss_state() -> tuple[float, ...]:
    return tuple(dynamics.elements_to_state(**dynamics.ISS_ELEMENTS))


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
        The filter: motion model, process noise spectral density (km/s^2)^2 s, IOD
        covariance floor, IOD batch size and span (one pass), real measurements beyond the
        gate in a row after which it initialises again, the bound on its standard
        deviations relative to |r| and |v| (`ekf.bound_covariance`), light-time correction
        (in the simulated measurements too).
    refraction
        Radar elevations refracted by the standard atmosphere (`core.refraction`), in the
        simulated measurements and in the filter's model alike.
    finding : str
        What the scenario shows.
    """

    name: str
    sensors: tuple[str, ...]
    x0: tuple[float, ...] = field(default_factory=_iss_state)
    bstar: float = ISS_BSTAR
    t0: float = ORBIT_EPOCH_UNIX
    duration_s: float = 3 * 86400.0
    truth_cadence_s: float = 60.0
    outages: tuple[tuple[str, float, float], ...] = ()
    motion_model: str = "j2"
    q: float = SKY_Q
    p0_sigma: tuple[float, ...] = (1.0, 1.0, 1.0, 1e-3, 1e-3, 1e-3)
    iod_samples: int = 7
    iod_max_span_s: float = 300.0
    reinit_after: int = 10
    sigma_bound: float = 2.0
    light_time: bool = True
    refraction: bool = False
    finding: str = ""

    @property
    def radars(self) -> list[Sensor]:
        """The scenario's radar sensors (those a catalog run simulates)."""
        return [SENSORS[n] for n in self.sensors if SENSORS[n].type == SensorType.RADAR]

    @property
    def network(self) -> str:
        """The filter's ``station`` setting: the sensors' station ids, comma-separated."""
        return ",".join(dict.fromkeys(SENSORS[s].station.name for s in self.sensors)) + ","

    def estimator(self) -> EstimatorConfig:
        """The filter of this scenario (the surrogate settings are the live defaults)."""
        kind = SENSORS[self.sensors[0]].kind
        return EstimatorConfig(
            kind=kind, station=self.network, motion_model=MotionModel(self.motion_model),
            jd0=UNIX_EPOCH_JD, light_time=self.light_time, refraction=self.refraction,
            tracker=TrackerConfig(p0_sigma=self.p0_sigma, q=self.q,
                                  iod_samples=self.iod_samples,
                                  iod_max_span_s=self.iod_max_span_s,
                                  reinit_after=self.reinit_after,
                                  sigma_bound=self.sigma_bound),
            surrogate=LIVE_SURROGATE)

    def with_(self, **changes: object) -> SkyScenario:
        return replace(self, **changes)  # type: ignore[arg-type]


_DAY = 86400.0
SKY_SCENARIOS: dict[str, SkyScenario] = {
    s.name: s
    for s in [
        SkyScenario(
            name="iss_radar_columbus", sensors=("columbus",),
            outages=(("columbus", 1.5 * _DAY, 0.5 * _DAY),),
            finding="one radar, 10 deg mask: ~5 passes a day, gaps of 1.5-16 h"),
        SkyScenario(
            name="iss_network", sensors=("millstone", "tira", "altair", "socorro", "maui",
                                         "diego_garcia"),
            outages=((ALL_STATIONS, 1.5 * _DAY, 0.25 * _DAY),),
            finding="radar + optical network, whole-network outage of 6 h"),
        SkyScenario(
            name="leo_optical", sensors=("socorro", "maui", "diego_garcia"),
            x0=tuple(dynamics.elements_to_state(**SSO_ELEMENTS)),
            outages=(("maui", 1.0 * _DAY, 1.0 * _DAY),),
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


def truth(s: SkyScenario, t: np.ndarray) -> np.ndarray:
    """True GCRF states (len(t), 6) at Unix epochs `t` (SGP4 with the scenario's bstar)."""
    return dynamics.sgp4_ephemeris(np.array(s.x0), s.t0, np.asarray(t, float) - s.t0,
                                   bstar=s.bstar)


def _visible(sensor: Sensor, t: np.ndarray, x: np.ndarray) -> np.ndarray:
    """Where `sensor` measures the object at epochs `t` with states `x` (N, 6)."""
    rae = frames.razel_gcrs(x, t, sensor.station)
    up = rae[:, 2] >= sensor.min_elevation(rae[:, 1])
    if sensor.type == SensorType.OPTICAL:
        up &= visibility.station_dark(t, sensor.station) & visibility.sunlit(x[:, :3], t)
    return np.asarray(up, dtype=bool)


def _observe(s: SkyScenario, sensor: Sensor, rng: np.random.Generator,
             object_id: str) -> list[Measurement]:
    """The noisy measurements of `sensor` over the scenario (light time in the truth)."""
    t = s.t0 + sensor.cadence_s * np.arange(int(s.duration_s // sensor.cadence_s) + 1)
    x = truth(s, t)
    up = _visible(sensor, t, x)
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
        out |= inside & ((names == SENSORS[who].station.name) if who != ALL_STATIONS else True)
    return out


def simulate_sky(s: SkyScenario, seed: int = 0, object_id: str = "") -> SkySimulation:
    """Truth and measurements of `s`, reproducible by `seed` (one noise stream per sensor)."""
    rngs = np.random.default_rng(seed).spawn(len(s.sensors))
    meas = [m for name, rng in zip(s.sensors, rngs, strict=True)
            for m in _observe(s, SENSORS[name], rng, object_id or s.name)]
    meas.sort(key=lambda m: (m.t, m.frame_id))
    t_meas = np.array([m.t for m in meas])
    withheld = _withheld(s, [m.frame_id for m in meas], t_meas)
    t = s.t0 + s.truth_cadence_s * np.arange(int(s.duration_s // s.truth_cadence_s) + 1)
    return SkySimulation(s, t, truth(s, t), meas, withheld)


def passes(measurements: list[Measurement], gap_s: float = PASS_BREAK_S
           ) -> list[tuple[int, int]]:
    """Index ranges [first, last] of the passes in `measurements` (epoch order): runs with
    no two consecutive measurements more than `gap_s` apart."""
    if not measurements:
        return []
    t = np.array([m.t for m in measurements])
    breaks = np.flatnonzero(np.diff(t) > gap_s)
    starts = np.concatenate([[0], breaks + 1])
    ends = np.concatenate([breaks, [len(t) - 1]])
    return list(zip(starts.tolist(), ends.tolist(), strict=True))


@dataclass
class PassReport:
    """How the filter did through the passes and gaps of a run.

    passes : per pass, (end epoch s, station ids, measurements fused, position error km and
    position sigma km (sqrt of the trace of the position covariance) at the first truth
    epoch after the pass); t_start : the first truth epoch, s; t, pos_err_km, nees : the
    filter's estimate or prediction at each truth epoch after its first estimate;
    nees_band : the per-epoch 95 % chi-square band (6 dof); gaps_h : the gaps between passes, h.
    """

    passes: list[tuple[float, str, int, float, float]]
    t_start: float
    t: np.ndarray
    pos_err_km: np.ndarray
    nees: np.ndarray
    nees_band: tuple[float, float]
    gaps_h: np.ndarray

    @property
    def nees_in_band(self) -> float:
        """Fraction of truth epochs whose NEES lies in the 95 % band."""
        lo, hi = self.nees_band
        return float(np.mean((self.nees >= lo) & (self.nees <= hi)))

    def table(self) -> str:
        """Markdown: the per-pass errors, then the run's NEES and gaps."""
        rows = ["| pass end (h after start) | stations | measurements | position error after "
                "the pass [km] | its σ [km] |", "|---|---|---|---|---|"]
        for t_end, who, n, err, sig in self.passes:
            rows.append(f"| {(t_end - self.t_start) / 3600:.2f} | {who} | {n} | {err:.3f} "
                        f"| {sig:.3f} |")
        lo, hi = self.nees_band
        e = self.nees
        after = [p[3] for p in self.passes]
        if after:
            rows.append(f"\nafter each pass: median error {np.median(after):.3f} km, max "
                        f"{max(after):.3f} km over {len(after)} passes")
        rows.append(f"through the run ({len(e)} truth epochs): position error mean "
                    f"{np.mean(self.pos_err_km):.3f} km, max {np.max(self.pos_err_km):.3f} km; "
                    f"NEES mean {np.mean(e):.2f}, median {np.median(e):.2f}, per-epoch 95 % band "
                    f"[{lo:.2f}, {hi:.2f}] holds {100 * self.nees_in_band:.0f} % of epochs")
        if len(self.gaps_h):
            rows.append(f"gaps between passes: {len(self.gaps_h)}, {self.gaps_h.min():.2f} to "
                        f"{self.gaps_h.max():.2f} h")
        return "\n".join(rows)


def pass_report(c: EstimatorConfig, estimates: dict[float, StateEstimate],
                real: list[Measurement], t_truth: np.ndarray,
                x_truth: np.ndarray) -> PassReport:
    """Score a filter's estimates (by epoch, those that fused a measurement) against the truth
    (`t_truth`, `x_truth` on a regular cadence): after each pass of `real`, and at every truth
    epoch (the estimate there, or the prediction from the last one)."""
    if not estimates:
        raise ValueError("the filter never published an estimate")
    traj = estimates_at(c, estimates, t_truth)
    x_true = x_truth[t_truth > min(estimates)]
    err = np.linalg.norm(traj.x[:, :3] - x_true[:, :3], axis=1)
    e = nees(traj.x - x_true, traj.P)
    fused = [m for m in real if m.t in estimates]
    rows = []
    for first, last in passes(fused):
        t_end = fused[last].t
        k = int(np.searchsorted(traj.t, t_end, side="right"))
        if k >= len(traj.t):
            continue
        who = ",".join(sorted({m.frame_id for m in fused[first:last + 1]}))
        rows.append((t_end, who, last - first + 1, float(err[k]),
                     float(np.sqrt(np.trace(traj.P[k, :3, :3])))))
    real_t = np.array([m.t for m in real])
    gaps = np.diff(real_t) if len(real_t) > 1 else np.zeros(0)
    return PassReport(rows, float(t_truth[0]), traj.t, err, e, chi2_bounds(6),
                      gaps[gaps > PASS_BREAK_S] / 3600.0)


def estimates_at(c: EstimatorConfig, estimates: dict[float, StateEstimate],
                 t: np.ndarray) -> arms.ArmTrajectory:
    """The filter's estimate, or its prediction from the last one, at every epoch of `t`
    after its first estimate (what the live filter publishes through the gaps)."""
    first = min(estimates)
    return arms.at_epochs(c, estimates, t[t > first])


def outage_epochs(t: np.ndarray, withheld: list[Measurement]) -> np.ndarray:
    """The truth epochs `t` the scheduled outage is scored over: from its first withheld
    measurement to its last (the same rule for a bag, `apps.evaluate`, which knows only what
    was withheld, not the schedule)."""
    w = [m.t for m in withheld]
    return t[(t >= min(w)) & (t <= max(w))] if w else t[:0]


@dataclass
class SkyDmdRun:
    """The filter's estimates fusing the surrogate's forecasts (last per epoch), and the
    forecasts the surrogate issued."""

    estimates: dict[float, StateEstimate]
    forecasts: list[Measurement]


def run_dmd_ekf(sim: SkySimulation) -> SkyDmdRun:
    """Surrogate + filter over the delivered measurements, driven as the live graph drives
    them: every real measurement goes to the surrogate (whose forecasts still owed go to the
    filter first) and to the filter; at every truth epoch between measurements the
    surrogate's timer releases the forecasts due."""
    c = sim.scenario.estimator()
    tracker, surrogate = make_tracker(c), make_surrogate(c)
    run = SkyDmdRun({}, [])

    def feed(m: Measurement) -> None:
        out = tracker.process(m)
        for e in (out.estimate, *out.fused_again):
            if e is not None:
                run.estimates[e.t] = e

    events = sorted([(m.t, 0, m) for m in sim.real] + [(float(t), 1, None) for t in sim.t],
                    key=lambda e: (e[0], e[1]))
    for t, _, m in events:
        forecasts = surrogate.add(m) if m is not None else surrogate.due(t)
        run.forecasts.extend(forecasts)
        for f in forecasts:
            feed(f)
        if m is not None:
            feed(m)
    return run


@dataclass
class SkyEvaluation:
    """A real-sky run scored: the passes and gaps, the arms over the scheduled outage, and
    how many forecasts the surrogate made."""

    passes: PassReport
    outage: arms.GapEvaluation | None
    forecasts: int


def evaluate_sky(sim: SkySimulation, seed: int = 0,
                 only: tuple[arms.ArmName, ...] = tuple(arms.ArmName)) -> SkyEvaluation:
    """Run the scenario's graph (filter and surrogate) over the delivered measurements and
    score it: after each pass, at every truth epoch, and every arm over the scheduled
    outage (`outage_epochs`)."""
    s = sim.scenario
    c = s.estimator()
    real, withheld = sim.real, sim.withheld_measurements
    run = run_dmd_ekf(sim)
    report = pass_report(c, run.estimates, real, sim.t, sim.x)
    outage = None
    if s.outages and withheld:
        t_gap = outage_epochs(sim.t, withheld)
        outage = arms.evaluate_gap(c, run.estimates, real, withheld, t_gap,
                                   sim.x[np.isin(sim.t, t_gap)], seed, only=only)
    return SkyEvaluation(report, outage, len(run.forecasts))

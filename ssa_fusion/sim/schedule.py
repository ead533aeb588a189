"""What the simulator node publishes, and when: a run's schedule and its pace, without ROS.

`plan` turns sensor_sim's settings (`SimSettings`, named as its parameters) into a `Plan`:

* a paper scenario (`sim.scenarios`): one idealised sensor measuring at every epoch of its
  cadence, the epochs of the scheduled outages withheld, and the truth at each epoch;
* a real-sky scenario (`sim.sky`): the truth on its cadence and what its stations measured
  (above their masks, optical ones only at night, of a sunlit object), in epoch order;
* a catalog: every object's measurements by the scenario's radars (`sim.survey`), published
  as rows (`CatalogRun.rows`), without a truth topic.

`Pace` says which scheduled epochs are due: in the open loop those up to the clock (sim time
following the wall clock), in lockstep one object's from one scheduled epoch to the next,
each in up to four phases (`Pace.object_step`, `Phase`). `CatalogPace` does the same for a
catalog's measurements, a window at a time (in lockstep steps of ``lockstep_step``,
computed ahead). Settings that give no run raise
`ScheduleError`, whose message names the parameters (the node reports it as a parameter
error). Units: s (sim time is Unix s UTC for orbits), the core's km and rad.
"""

from __future__ import annotations

import enum
import math
from collections.abc import Callable
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from ssa_fusion.core.base import types
from ssa_fusion.core.base.rows import MeasurementRows
from ssa_fusion.core.earth import timescales
from ssa_fusion.core.earth.frames import Frame
from ssa_fusion.formats import element_sets
from ssa_fusion.formats.skipped import Skipped
from ssa_fusion.sim import scenarios, sky, survey
from ssa_fusion.sim.simulate import Simulation, simulate
from ssa_fusion.sim.world import TruthModel


class Event(enum.IntEnum):
    """What a scheduled publication is."""

    TRUTH = 0
    MEASUREMENT = 1
    WITHHELD = 2


Schedule = list[tuple[float, Event, types.Measurement | types.StateEstimate]]
"""Publications in epoch order: (epoch s, what, the message's content)."""


class Phase(enum.IntEnum):
    """A phase of one object's lockstep step to the next scheduled epoch e (`Pace.object_step`).

    Each phase is published once every consumer took all of the one before; a release no
    consumer has anything for is left out (`Pace.object_step`'s `wants`).
    """

    FORECASTS = 0
    """The surrogate forecasts the epochs it missed before e (up to the step's `t`)."""
    DECISIONS = 1
    """The filter publishes what it decides for the epochs before e (up to the step's `t`):
    after the forecasts of those epochs reached it."""
    CLOCK = 2
    """/clock moves to e (alone: a message published after it in the same phase could reach
    the recorder before it, a reliable writer's repair overtaking it, and be logged at the
    clock before)."""
    EVENTS = 3
    """The measurements, withheld measurements and truth at e."""


RELEASE_MARGIN_S = 1e-3
"""The releases before an epoch e end this much (s) before it: e's own measurement comes
first, whatever round-off says of epochs computed on a grid."""


@dataclass(frozen=True)
class ObjectStep:
    """One phase of one object's lockstep: what to publish (`phase`), at or up to `t` (s).

    `events`: the schedule's indices to publish (`Phase.EVENTS` only).
    """

    phase: Phase
    t: float
    events: range = range(0)


class ScheduleError(ValueError):
    """The settings give no run; the message names the parameters and says why."""


@dataclass(frozen=True)
class SimSettings:
    """What to simulate, as sensor_sim's parameters of the same names say.

    Attributes
    ----------
    object_id : str
        The object id of a scenario's messages.
    cadence : float
        Time between measurements (real sky: between truth samples), s.
    duration : float
        Real sky and catalogs: sim time to run, s (0: the scenario's).
    start : float or None
        Real sky and catalogs: the first epoch, Unix s (None: the scenario's or catalog's).
    gap_start, gap_length, after_gap : float
        A paper scenario's tracking before its one gap, the gap, tracking after it, s.
    gaps : tuple of float
        Outages as pairs (start s, length s) after the first epoch; (0.0,) = the one gap of
        `gap_start` and `gap_length` (a real-sky scenario: its own outages).
    noise_sigma : tuple of float or None
        A paper scenario's noise standard deviation per channel in the core's units (km,
        rad); None: the scenario's.
    seed : int
        Noise random seed (and a high-fidelity world's space weather).
    truth : str
        Real sky: the object's truth (`world.TruthModel`).
    geometry_seed : int
        Real sky: turn the orbit as case ``geometry_seed`` (`sky.case_geometry`); -1: the
        scenario's own orbit.
    catalog : str
        Element sets of the objects to simulate instead of one ('' = none).
    objects, synthetic : int
        Catalog: only the first `objects` (0 = all); its first element set spread into
        `synthetic` objects (0 = the catalog's own).
    """

    object_id: str
    cadence: float
    duration: float = 0.0
    start: float | None = None
    gap_start: float = 0.0
    gap_length: float = 0.0
    gaps: tuple[float, ...] = (0.0,)
    after_gap: float = 0.0
    noise_sigma: tuple[float, ...] | None = None
    seed: int = 0
    truth: str = "sgp4"
    geometry_seed: int = -1
    catalog: str = ""
    objects: int = 0
    synthetic: int = 0


@dataclass(frozen=True)
class CatalogRun:
    """A catalog's measurements, a window at a time, and what their rows carry.

    Attributes
    ----------
    stream : survey.ObservationStream
        Every measurement, in epoch order, computed a window of sim time at a time.
    object_ids : ndarray (N,) of str
        Each object's id (index: a measurement's ``obj``).
    frames : ndarray (S,) of str
        Each sensor's station (frame_id; index: a measurement's ``sensor``).
    R : ndarray (S, 3, 3)
        Each sensor's measurement noise covariance, km², rad².
    skipped : Skipped
        The bad element sets of the file, left out (`formats.skipped`).
    """

    stream: survey.ObservationStream
    object_ids: NDArray[np.object_]
    frames: NDArray[np.object_]
    R: NDArray[np.float64]
    skipped: Skipped = field(default_factory=Skipped)

    def rows(self, obs: survey.Observations, keys: NDArray[np.uint32]) -> MeasurementRows:
        """Return measurements `obs` (a window of `stream`) as rows.

        `keys`: each object's shard key.
        """
        return MeasurementRows(
            t=obs.t, object_id=self.object_ids[obs.obj].tolist(),
            frame_id=self.frames[obs.sensor].tolist(), z=obs.z, R=self.R[obs.sensor],
            shard_key=keys[obs.obj])


@dataclass(frozen=True)
class Plan:
    """A run: its schedule (or catalog), the epochs to publish, and a line for the log.

    `times` are the epochs in publication order, s: the schedule's; for a catalog its first
    and last epoch (its measurements come window by window: `CatalogPace`).
    """

    schedule: Schedule
    catalog: CatalogRun | None
    times: NDArray[np.float64]
    summary: str


def resolve(name: str, sites: str = "",
            elements: str = "") -> tuple[scenarios.Scenario, sky.SkyScenario | None]:
    """Return the paper scenario of scenario `name`, and the real-sky one or None.

    For a real-sky scenario the paper scenario is the default live one, and the real-sky
    one observes with the sites of the file `sites` and the first object of the element
    set file `elements` when given ('' = the scenario's own). ValueError names an unknown
    scenario or an unreadable file.
    """
    real_sky = sky.SKY_SCENARIOS.get(name)
    if real_sky is None:
        return scenarios.get(name), None
    if sites:
        real_sky = real_sky.with_sites(sites)
    if elements:
        real_sky = real_sky.with_elements(elements)
    return scenarios.DEFAULT_LIVE, real_sky


def paper_schedule(sim: Simulation, in_gap: NDArray[np.bool_], object_id: str) -> Schedule:
    """Return a measurement (or a withheld one) and the truth per epoch of a paper scenario."""
    s = sim.scenario
    out: Schedule = []
    for i, t in enumerate(sim.t.tolist()):
        m = types.Measurement(t=t, z=sim.z[i], R=sim.R, kind=s.kind, object_id=object_id,
                              frame_id=s.station or Frame.GCRF)
        out.append((t, Event.WITHHELD if in_gap[i] else Event.MEASUREMENT, m))
        out.append((t, Event.TRUTH, types.StateEstimate(t=t, x=sim.x[i], object_id=object_id)))
    return out


def sky_schedule(sim: sky.SkySimulation, object_id: str) -> Schedule:
    """Return the truth on its cadence and the stations' measurements in epoch order."""
    out: Schedule = [(t, Event.TRUTH, types.StateEstimate(t=t, x=x, object_id=object_id))
                     for t, x in zip(sim.t.tolist(), sim.x, strict=True)]
    for m, w in zip(sim.measurements, sim.withheld, strict=True):
        m.object_id = object_id
        out.append((m.t, Event.WITHHELD if w else Event.MEASUREMENT, m))
    out.sort(key=lambda e: (e[0], -e[1]))  # at one epoch: measurements before the truth
    return out


def check_window(t0: float, span: float) -> None:
    """Refuse a run whose start `t0` or end `t0` + `span` (Unix s) cannot be represented.

    `ScheduleError` naming ``start`` and ``duration``, from `timescales.check_window`.
    """
    try:
        timescales.check_window(t0, span)
    except ValueError as exc:
        raise ScheduleError(f"parameters 'start', 'duration': {exc}") from exc


def _gap_pairs(s: SimSettings) -> list[float]:
    """Return the outages as [start, length, ...] s after the first epoch: `gaps`, or one gap."""
    return list(s.gaps) if list(s.gaps) != [0.0] else [s.gap_start, s.gap_length]


def paper_plan(base: scenarios.Scenario, s: SimSettings) -> Plan:
    """Return the run of paper scenario `base` with the settings' cadence, gaps and noise."""
    pairs = _gap_pairs(s)
    windows = [(pairs[i], pairs[i] + pairs[i + 1]) for i in range(0, len(pairs), 2)]
    last_end = max(end for _, end in windows)
    scenario = base.with_(cadence_s=s.cadence, track_s=pairs[0], gap_s=pairs[1],
                          after_s=max(0.0, last_end + s.after_gap - pairs[0] - pairs[1]))
    if s.noise_sigma is not None:
        scenario = scenario.with_(noise_sigma=s.noise_sigma, noise_rel=0.0)
    try:
        sim = simulate(scenario, seed=s.seed)
    except ValueError as exc:
        raise ScheduleError(f"cannot simulate scenario {base.name!r}: {exc}") from exc
    rel = sim.t - scenario.t0
    in_gap = np.zeros(len(rel), dtype=bool)
    for start, end in windows:
        in_gap |= (rel >= start) & (rel < end)
    schedule = paper_schedule(sim, in_gap, s.object_id)
    return Plan(schedule, None, np.array([e[0] for e in schedule]),
                f"{len(sim.t)} epochs every {s.cadence} s, gaps {windows} s")


def sky_plan(real_sky: sky.SkyScenario, s: SimSettings) -> Plan:
    """Return the run of real-sky scenario `real_sky` (the settings' `gaps`: outages)."""
    t0 = real_sky.t0 if s.start is None else s.start
    span = s.duration or real_sky.duration_s
    check_window(t0, span)  # what with_window would refuse, as a parameter error
    run = real_sky.with_window(t0, span).with_(
        truth_cadence_s=s.cadence, truth=TruthModel(s.truth),
        world=real_sky.world.with_(weather_seed=s.seed))
    if s.geometry_seed >= 0:
        try:
            run = run.with_geometry(*sky.case_geometry(s.geometry_seed))
        except ValueError as exc:
            raise ScheduleError(f"parameter 'geometry_seed': {exc}") from exc
    if list(s.gaps) != [0.0]:
        run = run.with_(outages=tuple((sky.ALL_STATIONS, s.gaps[i], s.gaps[i + 1])
                                      for i in range(0, len(s.gaps), 2)))
    try:
        sim = sky.simulate_sky(run, seed=s.seed, object_id=s.object_id)
    except ValueError as exc:
        raise ScheduleError(f"cannot simulate scenario {real_sky.name!r}: {exc}") from exc
    schedule = sky_schedule(sim, s.object_id)
    return Plan(schedule, None, np.array([e[0] for e in schedule]),
                f"{len(sim.measurements)} measurements ({int(sim.withheld.sum())} withheld) "
                f"from {', '.join(run.sensors)} from {timescales.iso(run.t0)} over "
                f"{run.duration_s / 3600:g} h, truth every "
                f"{s.cadence} s, outages {list(run.outages)}, {run.truth} truth")


def catalog_plan(real_sky: sky.SkyScenario, s: SimSettings) -> Plan:
    """Return the run of the settings' catalog, observed by `real_sky`'s radars.

    Over ``duration`` (0: the scenario's) from ``start`` (None: the catalog's first element
    set epoch). No truth in the schedule: the truth is SGP4 of the catalog, recomputed by
    whoever scores the run.
    """
    skipped = Skipped()
    try:
        entries = element_sets.read_catalog(s.catalog, skip=skipped)
    except ValueError as exc:
        raise ScheduleError(f"parameter 'catalog' = {s.catalog!r}: {exc}") from exc
    if s.synthetic:
        entries = survey.synthetic_catalog(entries[0], s.synthetic, seed=s.seed)
    if s.objects:
        entries = entries[:s.objects]
    radars = real_sky.radars
    if not radars:
        raise ScheduleError(f"scenario {real_sky.name!r} has no radar to observe a catalog")
    t0 = survey.catalog_start(entries) if s.start is None else s.start
    span = s.duration or real_sky.duration_s
    check_window(t0, span)
    stream = survey.ObservationStream(entries, radars, t0, span, seed=s.seed)
    run = CatalogRun(stream, np.asarray(list(stream.object_ids), dtype=object),
                     np.asarray([x.station.name for x in radars], dtype=object),
                     np.array([r.R for r in radars], dtype=float), skipped)
    left_out = f" ({skipped.count} bad element sets left out)" if skipped.count else ""
    return Plan([], run, np.array([stream.start, stream.end]),
                f"catalog {s.catalog}{left_out}: {len(entries)} objects measured by "
                f"{', '.join(r.station.name for r in radars)} over {span / 3600:g} h "
                f"from {timescales.iso(t0)}, a window at a time")


def plan(name: str, base: scenarios.Scenario, real_sky: sky.SkyScenario | None,
         s: SimSettings) -> Plan:
    """Return the run of scenario `name` (`resolve`'s `base` and `real_sky`) and settings `s`.

    A catalog needs a real-sky scenario. `ScheduleError` when the settings give nothing to
    publish (a catalog always has its epochs: whether any object is seen then, its stream
    tells as it goes).
    """
    if s.catalog:
        if real_sky is None:
            raise ScheduleError(f"scenario {name!r}: a catalog needs a real-sky scenario")
        out = catalog_plan(real_sky, s)
    elif real_sky is None:
        out = paper_plan(base, s)
    else:
        out = sky_plan(real_sky, s)
    if not out.times.size:
        raise ScheduleError(
            f"scenario {name!r}: nothing to publish (no measurement and no truth epoch)")
    return out


@dataclass
class Pace:
    """Which of a run's epochs are due, in the open loop or in lockstep.

    Attributes
    ----------
    times : ndarray (N,)
        The epochs in publication order, s.
    step_s : float
        Lockstep: sim time per step, s.
    next : int
        The first epoch not published yet.
    sim_now : float
        Lockstep: the end of the last step published, s (at first: the first epoch).
    clock_behind : bool
        Lockstep: the last step's measurements are out and its clock not yet.
    phase : Phase
        One object's lockstep: the next phase (`object_step`).
    released : float
        One object's lockstep: the time up to which forecasts and decisions were released, s.
    """

    times: NDArray[np.float64]
    step_s: float = math.inf
    next: int = 0
    sim_now: float = field(init=False)
    clock_behind: bool = False
    phase: Phase = Phase.FORECASTS
    released: float = -math.inf

    def __post_init__(self) -> None:
        """Start at the first epoch."""
        self.sim_now = float(self.times[0])

    @property
    def done(self) -> bool:
        """Return True once every epoch is published."""
        return self.next >= len(self.times)

    def due(self, now: float) -> range:
        """Return the epochs not published yet up to sim time `now` (s), now published."""
        stop = int(np.searchsorted(self.times, now, side="right"))
        out = range(self.next, stop)
        self.next = max(self.next, stop)
        return out

    def step(self, ceiling: float) -> range | None:
        """Return the next lockstep step's epochs, now published (its clock then behind).

        None while its end would pass `ceiling` (s: the time scale's limit).
        """
        target = self.sim_now + self.step_s
        if target > ceiling:
            return None
        self.sim_now = target
        self.clock_behind = True
        return self.due(target)

    @property
    def object_done(self) -> bool:
        """Return True once one object's lockstep published everything and its releases."""
        return self.done and self.phase == Phase.CLOCK

    def object_step(self, ceiling: float,
                    wants: Callable[[Phase, float], bool]) -> ObjectStep | None:
        """Return the next phase of one object's lockstep (see `Phase`), now published.

        For each scheduled epoch e in turn: the forecasts and then the decisions up to e -
        `RELEASE_MARGIN_S`, each only when `wants(phase, t)` says a consumer has something
        to release up to t; then /clock e (None while e is past `ceiling`, s: the time
        scale's limit), then the events at e. After the last epoch, the releases up to it;
        then None (`object_done`).
        """
        while self.phase in (Phase.FORECASTS, Phase.DECISIONS):
            phase = self.phase
            self.phase = Phase(phase + 1)
            t = float(self.times[-1]) if self.done else float(self.times[self.next]) - \
                RELEASE_MARGIN_S
            if t > self.released and wants(phase, t):
                if phase == Phase.DECISIONS:
                    self.released = t
                return ObjectStep(phase, t)
        if self.done:
            return None
        e = float(self.times[self.next])
        if self.phase == Phase.CLOCK:
            if e > ceiling:
                return None
            self.sim_now = e
            self.phase = Phase.EVENTS
            return ObjectStep(Phase.CLOCK, e)
        self.phase = Phase.FORECASTS
        return ObjectStep(Phase.EVENTS, e, self.due(e))

class CatalogPace:
    """Which of a catalog's measurements are due, a window at a time (`CatalogRun.stream`).

    In the open loop `due` computes the window up to the clock. In lockstep `step` hands out
    the next ``step_s`` of sim time's measurements, computed ahead: the first window is
    started at once, and each next one in a worker thread as soon as the last is handed out,
    while the consumers take it (SGP4 and numpy release the interpreter's lock for most of
    it). At most the window handed out and the next one are in memory, whatever the run's
    length. Attributes as `Pace`'s.
    """

    def __init__(self, run: CatalogRun, step_s: float = math.inf) -> None:
        self.run, self.step_s = run, step_s
        self.sim_now = run.stream.start
        self.clock_behind = False
        self.published = 0
        """Measurements handed out so far."""
        self._pool = ThreadPoolExecutor(1, thread_name_prefix="catalog_window") \
            if math.isfinite(step_s) else None
        self._ahead: Future[survey.Observations] | None = None
        self._ahead_until = -math.inf
        if self._pool is not None:
            self._prepare(self.sim_now + step_s)

    @property
    def done(self) -> bool:
        """Return True once every epoch of the stream is handed out."""
        return self.run.stream.done and self._ahead is None

    def due(self, now: float) -> survey.Observations:
        """Return the measurements not handed out yet up to sim time `now` (s), now handed out."""
        return self._out(self.run.stream.until(now))

    def step(self, ceiling: float) -> survey.Observations | None:
        """Return the next lockstep step's measurements, now handed out (its clock then behind).

        None while its end would pass `ceiling` (s: the time scale's limit). Waits for the
        window computed ahead if it is not ready yet.
        """
        target = self.sim_now + self.step_s
        if target > ceiling:
            return None
        if self._ahead is not None and self._ahead_until == target:
            window, self._ahead = self._ahead.result(), None
        else:
            window = self.run.stream.until(target)
        self.sim_now = target
        self.clock_behind = True
        if not self.run.stream.done:
            self._prepare(target + self.step_s)
        return self._out(window)

    def close(self) -> None:
        """Stop the worker thread (a window in progress is finished and dropped)."""
        if self._pool is not None:
            self._pool.shutdown(wait=True, cancel_futures=True)

    def _prepare(self, until: float) -> None:
        """Start computing the window up to `until` (s) in the worker thread."""
        assert self._pool is not None and self._ahead is None
        self._ahead_until = until
        self._ahead = self._pool.submit(self.run.stream.until, until)

    def _out(self, window: survey.Observations) -> survey.Observations:
        self.published += len(window)
        return window

"""`ssa-fusion import crd`'s reading: the two-way normal points of CRD files, as ranges.

`read_laser_ranges` reads CRD files (`crd.CrdReader`, streamed) and keeps, per normal point,
its transmit epoch, its range and its station and target, and every meteorological record
(20), in compact arrays. A normal point's range is the ILRS's: c x the two-way time of
flight / 2 (km); its epoch the transmit epoch at the station, from the record's epoch
event: the epoch itself (2, transmit), the epoch - time of flight (0, receive), the
epoch - time of flight / 2 (1, bounce: exact to ~50 ns, the legs' difference).

Refused, each with one line naming the file and the line of the session's H4 or of the
record (`records.RecordError`): full-rate sessions (record 10: form normal points first),
ranges that are not two-way (H4 range type), ranges with the troposphere or the
centre-of-mass correction applied (the model applies them) or without the station's system
delay applied (not calibrated), an epoch event that is not two-way, a system configuration
without its C0 (the wavelength), a target whose sessions give different NORAD numbers.
A point given twice (the same station and transmit epoch) is kept once and counted.

Station ids are the stations' 4-digit CDP pad ids ("7090": their SINEX site code); an
object's id its NORAD number ("22195"), or ``ilrs-<ILRS id>`` when no session gives it.
"""

from __future__ import annotations

from array import array
from collections.abc import Iterable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from ssa_fusion.core.base.constants import C_KM_S
from ssa_fusion.core.measure.troposphere import MeteoSample
from ssa_fusion.formats.ilrs.crd import CrdReader
from ssa_fusion.formats.ilrs.crd_records import (
    TWO_WAY_EVENTS,
    CrdSession,
    DataType,
    EpochEvent,
    MeteoRecord,
    RangeRecord,
    RangeType,
)
from ssa_fusion.formats.records import RecordError

Array = NDArray[np.float64]


@dataclass
class CrdStation:
    """What the CRD files say of one station: name, wavelengths, span and counts."""

    station_id: str
    name: str
    wavelengths_nm: set[float] = field(default_factory=set)
    first: float = np.inf
    last: float = -np.inf
    points: int = 0
    meteo: int = 0
    sessions: int = 0


@dataclass
class CrdTarget:
    """A target of the CRD files: ILRS id, NORAD number (None if no session gives it), name."""

    ilrs_id: int
    norad: int | None
    name: str

    @property
    def object_id(self) -> str:
        """The id its measurements carry (module docstring)."""
        return str(self.norad) if self.norad is not None else f"ilrs-{self.ilrs_id}"


@dataclass
class LaserRanges:
    """The normal points of CRD files, sorted by transmit epoch (module docstring).

    Attributes
    ----------
    t
        Transmit epochs (n,), Unix s (UTC).
    range_km
        c x two-way time of flight / 2 (n,), km.
    station
        Index of each point's station in `stations` (n,).
    target
        Index of each point's target in `targets` (n,).
    wavelength_nm
        The transmit wavelength of each point's configuration (n,), nm.
    stations, targets
        By station id and by ILRS id, in the order first read.
    meteo
        The meteorological records (20), in file order.
    duplicates
        Points given twice (kept once).
    sessions
        Sessions read.
    """

    t: Array
    range_km: Array
    station: NDArray[np.intp]
    target: NDArray[np.intp]
    wavelength_nm: Array
    stations: dict[str, CrdStation]
    targets: dict[int, CrdTarget]
    meteo: list[MeteoSample]
    duplicates: int = 0
    sessions: int = 0

    def __len__(self) -> int:
        """Return the number of points."""
        return len(self.t)

    @property
    def station_ids(self) -> list[str]:
        """The station ids in the order `station` indexes them."""
        return list(self.stations)

    @property
    def object_ids(self) -> list[str]:
        """The object ids in the order `target` indexes them."""
        return [t.object_id for t in self.targets.values()]


def _transmit_epoch(r: RangeRecord) -> float:
    """Return the transmit epoch of a two-way range (module docstring)."""
    if r.epoch_event == EpochEvent.GROUND_TRANSMIT:
        return r.t
    if r.epoch_event == EpochEvent.GROUND_RECEIVE:
        return r.t - r.time_of_flight_s
    return r.t - 0.5 * r.time_of_flight_s


class _Reading:
    """The state of `read_laser_ranges`: the points and records so far."""

    def __init__(self) -> None:
        self.t, self.rng, self.wl = array("d"), array("d"), array("d")
        self.station, self.target = array("q"), array("q")
        self.stations: dict[str, CrdStation] = {}
        self.targets: dict[int, CrdTarget] = {}
        self.meteo: list[MeteoSample] = []
        self.judged: set[int] = set()
        self.sessions = 0

    def session(self, s: CrdSession, path: str) -> None:
        """Take a session's headers: its station and target."""
        self.sessions += 1
        sid = str(s.pad)
        st = self.stations.setdefault(sid, CrdStation(sid, s.station_name))
        st.sessions += 1
        tg = self.targets.setdefault(s.ilrs_id, CrdTarget(s.ilrs_id, s.norad, s.target_name))
        if s.norad is not None and tg.norad is None:
            tg.norad = s.norad
        elif s.norad is not None and s.norad != tg.norad:
            raise RecordError(f"{path}:{s.line}: target {s.ilrs_id} ({s.target_name}) has "
                              f"NORAD id {s.norad} here, {tg.norad} in a session before")

    def judge(self, s: CrdSession, path: str) -> None:
        """Refuse a session whose ranges this importer cannot model (module docstring)."""
        where = f"{path}:{s.line}: session {s.number} (station {s.pad} {s.station_name})"
        if s.data_type != DataType.NORMAL_POINT:
            raise RecordError(f"{where}: full-rate ranges (H4 data type {int(s.data_type)}, "
                              f"record 10): `import crd` takes normal points (record 11); "
                              f"form normal points first")
        why = ("" if s.range_type == RangeType.TWO_WAY else
               f"range type {int(s.range_type)} ({s.range_type.name.lower()}): not two-way")
        why = why or ("the troposphere correction is applied (the model applies its own)"
                      if s.troposphere_applied else "")
        why = why or ("the centre-of-mass correction is applied (the model applies its own)"
                      if s.com_applied else "")
        why = why or ("the station's system delay is not applied: the ranges are not "
                      "calibrated" if not s.station_delay_applied else "")
        if why:
            raise RecordError(f"{where}: {why}")

    def point(self, r: RangeRecord, path: str) -> None:
        """Take one normal point."""
        s = r.session
        if id(s) not in self.judged:
            self.judge(s, path)
            self.judged.add(id(s))
        if r.epoch_event not in TWO_WAY_EVENTS:
            raise RecordError(f"{path}:{r.line}: record 11: epoch event {int(r.epoch_event)} "
                              f"({r.epoch_event.name.lower()}): not a two-way range's")
        wl = s.wavelengths_nm.get(r.config_id)
        if wl is None:
            raise RecordError(f"{path}:{r.line}: record 11: system configuration "
                              f"{r.config_id!r} has no C0 record: its wavelength is unknown")
        t = _transmit_epoch(r)
        st = self.stations[str(s.pad)]
        st.points += 1
        st.first, st.last = min(st.first, t), max(st.last, t)
        st.wavelengths_nm.add(wl)
        self.t.append(t)
        self.rng.append(0.5 * C_KM_S * r.time_of_flight_s)
        self.wl.append(wl)
        self.station.append(list(self.stations).index(str(s.pad)))
        self.target.append(list(self.targets).index(s.ilrs_id))

    def weather(self, m: MeteoRecord) -> None:
        """Take one meteorological record."""
        sid = str(m.session.pad)
        self.stations[sid].meteo += 1
        self.meteo.append(MeteoSample(m.t, sid, m.pressure_hpa, m.temperature_k,
                                      m.humidity_pct))

    def result(self) -> LaserRanges:
        """Return the points, sorted by epoch, a point given twice once."""
        t = np.frombuffer(self.t, dtype=float) if self.t else np.zeros(0)
        st = np.frombuffer(self.station, dtype=np.int64) if self.station else \
            np.zeros(0, np.int64)
        order = np.lexsort((st, t))
        keep = np.ones(len(t), bool)
        keep[1:] = (np.diff(t[order]) != 0) | (np.diff(st[order]) != 0)
        idx = order[keep]

        def floats(a: array[float]) -> Array:
            return np.asarray(a, dtype=float)[idx]

        def ints(a: array[int]) -> NDArray[np.intp]:
            return np.asarray(a, dtype=np.intp)[idx]

        return LaserRanges(t=floats(self.t), range_km=floats(self.rng),
                           station=ints(self.station), target=ints(self.target),
                           wavelength_nm=floats(self.wl), stations=self.stations,
                           targets=self.targets, meteo=self.meteo,
                           duplicates=int(len(t) - len(idx)), sessions=self.sessions)


def read_laser_ranges(paths: Iterable[Path | str]) -> LaserRanges:
    """Return the normal points and meteorological records of CRD files (module docstring).

    `records.RecordError` (one line) for a file that is not a CRD file, or holds what the
    importer does not take; a file set without any normal point is refused.
    """
    files = [str(p) for p in paths]
    state = _Reading()
    for name in files:
        for item in CrdReader(name):
            if isinstance(item, CrdSession):
                state.session(item, name)
            elif isinstance(item, RangeRecord):
                state.point(item, name)
            elif isinstance(item, MeteoRecord):
                state.weather(item)
    out = state.result()
    if not len(out):
        raise RecordError(f"{', '.join(files)}: no normal point (record 11) in "
                          f"{state.sessions} session(s)")
    return out

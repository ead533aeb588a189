"""What a radar network measures of a whole catalog, vectorised over objects and epochs.

`observe_catalog` propagates every object of a catalog with SGP4/SDP4 (`catalog`) at each
radar's cadence, keeps the epochs where the object is above the radar's elevation mask, and
adds the radar's noise: one array of measurements for the whole catalog, in epoch order.
`synthetic_catalog` spreads one real element set into many objects (a test catalog of any
size when no real one of that size is at hand); `satellite_train` and `crossing_trains` make
crowded catalogs (objects launched together, a few km apart, and two such groups crossing
over a station). `Observations.scans` hands the measurements out as a radar reports them:
one scan per sensor and epoch, without object ids, the truth kept aside for scoring.

Units and frames as in the rest of the core: epochs Unix seconds (UTC), range km, azimuth
(from north, clockwise, [0, 2π)) and elevation rad, states GCRF km, km/s.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from sgp4.api import WGS72, Satrec, SatrecArray

from ssa_fusion.core.base.constants import MU_EARTH, R_EARTH
from ssa_fusion.core.earth.frames import (
    Station,
    enu_matrix,
    gcrs_to_itrs_matrix,
    razel_itrs,
    site_gcrs,
    teme_to_gcrs_matrix,
)
from ssa_fusion.core.earth.stations import Sensor, SensorType
from ssa_fusion.core.earth.timescales import DAY_S, UNIX_EPOCH_JD, jd_utc
from ssa_fusion.core.motion.element_sets import CatalogEntry

SGP4_EPOCH_JD = 2433281.5
"""Julian date of SGP4's epoch origin (1949 December 31 00:00 UTC), for `Satrec.sgp4init`."""


@dataclass(frozen=True)
class Observations:
    """Measurements of a catalog by a radar network, in epoch order (ties: sensor order).

    Attributes
    ----------
    t : ndarray (M,)
        Epochs, Unix seconds (UTC).
    obj : ndarray (M,) of int
        Index of the measured object in `object_ids`.
    sensor : ndarray (M,) of int
        Index of the measuring sensor in `sensors`.
    z : ndarray (M, 3)
        Range km, azimuth rad in [0, 2π), elevation rad, with the sensor's noise.
    object_ids : tuple of str
    sensors : tuple of Sensor
    """

    t: NDArray[np.float64]
    obj: NDArray[np.int64]
    sensor: NDArray[np.int64]
    z: NDArray[np.float64]
    object_ids: tuple[str, ...]
    sensors: tuple[Sensor, ...]

    def __len__(self) -> int:
        """Return the number of measurements."""
        return int(self.t.size)

    def per_object(self) -> NDArray[np.int64]:
        """Return the number of measurements (len(object_ids),) of each object."""
        return np.bincount(self.obj, minlength=len(self.object_ids)).astype(np.int64)

    def scans(self, seed: int = 0) -> list[Scan]:
        """Return the measurements as unlabelled scans, one per sensor and epoch.

        In epoch order (ties: sensor order); within a scan the detections are shuffled
        (`seed`), so that their order tells nothing of the objects (`observe_catalog`
        orders them by object).
        """
        rng = np.random.default_rng(seed)
        if not len(self):
            return []
        cut = np.flatnonzero((np.diff(self.t) != 0) | (np.diff(self.sensor) != 0)) + 1
        out = []
        for a, b in zip(np.r_[0, cut].tolist(), np.r_[cut, len(self)].tolist(), strict=True):
            idx = a + rng.permutation(b - a)
            out.append(Scan(float(self.t[a]), int(self.sensor[a]), self.z[idx], self.obj[idx],
                            idx))
        return out


@dataclass(frozen=True)
class Scan:
    """One sensor's detections at one epoch, without object ids (`Observations.scans`).

    Attributes
    ----------
    t : float
        Epoch, Unix s (UTC).
    sensor : int
        Index of the sensor in `Observations.sensors`.
    z : ndarray (M, 3)
        Range km, azimuth rad in [0, 2π), elevation rad.
    truth : ndarray (M,) of int
        The object of each detection (index in `Observations.object_ids`): for scoring only,
        never for the association.
    index : ndarray (M,) of int
        Each detection's index in the `Observations`.
    """

    t: float
    sensor: int
    z: NDArray[np.float64]
    truth: NDArray[np.int64]
    index: NDArray[np.int64]


def catalog_start(entries: Sequence[CatalogEntry]) -> float:
    """Return where a simulation of the catalog starts (Unix s).

    The first whole minute at or after the newest element set's epoch: no object is
    propagated backwards.
    """
    return 60.0 * math.ceil(max(e.epoch_unix for e in entries) / 60.0)


def observe_catalog(entries: Sequence[CatalogEntry], sensors: Sequence[Sensor], t0: float,
                    duration_s: float, seed: int = 0,
                    chunk_states: int = 2_000_000) -> Observations:
    """Simulate radar measurements of a catalog (reproducible by `seed`).

    Every object of `entries` measured by `sensors` from Unix time `t0` for `duration_s` s,
    one noise stream per sensor: the windows of an `ObservationStream` over the whole span,
    joined (the same measurements, whatever the windows).

    Each sensor measures at the multiples of its ``cadence_s`` after `t0` where the object
    is at or above its elevation mask (by azimuth where it has one) and within its maximum
    range (`Sensor.in_view`); no light time. Objects
    SGP4 cannot propagate at an epoch (decayed) are not measured then. The states are
    computed `chunk_states` (object x epoch) at a time, bounding memory at ~100 B each.
    ValueError for an optical sensor (only radars are supported here).
    """
    stream = ObservationStream(entries, sensors, t0, duration_s, seed, chunk_states)
    return stream.until(math.inf)


class ObservationStream:
    """A radar network's measurements of a catalog, a window of sim time at a time.

    `until` returns the measurements of the epochs after the last window's up to a sim
    time, in epoch order: each object's SGP4/SDP4 state is computed once per epoch of any
    sensor (`sgp4.api.SatrecArray`, vectorised), turned from TEME to the ITRF by one matrix
    per epoch (`frames.teme_to_gcrs_matrix` then `frames.gcrs_to_itrs_matrix`), and only
    the objects above a sensor's lowest elevation and within its range get their range,
    azimuth and elevation computed. Memory is bounded by the window's `chunk_states`
    (object x epoch, ~100 B each) and its measurements, never the run's.

    The noise is drawn per sensor in (epoch, object) order from one stream per sensor
    (`seed`), so the measurements do not depend on how the span is cut into windows.
    Parameters as `observe_catalog`'s; ValueError for an optical sensor.
    """

    def __init__(self, entries: Sequence[CatalogEntry], sensors: Sequence[Sensor], t0: float,
                 duration_s: float, seed: int = 0, chunk_states: int = 2_000_000) -> None:
        for sensor in sensors:
            if sensor.type != SensorType.RADAR:
                raise ValueError(f"sensor at {sensor.station.name!r} is {sensor.type}: "
                                 "observe_catalog simulates radars only")
        self.object_ids = tuple(e.object_id for e in entries)
        self.sensors = tuple(sensors)
        self._sats = SatrecArray([e.satrec for e in entries]) if entries else None
        self._rngs = np.random.default_rng(seed).spawn(len(sensors))
        self._grids = [t0 + s.cadence_s * np.arange(int(duration_s // s.cadence_s) + 1)
                       for s in sensors]
        self._next = [0] * len(sensors)
        self._chunk = max(1, chunk_states // max(len(entries), 1))
        self.start = float(t0)
        """The first epoch, Unix s."""
        self.end = max((float(g[-1]) for g in self._grids), default=float(t0))
        """The last epoch of any sensor, Unix s."""

    @property
    def done(self) -> bool:
        """Return True once every epoch of every sensor is in a window."""
        return all(k >= g.size for k, g in zip(self._next, self._grids, strict=True))

    def until(self, t_stop: float) -> Observations:
        """Return the measurements of the epochs after the last window up to `t_stop` (s).

        In epoch order (ties: sensor, then object order); empty when no epoch is due.
        """
        stops = [int(np.searchsorted(g, t_stop, side="right")) for g in self._grids]
        epochs = [g[a:b] for g, a, b in zip(self._grids, self._next, stops, strict=True)]
        self._next = stops
        found: list[list[tuple[NDArray[np.float64], NDArray[np.int64]]]] = [
            [] for _ in self.sensors]
        found_z: list[list[NDArray[np.float64]]] = [[] for _ in self.sensors]
        union = np.unique(np.concatenate(epochs)) if self._sats is not None else np.zeros(0)
        for i in range(0, union.size, self._chunk):
            t = union[i:i + self._chunk]
            r = self._itrs(t)
            for k, sensor in enumerate(self.sensors):
                cols = np.flatnonzero(np.isin(t, epochs[k]))
                obj, ti, rae = _in_view(sensor, r[:, cols])
                found[k].append((t[cols][ti], obj))
                found_z[k].append(rae)
        return self._noisy(found, found_z)

    def _itrs(self, t: NDArray[np.float64]) -> NDArray[np.float64]:
        """Return every object's ITRF position (N, T, 3) km at epochs `t`; NaN: SGP4 failed."""
        assert self._sats is not None
        jd, fr = jd_utc(t)
        err, r, _ = self._sats.sgp4(jd, fr)
        m = np.matmul(gcrs_to_itrs_matrix(t), teme_to_gcrs_matrix(t))  # (T, 3, 3)
        out: NDArray[np.float64] = np.einsum("tij,ntj->nti", m, r)
        out[err != 0] = np.nan
        return out

    def _noisy(self, found: list[list[tuple[NDArray[np.float64], NDArray[np.int64]]]],
               found_z: list[list[NDArray[np.float64]]]) -> Observations:
        """Return the sensors' measurements found, with their noise, in epoch order."""
        t_out, obj_out, sen_out, z_out = [np.zeros(0)], [np.zeros(0, np.int64)], \
            [np.zeros(0, np.int64)], [np.zeros((0, 3))]
        for k, (sensor, rng) in enumerate(zip(self.sensors, self._rngs, strict=True)):
            tk = np.concatenate([np.zeros(0)] + [t for t, _ in found[k]])
            ok = np.concatenate([np.zeros(0, np.int64)] + [o for _, o in found[k]])
            z = np.concatenate([np.zeros((0, 3))] + found_z[k])
            first = np.lexsort((ok, tk))  # noise drawn per sensor in (epoch, object) order
            z = z[first]
            z += rng.standard_normal(z.shape) * np.asarray(sensor.sigma, dtype=float)
            z[:, 1] = np.mod(z[:, 1], 2.0 * math.pi)
            t_out.append(tk[first])
            obj_out.append(ok[first])
            sen_out.append(np.full(z.shape[0], k, dtype=np.int64))
            z_out.append(z)
        t = np.concatenate(t_out).astype(np.float64)
        obj, sen = (np.concatenate(a).astype(np.int64) for a in (obj_out, sen_out))
        z = np.concatenate(z_out).astype(np.float64)
        order = np.lexsort((obj, sen, t))
        return Observations(np.asarray(t[order], dtype=np.float64), obj[order], sen[order],
                            np.asarray(z[order], dtype=np.float64), self.object_ids,
                            self.sensors)


def _in_view(sensor: Sensor, r_itrs: NDArray[np.float64]
             ) -> tuple[NDArray[np.int64], NDArray[np.int64], NDArray[np.float64]]:
    """Return (object, epoch column, range/az/el) where `sensor` sees ITRF positions `r_itrs`.

    `r_itrs` (N, T, 3) km. Only the positions above the sensor's lowest elevation and
    within its range (with a margin of round-off) get range, azimuth and elevation
    computed and `Sensor.in_view` applied.
    """
    station = sensor.station
    rho = r_itrs - station.itrs
    enu = rho @ enu_matrix(station.lat_rad, station.lon_rad).T
    dist = np.sqrt(np.einsum("...i,...i->...", enu, enu))
    lowest = math.sin(math.radians(max(-90.0, min(90.0, sensor.min_elevation_deg))))
    with np.errstate(invalid="ignore"):
        near = (enu[..., 2] >= (lowest - 1e-9) * dist) & (dist <= sensor.max_range_km * 1.0001)
    obj, ti = np.nonzero(near)
    rae = razel_itrs(r_itrs[obj, ti], station)
    up = sensor.in_view(rae) & np.isfinite(rae).all(-1)
    return obj[up].astype(np.int64), ti[up].astype(np.int64), rae[up]


def synthetic_catalog(base: CatalogEntry, n: int, seed: int = 0,
                      first_id: int = 70000) -> list[CatalogEntry]:
    """Spread the orbit of `base` into a catalog of `n` objects of the same regime.

    Each keeps `base`'s mean motion, eccentricity, inclination, argument of perigee, drag
    term and epoch; the right ascension of the ascending node and the mean anomaly are drawn
    uniformly in [0, 2π) (`seed`). Object ids are `first_id`, `first_id` + 1, ... as strings
    (NORAD numbers of the analyst range by default); names "SYNTH <id>".
    """
    if first_id < 0 or first_id + n - 1 > 339999:
        raise ValueError("object ids must fit the TLE's alpha-5 catalogue numbers "
                         "(0..339999)")
    rng = np.random.default_rng(seed)
    raan = rng.uniform(0.0, 2.0 * math.pi, n)
    mean_anomaly = rng.uniform(0.0, 2.0 * math.pi, n)
    s = base.satrec
    epoch = s.jdsatepoch + s.jdsatepochF - SGP4_EPOCH_JD
    return [_entry(first_id + i, epoch, s.bstar, s.ecco, s.argpo, s.inclo,
                   float(mean_anomaly[i]), s.no_kozai, float(raan[i]),
                   f"synthetic_catalog({base.object_id}, seed={seed})", s.ndot, s.nddot)
            for i in range(n)]


def _entry(satnum: int, epoch: float, bstar: float, ecco: float, argpo: float, inclo: float,
           mo: float, no_kozai: float, nodeo: float, source: str, ndot: float = 0.0,
           nddot: float = 0.0) -> CatalogEntry:
    """Return one SGP4 element set, named "SYNTH <satnum>".

    `Satrec.sgp4init` (WGS-72): angles rad, mean motion rad/min, epoch days after
    `SGP4_EPOCH_JD`.
    """
    sat = Satrec()
    sat.sgp4init(WGS72, "i", satnum, epoch, bstar, ndot, nddot, ecco, argpo, inclo, mo,
                 no_kozai, nodeo)
    return CatalogEntry(str(satnum), f"SYNTH {satnum}", sat, source)


def _over(station: Station, t_unix: float, inc_rad: float,
          ascending: bool) -> tuple[float, float]:
    """Return (RAAN, argument of latitude) rad of an orbit over `station` at `t_unix`.

    A circular orbit of inclination `inc_rad` through the station's geocentric direction
    (TEME taken as the GCRF, ~0.4 deg), on its ascending or descending half. ValueError
    when the inclination is below the station's latitude.
    """
    p = site_gcrs(station, t_unix)
    lat, ra = math.asin(p[2] / float(np.linalg.norm(p))), math.atan2(p[1], p[0])
    s = math.sin(lat) / math.sin(inc_rad)
    if abs(s) > 1.0:
        raise ValueError(f"an inclination of {math.degrees(inc_rad):.1f} deg never passes "
                         f"over latitude {math.degrees(lat):.1f} deg")
    u = math.asin(s) if ascending else math.pi - math.asin(s)
    raan = ra - math.atan2(math.cos(inc_rad) * math.sin(u), math.cos(u))
    return raan % (2 * math.pi), u


def satellite_train(station: Station, t_over: float, n: int = 20, altitude_km: float = 550.0,
                    inc_deg: float = 53.0, spacing_km: tuple[float, float] = (1.0, 5.0),
                    ascending: bool = True, bstar: float = 1e-4, seed: int = 0,
                    first_id: int = 80000) -> list[CatalogEntry]:
    """Objects launched together: `n` near-circular orbits in one plane, in a row.

    The train's first object is over `station` at Unix `t_over` (the element sets' epoch);
    each next one trails the previous along track by a spacing drawn uniformly in
    `spacing_km` (`seed`). Same altitude (km above the equatorial radius), inclination,
    eccentricity 1e-4 and drag term for all; ids `first_id`, `first_id` + 1, ...
    """
    raan, u = _over(station, t_over, math.radians(inc_deg), ascending)
    a = R_EARTH + altitude_km
    no_kozai = math.sqrt(MU_EARTH / a**3) * 60.0
    gaps = np.random.default_rng(seed).uniform(*spacing_km, n)
    gaps[0] = 0.0
    lag = np.cumsum(gaps) / a  # rad of argument of latitude behind the first object
    epoch = (t_over / DAY_S + UNIX_EPOCH_JD) - SGP4_EPOCH_JD
    src = f"satellite_train({station.name}, n={n}, spacing={spacing_km} km, seed={seed})"
    return [_entry(first_id + i, epoch, bstar, 1e-4, 0.0, math.radians(inc_deg),
                   float((u - lag[i]) % (2 * math.pi)), no_kozai, raan, src)
            for i in range(n)]


def crossing_trains(station: Station, t_over: float, n: int = 10, seed: int = 0,
                    lag_s: float = 4.0, first_id: int = 81000, altitude_km: float = 550.0,
                    inc_deg: float = 53.0,
                    spacing_km: tuple[float, float] = (1.0, 5.0)) -> list[CatalogEntry]:
    """Two trains of `n` objects each (`satellite_train`) whose planes cross over `station`.

    One train passes over it on the ascending half of its orbit, the other on the
    descending half (its plane turned by the crossing angle, ~70 deg at 53 deg inclination
    over 40 deg latitude), the second `lag_s` s after the first: both are in the station's
    view together, and cross there.
    """
    a = satellite_train(station, t_over, n, altitude_km, inc_deg, spacing_km, seed=seed,
                        first_id=first_id)
    b = satellite_train(station, t_over + lag_s, n, altitude_km, inc_deg, spacing_km,
                        ascending=False, seed=seed + 1, first_id=first_id + n)
    return a + b

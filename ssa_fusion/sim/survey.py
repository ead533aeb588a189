"""What a radar network measures of a whole catalog, vectorised over objects and epochs.

`observe_catalog` propagates every object of a catalog with SGP4/SDP4 (`catalog`) at each
radar's cadence, keeps the epochs where the object is above the radar's elevation mask, and
adds the radar's noise: one array of measurements for the whole catalog, in epoch order.
`synthetic_catalog` spreads one real element set into many objects (a test catalog of any
size when no real one of that size is at hand).

Units and frames as in the rest of the core: epochs Unix seconds (UTC), range km, azimuth
(from north, clockwise, [0, 2π)) and elevation rad, states GCRF km, km/s.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from sgp4.api import WGS72, Satrec

from ssa_fusion.core.catalog import CatalogEntry, catalog_states
from ssa_fusion.core.frames import razel_gcrs
from ssa_fusion.core.stations import Sensor, SensorType

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
    one noise stream per sensor.

    Each sensor measures at the multiples of its ``cadence_s`` after `t0` where the object
    is at or above its elevation mask (by azimuth where it has one) and within its maximum
    range (`Sensor.in_view`); no light time. Objects
    SGP4 cannot propagate at an epoch (decayed) are not measured then. The states are
    computed `chunk_states` (object x epoch) at a time, bounding memory at ~100 B each.
    ValueError for an optical sensor (only radars are supported here).
    """
    n = len(entries)
    ids = tuple(e.object_id for e in entries)
    rngs = np.random.default_rng(seed).spawn(len(sensors))
    t_out: list[NDArray[np.float64]] = [np.zeros(0)]
    obj_out: list[NDArray[np.int64]] = [np.zeros(0, np.int64)]
    sen_out: list[NDArray[np.int64]] = [np.zeros(0, np.int64)]
    z_out: list[NDArray[np.float64]] = [np.zeros((0, 3))]
    for k, (sensor, rng) in enumerate(zip(sensors, rngs, strict=True)):
        if sensor.type != SensorType.RADAR:
            raise ValueError(f"sensor at {sensor.station.name!r} is {sensor.type}: "
                             "observe_catalog simulates radars only")
        t_all = t0 + sensor.cadence_s * np.arange(int(duration_s // sensor.cadence_s) + 1)
        step = max(1, chunk_states // max(n, 1))
        ts: list[NDArray[np.float64]] = []
        objs: list[NDArray[np.int64]] = []
        zs: list[NDArray[np.float64]] = []
        for i in range(0, t_all.size, step):
            t = t_all[i:i + step]
            x = catalog_states(entries, t).x  # (N, T, 6)
            rae = razel_gcrs(x, t, sensor.station)  # (N, T, 3)
            up = sensor.in_view(rae) & np.isfinite(rae).all(-1)
            obj, ti = np.nonzero(up)
            ts.append(np.asarray(t[ti], dtype=np.float64))
            objs.append(obj.astype(np.int64))
            zs.append(rae[obj, ti])
        # noise drawn per sensor in (epoch, object) order: independent of `chunk_states`
        tk, ok = np.concatenate(ts), np.concatenate(objs)
        first = np.lexsort((ok, tk))
        ts, objs = [tk[first]], [ok[first]]
        z = np.concatenate(zs)[first]
        z += rng.standard_normal(z.shape) * np.asarray(sensor.sigma, dtype=float)
        z[:, 1] = np.mod(z[:, 1], 2.0 * math.pi)
        t_out += ts
        obj_out += objs
        sen_out.append(np.full(z.shape[0], k, dtype=np.int64))
        z_out.append(z)
    t = np.concatenate(t_out).astype(np.float64)
    obj, sen = (np.concatenate(a).astype(np.int64) for a in (obj_out, sen_out))
    z = np.concatenate(z_out).astype(np.float64)
    order = np.lexsort((obj, sen, t))
    return Observations(np.asarray(t[order], dtype=np.float64), obj[order], sen[order],
                        np.asarray(z[order], dtype=np.float64), ids, tuple(sensors))


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
    out = []
    for i in range(n):
        sat = Satrec()
        sat.sgp4init(WGS72, "i", first_id + i, epoch, s.bstar, s.ndot, s.nddot, s.ecco,
                     s.argpo, s.inclo, float(mean_anomaly[i]), s.no_kozai, float(raan[i]))
        oid = str(first_id + i)
        out.append(CatalogEntry(oid, f"SYNTH {oid}", sat,
                                f"synthetic_catalog({base.object_id}, seed={seed})"))
    return out

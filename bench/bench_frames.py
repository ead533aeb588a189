"""Benchmark of the frame transformations (not a test): `core.earth.frames` against astropy
and skyfield in the same run, on the same IERS finals2000A table (astropy-iers-data, offline).

Two shapes of work, as a catalog and a filter meet them:

(a) 10,000 objects at one epoch: the 306 real element sets of
    ``config/catalogs/celestrak_active_2025-07.tle`` (CelesTrak's active catalog, July 2025;
    LEO, MEO, GEO, HEO) propagated by SGP4 to 33 epochs 3 min apart, the first 10,000 of
    those states, all transformed at the catalog's median element-set epoch;
(b) one object (the catalog's first LEO object) at 10,000 epochs one minute apart (~7 days).

Three operations on each: TEME -> GCRS (SGP4's output to the inertial frame; positions and
velocities), GCRS -> ITRS (positions and velocities) and the topocentric range, azimuth and
elevation from the Millstone radar (GCRS in; geometric, no refraction). The same inputs go
to

* ours: `frames.teme_to_gcrs`, `frames.gcrs_to_itrs`, `frames.razel_gcrs` from Unix epochs;
  "warm" with the hourly precession-nutation/polar-motion nodes cached (what a running
  filter or catalog sees), "cold" with those caches emptied before each run;
* astropy: ``TEME``/``GCRS``/``ITRS`` coordinates with velocities (which astropy carries
  by finite differences), and topocentric ``ITRS`` -> ``AltAz(pressure=0)``, from a ``Time``
  built in the run (format "unix");
* skyfield: ``TEME.rotation_at`` (its velocities rotated the same way: it too neglects the
  rotation's rate), ``ICRF.frame_xyz_and_velocity(itrs)``, ``ICRF(..., center=topos).altaz()``,
  from a ``Time`` built in the run, its UT1 and polar motion those of the same table
  (Bulletin B where given, as ours and astropy's).

Times are medians over ``--repeats`` runs, in ms; ratios are theirs / ours (warm). The bench
asserts that what it timed agrees: every position and range within 1 m, angle within 0.1",
velocity within 1 mm/s (within 1.2e-11 rad/s x |r| beyond GEO: the slow rotation `frames`
neglects in velocities) of both astropy and skyfield (skyfield's ITRS velocities within
omega x 0.7" x |r|: they leave out polar motion in the rotation's axis). Prints a table, the largest
differences, and last one JSON line.

Usage: .venv/bin/python bench/bench_frames.py [--repeats 5]
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
import time
import warnings
from collections.abc import Callable
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
# test/references.py: astropy and skyfield on our IERS table, as the frame tests set them up
sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "test"))

from ssa_fusion import limit_blas_threads

limit_blas_threads()

import astropy.units as u  # noqa: E402
import numpy as np  # noqa: E402
import references  # noqa: E402
from astropy.coordinates import GCRS, ITRS, TEME, CartesianRepresentation  # noqa: E402
from astropy.time import Time  # noqa: E402
from astropy.utils import iers  # noqa: E402
from numpy.typing import NDArray  # noqa: E402
from sgp4.api import SatrecArray  # noqa: E402
from skyfield.constants import AU_KM, DAY_S  # noqa: E402
from skyfield.framelib import itrs as sky_itrs  # noqa: E402
from skyfield.positionlib import ICRF  # noqa: E402
from skyfield.sgp4lib import TEME as SKY_TEME  # noqa: E402

from ssa_fusion.core.base.constants import ARCSEC  # noqa: E402
from ssa_fusion.core.earth import frames, timescales  # noqa: E402
from ssa_fusion.core.earth.stations import SENSORS  # noqa: E402
from ssa_fusion.formats import element_sets as catalog  # noqa: E402

Array = NDArray[np.float64]
CATALOG = references.ACTIVE
N = 10_000
STATION = SENSORS["millstone"].station
GEO_KM = 50_000.0
"""States nearer than this are held to 1 mm/s in velocity."""
SLOW_RATE = 1.2e-11
"""rad/s: the rotation rate of the slowly varying matrices that `frames` neglects in velocities
(its docstring: < 1e-11 rad/s; measured 1.08e-11 for TEME -> GCRS). Farther states (HEO
apogees beyond 100,000 km) are held to SLOW_RATE |r|."""
SKY_ITRS_RATE = SLOW_RATE + frames.ERA_RATE * 0.7 * ARCSEC
"""rad/s: skyfield's ITRS velocity turns about the ITRS z axis, not the rotation pole (its
``framelib.itrs._dRdt_times_RT_at``): it is off by omega x (polar motion, < 0.7") x |r|
(measured 1.69e-10 rad/s x |r|, 17 mm/s at 175,000 km; astropy agrees with ours)."""


def _inputs() -> dict[str, tuple[Array, Array]]:
    """TEME states (N, 6) km, km/s and their transformation epochs (N,) Unix s per case."""
    entries = catalog.read_catalog(CATALOG)
    t0 = float(np.median([e.epoch_unix for e in entries]))
    jd, fr = timescales.jd_utc(t0 + 180.0 * np.arange(33))
    err, r, v = SatrecArray([e.satrec for e in entries]).sgp4(jd, fr)
    ok = err == 0
    many = np.concatenate([r[ok], v[ok]], axis=-1)[:N]
    assert len(many) == N, len(many)
    leo = next(e for e in entries if 2 * np.pi / e.satrec.no_kozai < 100.0)
    t = t0 + 60.0 * np.arange(N)
    jd, fr = timescales.jd_utc(t)
    err1, r1, v1 = leo.satrec.sgp4_array(jd, fr)
    assert not err1.any()
    return {"10k_objects": (many, np.full(N, t0)),
            "10k_epochs": (np.concatenate([r1, v1], axis=1), t)}


# --------------------------------------------------------------------------------------------
# The three libraries. Each function: (TEME or GCRS states (N, 6), epochs (N,)) -> array;
# one epoch for all objects is passed as a scalar (every library then rotates once).
# --------------------------------------------------------------------------------------------
def _epochs(t: Array) -> Array | float:
    return float(t[0]) if np.all(t == t[0]) else t


def ours_teme_to_gcrs(x: Array, t: Array) -> Array:
    return frames.teme_to_gcrs(x, _epochs(t))


def ours_gcrs_to_itrs(x: Array, t: Array) -> Array:
    return frames.gcrs_to_itrs(x, _epochs(t))


def ours_razel(x: Array, t: Array) -> Array:
    return frames.razel_gcrs(x, _epochs(t), STATION)


def _astropy_time(t: Array) -> Time:
    e = _epochs(t)
    return Time(e, format="unix", scale="utc")


def astropy_teme_to_gcrs(x: Array, t: Array) -> Array:
    tt = _astropy_time(t)
    return references.states(references.astropy_state(x, tt, TEME).transform_to(GCRS(obstime=tt)))


def astropy_gcrs_to_itrs(x: Array, t: Array) -> Array:
    tt = _astropy_time(t)
    return references.states(references.astropy_state(x, tt, GCRS).transform_to(ITRS(obstime=tt)))


_LOC = references.location(STATION)


def astropy_razel(x: Array, t: Array) -> Array:
    tt = _astropy_time(t)
    itrs = GCRS(CartesianRepresentation(x[:, :3].T * u.km), obstime=tt).transform_to(
        ITRS(obstime=tt))
    return references.astropy_razel(itrs, tt, _LOC)


SKY_TS = references.skyfield_timescale()
"""Skyfield on the same finals2000A.all, Bulletin B where given (UT1 differs from A by ~20 us
in 2025: 0.3 m at 175,000 km)."""
TOPOS = references.topos(STATION)


def _sky_time(t: Array) -> Any:
    e = np.asarray(_epochs(t))
    days = np.floor(e / 86400.0)
    return SKY_TS.utc(1970, 1, 1 + days, 0, 0, e - days * 86400.0)


def skyfield_teme_to_gcrs(x: Array, t: Array) -> Array:
    rot = SKY_TEME.rotation_at(_sky_time(t))  # TEME <- GCRS: (3, 3) or (3, 3, N)
    r = np.einsum("ji...,j...->i...", rot, x[:, :3].T)
    v = np.einsum("ji...,j...->i...", rot, x[:, 3:].T)
    return np.concatenate([r.T, v.T], axis=1)


def skyfield_gcrs_to_itrs(x: Array, t: Array) -> Array:
    pos = ICRF(x[:, :3].T / AU_KM, x[:, 3:].T / AU_KM * DAY_S, t=_sky_time(t), center=399)
    r, v = pos.frame_xyz_and_velocity(sky_itrs)
    return np.concatenate([r.km.T, v.km_per_s.T], axis=1)


def skyfield_razel(x: Array, t: Array) -> Array:
    return references.sky_razel(references.topocentric(x[:, :3].T, _sky_time(t), TOPOS))


# --------------------------------------------------------------------------------------------
def _timed(fn: Callable[[], Array], repeats: int, before: Callable[[], None] | None = None
           ) -> tuple[float, Array]:
    """Median wall time (ms) of `fn` over `repeats` runs (`before` untimed before each)."""
    times, out = [], np.zeros(0)
    for _ in range(repeats):
        if before is not None:
            before()
        t0 = time.perf_counter()
        out = fn()
        times.append((time.perf_counter() - t0) * 1e3)
    return statistics.median(times), out


def _empty_caches() -> None:
    """Forget the hourly Q/W nodes (what a cold process computes first)."""
    frames._NODES.clear()
    frames._SEGMENTS.clear()


def _diff(op: str, ours: Array, ref: Array, rate: float = SLOW_RATE) -> dict[str, float]:
    """Largest differences; ``vel_excess`` is the largest velocity difference over its bound
    max(1 mm/s, `rate` |r|) (rad/s x km)."""
    if op == "razel":
        daz = np.abs(frames.wrap_pi(ours[:, 1] - ref[:, 1])) * np.cos(ref[:, 2])
        return {"range_m": float(np.abs(ours[:, 0] - ref[:, 0]).max() * 1e3),
                "angle_arcsec": float(max(daz.max(), np.abs(ours[:, 2] - ref[:, 2]).max())
                                      / ARCSEC)}
    dv = np.linalg.norm(ours[:, 3:] - ref[:, 3:], axis=1)
    near = np.linalg.norm(ref[:, :3], axis=1) < GEO_KM
    return {"pos_m": float(np.linalg.norm(ours[:, :3] - ref[:, :3], axis=1).max() * 1e3),
            "vel_mm_s": float(dv[near].max() * 1e6) if near.any() else 0.0,
            "vel_mm_s_beyond_geo": float(dv[~near].max() * 1e6) if (~near).any() else 0.0,
            "vel_excess": float((dv / np.maximum(1e-6, rate * np.linalg.norm(
                ref[:, :3], axis=1))).max())}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--repeats", type=int, default=5)
    args = ap.parse_args()
    warnings.simplefilter("ignore", category=UserWarning)
    iers.conf.auto_download = False
    iers.conf.auto_max_age = None
    iers.earth_orientation_table.set(iers.IERS_A.open(iers.IERS_A_FILE))

    libs = {
        "teme_to_gcrs": (ours_teme_to_gcrs, astropy_teme_to_gcrs, skyfield_teme_to_gcrs),
        "gcrs_to_itrs": (ours_gcrs_to_itrs, astropy_gcrs_to_itrs, skyfield_gcrs_to_itrs),
        "razel": (ours_razel, astropy_razel, skyfield_razel),
    }
    rows, result, worst = [], {}, {}
    for case, (x_teme, t) in _inputs().items():
        x_gcrs = frames.teme_to_gcrs(x_teme, t)
        for op, (ours, theirs_a, theirs_s) in libs.items():
            x = x_teme if op == "teme_to_gcrs" else x_gcrs
            cold, _ = _timed(lambda f=ours, x=x, t=t: f(x, t), args.repeats, _empty_caches)
            warm, z = _timed(lambda f=ours, x=x, t=t: f(x, t), args.repeats)
            ta, za = _timed(lambda f=theirs_a, x=x, t=t: f(x, t), args.repeats)
            ts, zs = _timed(lambda f=theirs_s, x=x, t=t: f(x, t), args.repeats)
            sky_rate = SKY_ITRS_RATE if op == "gcrs_to_itrs" else SLOW_RATE
            da, ds = _diff(op, z, za), _diff(op, z, zs, sky_rate)
            key = f"{op}_{case}"
            for lib, d in (("astropy", da), ("skyfield", ds)):
                for k, v in d.items():
                    worst[f"{key}_vs_{lib}_{k}"] = v
                    limit = {"pos_m": 1.0, "range_m": 1.0, "vel_mm_s": np.inf, "angle_arcsec": 0.1,
                             "vel_excess": 1.0, "vel_mm_s_beyond_geo": np.inf}[k]
                    assert v < limit, f"{key}: {lib} differs by {v:.4g} {k}"
            rows.append((op, case, cold, warm, ta, ts, da, ds))
            result.update({f"{key}_ms": warm, f"{key}_cold_ms": cold,
                           f"{key}_astropy_ms": ta, f"{key}_skyfield_ms": ts,
                           f"{key}_ratio_vs_astropy": ta / warm,
                           f"{key}_ratio_vs_skyfield": ts / warm})

    print(f"frame transformations, {N:,} states; median of {args.repeats} runs, ms "
          f"(ratio: theirs / ours warm)\n")
    print("| operation | case | ours cold | ours warm | astropy | ratio | skyfield | ratio |")
    print("|---|---|---:|---:|---:|---:|---:|---:|")
    for op, case, cold, warm, ta, ts, _, _ in rows:
        print(f"| {op} | {case} | {cold:.2f} | {warm:.2f} | {ta:.1f} | {ta / warm:.1f} | "
              f"{ts:.1f} | {ts / warm:.1f} |")
    print("\nlargest differences (ours - theirs):")
    for op, case, *_, da, ds in rows:
        fmt = ", ".join(f"{k} {v:.3g}" for k, v in da.items())
        fms = ", ".join(f"{k} {v:.3g}" for k, v in ds.items())
        print(f"  {op} {case}: astropy {fmt}; skyfield {fms}")
    print(json.dumps({"n": N, "repeats": args.repeats, **result, **worst}))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

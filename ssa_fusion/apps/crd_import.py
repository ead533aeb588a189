"""`ssa-fusion import crd FILE... --stations SINEX --bag OUT`: laser ranging into a bag.

Reads ILRS CRD normal points (`formats.ilrs.crd_in`), the stations' coordinates and
velocities (SINEX ``SOLUTION/ESTIMATE``, `formats.sinex`) and, with ``--eccentricities``,
their eccentricities (SINEX ``SITE/ECCENTRICITY``; without it the markers are ranged from),
and writes a bag:

* ``/ssa/measurement``: one LASER_RANGE Measurement per normal point (range m = c x two-way
  time of flight / 2, stamped at its transmit epoch, frame_id the station id = its CDP pad,
  noise ``--sigma``);
* ``/ssa/meteo``: the stations' meteorological records (ssa_fusion_msgs/Meteo);
* ``/ssa/config``: the stations (ITRF position at the solution's epoch, velocity,
  eccentricity, wavelength, range-bias prior ``--bias-sigma``) and the objects
  (centre-of-mass offset: ``--com-offset``, else the ILRS standard of the geodetic
  spheres), `ros.laser_config`;
* ``/ssa/reference`` with ``--reference CPF|OEM``: an independent orbit of the object
  (GCRF StateEstimates, zero covariance), for evaluation only.

Each station's solution and eccentricity are those whose SINEX spans hold its first point;
one that changes before its last point is refused, as a station ranging at two wavelengths
(import those sessions apart). The files are read whole before the bag is written: an
error leaves no bag behind. Points without meteorological data within 30 min get a
standard atmosphere (counted in the summary line).
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
from collections import Counter
from collections.abc import Iterator
from pathlib import Path

import numpy as np

from ssa_fusion.apps.partial import removed_if_unfinished
from ssa_fusion.apps.progress_lines import ProgressLines
from ssa_fusion.core.base import types
from ssa_fusion.core.base.quoting import shown
from ssa_fusion.core.earth.timescales import iso
from ssa_fusion.core.measure.laser_range import COM_OFFSETS_KM
from ssa_fusion.core.measure.laser_station import LaserStation, velocity_per_year
from ssa_fusion.core.measure.troposphere import MeteoSeries
from ssa_fusion.formats import sinex
from ssa_fusion.formats.ccsds.common import CcsdsError
from ssa_fusion.formats.ilrs.crd_in import LaserRanges, read_laser_ranges
from ssa_fusion.formats.records import RecordError
from ssa_fusion.formats.reference_orbit import ReferenceOrbit, read_reference
from ssa_fusion.ros import bagio, messages
from ssa_fusion.ros.laser_config import LaserConfig, laser_config_message
from ssa_fusion.ros.topics import TOPIC_CONFIG, TOPIC_MEASUREMENT, TOPIC_METEO, TOPIC_REFERENCE

SIGMA_M = 0.005
"""Default noise of a normal point, m (1 sigma): its precision (the RMS of its bin over the
square root of its ranges: 1-4 mm one-way for LAGEOS), the target's signature (1-2 mm) and
the model's short-period errors; what is left after a fit and a bias per station (1-2 cm on
LAGEOS) drifts through a pass, not white (`core.od.laser_od`)."""
BIAS_SIGMA_M = 1.0
"""Default prior sigma of a station's range bias, m."""
METEO_LEAD_S = 1e-3
"""A meteorological record is stamped and logged this long before its epoch: CRD gives its
epoch to the millisecond, rounded, so the record a station writes with a normal point may
carry an epoch up to 0.5 ms after the point's; a millisecond earlier (below the record's
resolution), it is known when the point is fused, offline and live alike."""
WAVELENGTH_TOLERANCE_NM = 1.0
"""Wavelengths of one station's sessions that differ by more are refused."""


def add_import_crd(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """Add `import crd` to the `import` subcommands `sub`."""
    c = sub.add_parser(
        "crd", help="ILRS laser ranging (CRD normal points) into a bag, with its stations",
        description="Read ILRS CRD normal points (v1 or v2) of two-way laser ranging, the "
                    "stations' SINEX coordinates and eccentricities, into a bag: LASER_RANGE "
                    "measurements on /ssa/measurement, meteorological data on /ssa/meteo, "
                    "the stations and objects on /ssa/config, an independent orbit on "
                    "/ssa/reference (docs/REALDATA.md).")
    c.add_argument("files", type=Path, nargs="+", metavar="FILE", help="CRD files")
    c.add_argument("--stations", type=Path, required=True, metavar="SINEX",
                   help="SINEX of the stations' positions and velocities (e.g. SLRF2014)")
    c.add_argument("--eccentricities", type=Path, default=None, metavar="SINEX",
                   help="SINEX of the stations' eccentricities (SITE/ECCENTRICITY, UNE); "
                        "default: none (the markers')")
    c.add_argument("--bag", type=Path, required=True, help="bag to write; must not exist")
    c.add_argument("--reference", type=Path, default=None, metavar="CPF|OEM",
                   help="an independent orbit of the object (CPF or CCSDS OEM) for "
                        "evaluation, on /ssa/reference")
    c.add_argument("--sigma", type=float, default=SIGMA_M, metavar="M",
                   help=f"noise of every normal point, m (1 sigma; default {SIGMA_M})")
    c.add_argument("--bias-sigma", type=float, default=BIAS_SIGMA_M, metavar="M",
                   help=f"prior sigma of each station's range bias, m (default "
                        f"{BIAS_SIGMA_M})")
    c.add_argument("--com-offset", type=float, default=None, metavar="M",
                   help="the target's centre-of-mass offset, m (default: the ILRS standard "
                        "of LAGEOS, Etalon, Ajisai, Starlette, Stella, LARES)")
    c.set_defaults(_ccsds_run=run_import_crd)


def run_import_crd(args: argparse.Namespace) -> int:
    """Run `import crd`; return 0, or 2 with one ``error:`` line."""
    try:
        return _run(args)
    except (RecordError, CcsdsError, bagio.BagError, OSError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2


def _run(args: argparse.Namespace) -> int:
    """Read everything, write the bag, print the summary line."""
    if args.bag.exists():
        raise RecordError(f"{args.bag} exists already; choose another --bag")
    for name, v in (("--sigma", args.sigma), ("--bias-sigma", args.bias_sigma)):
        if not 0.0 < v < 1e4:
            raise RecordError(f"{name} {v!r}: want a number of metres in (0, 10000)")
    if args.com_offset is not None and not 0.0 <= args.com_offset < 100.0:
        raise RecordError(f"--com-offset {args.com_offset!r}: want metres in [0, 100)")
    ranges = read_laser_ranges(args.files)
    config = LaserConfig()
    _stations(ranges, args, config)
    _objects(ranges, args.com_offset, config)
    reference = _reference(args.reference, ranges) if args.reference else None
    if reference is not None:
        config.meta["reference"] = {"file": reference.path, "format": reference.source,
                                    "states": len(reference.t), "topic": TOPIC_REFERENCE}
    config.meta["sources"] = {"crd": [str(f) for f in args.files],
                              "stations": str(args.stations),
                              "eccentricities": str(args.eccentricities or "")}
    progress = ProgressLines("import crd", "messages", 5.0, None)
    progress.total = len(ranges) + len(ranges.meteo)
    n = _write_bag(args.bag, ranges, config, reference, args.sigma / 1000.0, progress)
    print(_summary(ranges, config, reference, n, args.bag))
    return 0


def _stations(ranges: LaserRanges, args: argparse.Namespace, config: LaserConfig) -> None:
    """Fill `config.stations` (and their bias priors) from the SINEX files."""
    sol = sinex.read_solutions(args.stations)
    ecc = sinex.read_eccentricities(args.eccentricities) if args.eccentricities else None
    for sid, st in ranges.stations.items():
        if not st.points:
            continue
        if max(st.wavelengths_nm) - min(st.wavelengths_nm) > WAVELENGTH_TOLERANCE_NM:
            raise RecordError(f"station {sid} {st.name} ranges at "
                              f"{', '.join(f'{w:g}' for w in sorted(st.wavelengths_nm))} nm: "
                              f"import the sessions of each wavelength apart")
        s = sinex.solution_at(sol, sid, st.first, str(args.stations))
        if sinex.solution_at(sol, sid, st.last, str(args.stations)) is not s:
            raise RecordError(f"{args.stations}: station {sid}'s solution changes between "
                              f"{iso(st.first)} and {iso(st.last)}: import the spans apart")
        une = np.zeros(3)
        meta: dict[str, object] = {"solution": " ".join((s.code, s.point, s.solution)),
                                   "solution_line": s.line}
        if ecc is not None:
            e = sinex.eccentricity_at(ecc, sid, st.first, str(args.eccentricities))
            if not np.array_equal(sinex.eccentricity_at(
                    ecc, sid, st.last, str(args.eccentricities)).une_m, e.une_m):
                raise RecordError(f"{args.eccentricities}: station {sid}'s eccentricity "
                                  f"changes between {iso(st.first)} and {iso(st.last)}")
            une, meta["eccentricity_line"] = e.une_m, e.line
        config.stations[sid] = LaserStation(
            sid, s.position_m / 1000.0, velocity_per_year(s.velocity_m_yr), s.t_ref,
            une / 1000.0, float(np.mean(sorted(st.wavelengths_nm))) / 1000.0, st.name)
        config.bias_km[sid] = 0.0
        config.bias_sigma_km[sid] = args.bias_sigma / 1000.0
        config.meta.setdefault("stations", {})[sid] = meta


def _objects(ranges: LaserRanges, com_offset_m: float | None, config: LaserConfig) -> None:
    """Fill `config.com_km` (the centre-of-mass offsets) of the objects ranged."""
    for tg in ranges.targets.values():
        com = com_offset_m / 1000.0 if com_offset_m is not None else \
            COM_OFFSETS_KM.get(tg.ilrs_id)
        if com is None:
            raise RecordError(f"no centre-of-mass offset known for target {tg.ilrs_id} "
                              f"({shown(tg.name)}): give --com-offset M")
        config.com_km[tg.object_id] = com
        config.meta.setdefault("objects", {})[tg.object_id] = {
            "name": tg.name, "ilrs_id": tg.ilrs_id}


def _reference(path: Path, ranges: LaserRanges) -> ReferenceOrbit:
    """Return the reference orbit, which must name one of the objects ranged."""
    ref = read_reference(path)
    known = {str(v) for tg in ranges.targets.values()
             for v in (tg.object_id, tg.ilrs_id, tg.name, tg.norad) if v is not None}
    if not known & set(ref.names):
        raise RecordError(f"{path}: an orbit of {', '.join(shown(n) for n in ref.names)}, "
                          f"not of the object(s) ranged ({', '.join(sorted(known))})")
    return ref


def _meteo_missing(ranges: LaserRanges) -> int:
    """Return how many points have no meteorological record within 30 min."""
    missing = 0
    for k, sid in enumerate(ranges.station_ids):
        mine = ranges.station == k
        ms = [m for m in ranges.meteo if m.station == sid]
        series = MeteoSeries.of([m.t for m in ms], [m.pressure_hpa for m in ms],
                                [m.temperature_k for m in ms], [m.humidity_pct for m in ms])
        missing += int(np.count_nonzero(~series.at(ranges.t[mine])[3]))
    return missing


def _rows(ranges: LaserRanges, reference: ReferenceOrbit | None, sigma_km: float,
          classes: messages.MsgClasses) -> Iterator[tuple[int, str, object]]:
    """Yield (log time ns, topic, message) of every message but the config, in time order."""
    rows: list[tuple[float, int, int]] = []  # (t, topic, index) sorted once
    rows += [(t, 0, i) for i, t in enumerate(ranges.t.tolist())]
    rows += [(m.t - METEO_LEAD_S, 1, i) for i, m in enumerate(ranges.meteo)]
    if reference is not None:
        rows += [(t, 2, i) for i, t in enumerate(reference.t.tolist())]
    rows.sort()
    ids, oids = ranges.station_ids, ranges.object_ids
    R = np.array([[sigma_km**2]])
    for t, topic, i in rows:
        ns = round(t * 1e9)
        if topic == 0:
            m = types.Measurement(t=t, z=np.array([ranges.range_km[i]]), R=R,
                                  kind=types.Kind.LASER_RANGE, source=types.Source.SENSOR,
                                  object_id=oids[ranges.target[i]],
                                  frame_id=ids[ranges.station[i]])
            yield ns, TOPIC_MEASUREMENT, messages.measurement_to_msg(m, classes)
        elif topic == 1:
            early = dataclasses.replace(ranges.meteo[i], t=t)
            yield ns, TOPIC_METEO, messages.meteo_to_msg(early, classes)
        else:
            assert reference is not None
            e = types.StateEstimate(t=t, x=reference.x[i], object_id=oids[0])
            yield ns, TOPIC_REFERENCE, messages.estimate_to_msg(e, classes)


def _write_bag(out: Path, ranges: LaserRanges, config: LaserConfig,
               reference: ReferenceOrbit | None, sigma_km: float,
               progress: ProgressLines) -> Counter[str]:
    """Write the bag (module docstring); return the messages written by topic."""
    classes = bagio.rosbags_classes()
    written: Counter[str] = Counter()
    first_ns = round(float(ranges.t.min()) * 1e9)
    if ranges.meteo:
        first_ns = min(first_ns, round((min(m.t for m in ranges.meteo) - METEO_LEAD_S) * 1e9))
    if reference is not None:
        first_ns = min(first_ns, round(float(reference.t.min()) * 1e9))
    with removed_if_unfinished(out):
        writer = bagio.BagWriter(out)
        try:
            writer.add_topic(TOPIC_CONFIG, "std_msgs/msg/String",
                             [bagio.LATCHED_QOS])
            for topic, name in ((TOPIC_MEASUREMENT, "Measurement"), (TOPIC_METEO, "Meteo"),
                                (TOPIC_REFERENCE, "StateEstimate")):
                writer.add_topic(topic, f"{bagio.MSG_PACKAGE}/msg/{name}")
            text = bagio.typestore().types["std_msgs/msg/String"]
            writer.write_msg(TOPIC_CONFIG, first_ns, text(data=laser_config_message(config)))
            for ns, topic, msg in _rows(ranges, reference, sigma_km, classes):
                writer.write_msg(topic, ns, msg)
                written[topic] += 1
                progress.writing(sum(written.values()))
        except BaseException:
            writer.close()
            raise
        writer.close()
    return written


def _summary(ranges: LaserRanges, config: LaserConfig, reference: ReferenceOrbit | None,
             written: Counter[str], bag: Path) -> str:
    """Return the summary line of an import."""
    per = ", ".join(f"{sid} {st.name} {st.points}" for sid, st in ranges.stations.items()
                    if st.points)
    objs = ", ".join(f"{tg.object_id} ({tg.name})" for tg in ranges.targets.values())
    missing = _meteo_missing(ranges)
    dup = f", {ranges.duplicates} given twice (kept once)" if ranges.duplicates else ""
    ref = (f"; reference: {len(reference.t)} {reference.source.upper()} states "
           f"{iso(float(reference.t[0]))} .. {iso(float(reference.t[-1]))}"
           if reference is not None else "")
    return (f"import crd: {written[TOPIC_MEASUREMENT]} laser ranges of {objs} from "
            f"{len(config.stations)} station(s) ({per}){dup}; {written[TOPIC_METEO]} "
            f"meteorological records ({missing} point(s) without: standard atmosphere)"
            f"{ref} -> {bag}")

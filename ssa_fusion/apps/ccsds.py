"""CCSDS in and out: `ssa-fusion export oem|tdm BAG` and `ssa-fusion import tdm FILE --bag OUT`.

* **OEM** (Orbit Ephemeris Message, CCSDS 502.0, version 3.0) out of a bag: the filter's
  estimates (``/ssa/estimate``), one segment per object (all objects, or ``--object ID``),
  a state vector and a 6x6 covariance per epoch (the last estimate published for that
  epoch). Units km, km/s, km², km²/s, km²/s² as OEM prescribes.
* **TDM** (Tracking Data Message, CCSDS 503.0, version 2.0) out of a bag: its real
  range/azimuth/elevation measurements (``/ssa/measurement``, SENSOR), one segment per
  object, station and noise level.
* **TDM into a bag** that `ssa-fusion replay` runs through surrogate and filter: RANGE (km),
  ANGLE_1 / ANGLE_2 (azimuth / elevation, deg, ``ANGLE_TYPE = AZEL``) of one station
  participant and one object participant; the three at one epoch make one measurement.

Files are written and read with the ``ccsds-ndm`` library (KVN or XML; reading tells the
format from the content). Conventions, and what is not supported: docs/CCSDS.md.

TDM carries no measurement noise. The noise of imported measurements is, in this order,
``--sigma``, the metadata comment ``ssa_fusion sigma: RANGE_KM AZ_DEG EL_DEG`` that
`export tdm` writes, else the station's sensor preset (`stations.SENSORS`).

`cli` registers this module under two commands, ``export`` and ``import``; the parser's
name (its last word) says which one `add_arguments` builds.
"""

from __future__ import annotations

import argparse
import datetime as dt
import math
import re
import sys
from collections import defaultdict
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ssa_fusion.apps import evaluate
from ssa_fusion.core import types
from ssa_fusion.core.stations import SENSORS, STATIONS
from ssa_fusion.ros import bagio, messages
from ssa_fusion.ros.topics import TOPIC_MEASUREMENT

ORIGINATOR = "ssa_fusion"
REF_FRAME = "TEME"
"""The project's ECI frame, named as CCSDS names it (SGP4's TEME, used as ECI; see
`core.frames`)."""
SIGMA_COMMENT = "ssa_fusion sigma:"
"""Start of the TDM metadata comment that carries the measurement noise (range km, azimuth
deg, elevation deg, one standard deviation each)."""
_COV = ("x", "y", "z", "x_dot", "y_dot", "z_dot")
"""OEM covariance element names by state index (CX_X, CY_X, ..., CZ_DOT_Z_DOT)."""


class CcsdsError(ValueError):
    """Input that cannot become a CCSDS message or a bag; the message says why."""


# ------------------------------------------------------------------------------------------
# epochs: Unix seconds (float, as the bag stamps give them) <-> CCSDS UTC strings, to the ns
# ------------------------------------------------------------------------------------------
_EPOCH = re.compile(r"^(\d{4})-(?:(\d{2})-(\d{2})|(\d{3}))T(\d{2}):(\d{2}):(\d{2})(?:\.(\d+))?Z?$")


def format_epoch(t: float) -> str:
    """Unix seconds -> ``YYYY-MM-DDThh:mm:ss.nnnnnnnnn`` (UTC, nanoseconds, as the stamps).

    Whole and fractional seconds are split first (exact), so 0.25 s is written .250000000
    (``t * 1e9`` would lose the last digits to the float's 2**-22 s spacing near 2e9 s).
    """
    sec = math.floor(t)
    nsec = round((t - sec) * 1e9)
    sec, nsec = sec + nsec // 1_000_000_000, nsec % 1_000_000_000
    day = dt.datetime.fromtimestamp(sec, dt.UTC)
    return f"{day:%Y-%m-%dT%H:%M:%S}.{nsec:09d}"


def parse_epoch(text: str) -> float:
    """CCSDS UTC epoch (calendar or day-of-year form) -> Unix seconds, to the nanosecond,
    computed as `messages.stamp_to_seconds` does (so a bag's stamps round-trip exactly)."""
    m = _EPOCH.match(text.strip())
    if m is None:
        raise CcsdsError(f"epoch {text!r} is not a CCSDS UTC epoch (YYYY-MM-DDThh:mm:ss[.f] "
                         f"or YYYY-DDDThh:mm:ss[.f])")
    year, month, day, doy, hh, mm, ss, frac = m.groups()
    try:
        if doy is not None:
            date = dt.datetime(int(year), 1, 1, tzinfo=dt.UTC) + dt.timedelta(days=int(doy) - 1)
        else:
            date = dt.datetime(int(year), int(month), int(day), tzinfo=dt.UTC)
    except ValueError as exc:
        raise CcsdsError(f"epoch {text!r}: {exc}") from None
    sec = int(date.timestamp()) + int(hh) * 3600 + int(mm) * 60 + int(ss)
    nsec = round(float(f"0.{frac}") * 1e9) if frac else 0
    return messages.stamp_to_seconds(_Stamp(sec + nsec // 1_000_000_000, nsec % 1_000_000_000))


@dataclass(frozen=True)
class _Stamp:
    sec: int
    nanosec: int


def _ndm() -> tuple[Any, Any, Any, Any, Any, Any]:
    """The ccsds-ndm modules (imported on use: only these commands need the library)."""
    from ccsds_ndm.mapping import NDMFileFormats
    from ccsds_ndm.models.ndmxml4 import ndmxml_4_0_0_common_4_0 as common
    from ccsds_ndm.models.ndmxml4 import ndmxml_4_0_0_master_4_0 as master
    from ccsds_ndm.models.ndmxml4 import ndmxml_4_0_0_oem_3_0 as oem
    from ccsds_ndm.models.ndmxml4 import ndmxml_4_0_0_tdm_2_0 as tdm
    from ccsds_ndm.ndm_io import NdmIo

    return NdmIo(), NDMFileFormats, common, master, oem, tdm


def _now() -> str:
    return f"{dt.datetime.now(dt.UTC):%Y-%m-%dT%H:%M:%S}"


def write_ndm(doc: Any, out: Path, fmt: str) -> None:
    """Write an NDM object tree to `out` as ``kvn`` or ``xml`` (ccsds-ndm)."""
    io, formats, *_ = _ndm()
    text = io.to_string(doc, formats.XML if fmt == "xml" else formats.KVN)
    out.write_text(text if text.endswith("\n") else text + "\n")


def read_ndm(path: Path) -> Any:
    """Parse a CCSDS NDM file (KVN or XML) with ccsds-ndm; CcsdsError if it cannot."""
    io, *_ = _ndm()
    try:
        return io.from_path(path)
    except OSError as exc:
        raise CcsdsError(f"{path}: cannot read: {exc.strerror or exc}") from None
    except Exception as exc:  # the parser raises many unrelated types; name the file
        first = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        raise CcsdsError(f"{path}: not a readable CCSDS message: {first}") from None


# ------------------------------------------------------------------------------------------
# OEM
# ------------------------------------------------------------------------------------------
def ephemerides(estimates: Iterable[types.StateEstimate],
                object_id: str | None = None) -> dict[str, list[types.StateEstimate]]:
    """Estimates by object id (sorted by epoch, the last one published per epoch), for one
    object or all; CcsdsError if there are none (naming the objects there are)."""
    by_object: dict[str, dict[float, types.StateEstimate]] = defaultdict(dict)
    for e in estimates:
        by_object[e.object_id or "unknown"][e.t] = e
    if object_id is not None:
        if object_id not in by_object:
            known = ", ".join(sorted(by_object)) or "none"
            raise CcsdsError(f"no estimates of object {object_id!r} (objects: {known})")
        by_object = {object_id: by_object[object_id]}
    if not by_object:
        raise CcsdsError("no estimates (/ssa/estimate) to export")
    return {k: [v[t] for t in sorted(v)] for k, v in sorted(by_object.items())}


def oem_document(ephem: dict[str, list[types.StateEstimate]]) -> Any:
    """An OEM 3.0 object tree: one segment per object, state + covariance per epoch."""
    _, _, common, master, oem, _ = _ndm()
    km, kms = common.PositionUnits.KM, common.VelocityUnits.KM_S
    cov_types = {f: _cov_type(common, f) for f in _cov_fields()}
    segments = []
    for oid, rows in ephem.items():
        meta = oem.OemMetadata(
            comment=["ECI: TEME as SGP4 outputs it; ECEF <-> ECI by Earth rotation angle "
                     "only (ssa_fusion core.frames)"],
            object_name=oid, object_id=oid, center_name="EARTH", ref_frame=REF_FRAME,
            time_system="UTC", start_time=format_epoch(rows[0].t),
            stop_time=format_epoch(rows[-1].t))
        states, covs = [], []
        for e in rows:
            x = np.asarray(e.x, dtype=float)
            epoch = format_epoch(e.t)
            states.append(common.StateVectorAccType(
                epoch=epoch,
                **{n: common.PositionTypeUo(value=float(x[i]), units=km)
                   for i, n in enumerate(("x", "y", "z"))},
                **{n: common.VelocityTypeUo(value=float(x[3 + i]), units=kms)
                   for i, n in enumerate(("x_dot", "y_dot", "z_dot"))}))
            P = np.asarray(e.P, dtype=float)
            covs.append(common.OemCovarianceMatrixType(
                epoch=epoch, **{f: cov_types[f](value=float(P[i, j]))
                                for f, (i, j) in _cov_fields().items()}))
        segments.append(oem.OemSegment(metadata=meta, data=oem.OemData(
            state_vector=states, covariance_matrix=covs)))
    header = common.OdmHeader(creation_date=_now(), originator=ORIGINATOR)
    return master.Oem(header=header, body=oem.OemBody(segment=segments))


def _cov_fields() -> dict[str, tuple[int, int]]:
    """OEM covariance field name -> (row, column) of the 6x6 matrix (lower triangle)."""
    return {f"c{_COV[i]}_{_COV[j]}": (i, j) for i in range(6) for j in range(i + 1)}


def _cov_type(common: Any, name: str) -> Any:
    """The ccsds-ndm wrapper type of covariance field `name` (km², km²/s or km²/s²)."""
    return (common.PositionCovarianceType, common.PositionVelocityCovarianceType,
            common.VelocityCovarianceType)[name.count("dot")]


def oem_states(doc: Any) -> dict[str, list[types.StateEstimate]]:
    """OEM object tree (as ccsds-ndm parses it) -> estimates by OBJECT_ID (km, km/s, km²).

    Only segments with covariances at the state vectors' epochs keep them; others get
    zero covariance."""
    out: dict[str, list[types.StateEstimate]] = {}
    for seg in doc.body.segment:
        oid = seg.metadata.object_id
        covs = {parse_epoch(c.epoch): c for c in seg.data.covariance_matrix}
        rows = []
        for sv in seg.data.state_vector:
            t = parse_epoch(sv.epoch)
            x = np.array([getattr(sv, n).value for n in _COV], dtype=float)
            P = np.zeros((6, 6))
            if t in covs:
                for f, (i, j) in _cov_fields().items():
                    P[i, j] = P[j, i] = getattr(covs[t], f).value
            rows.append(types.StateEstimate(t=t, x=x, P=P, object_id=oid))
        out[oid] = rows
    return out


# ------------------------------------------------------------------------------------------
# TDM
# ------------------------------------------------------------------------------------------
def tdm_document(measurements: Iterable[types.Measurement]) -> tuple[Any, int]:
    """A TDM 2.0 object tree of the real range/az/el measurements, one segment per object,
    station and noise level; and how many measurements were left out (forecasts, other
    kinds). CcsdsError if none is left."""
    _, _, common, master, _, tdm = _ndm()
    groups: dict[tuple[str, str, tuple[float, ...]], list[types.Measurement]] = defaultdict(list)
    skipped = 0
    for m in measurements:
        if m.kind != types.Kind.RANGE_AZ_EL or m.source != types.Source.SENSOR:
            skipped += 1
            continue
        sigma = tuple(float(s) for s in np.sqrt(np.diag(np.asarray(m.R, dtype=float))))
        groups[(m.object_id or "unknown", m.frame_id, sigma)].append(m)
    if not groups:
        raise CcsdsError("no real range/azimuth/elevation measurements to export (TDM "
                         "export supports RANGE_AZ_EL sensor measurements)")
    deg = common.AngleUnits.DEG
    segments = []
    for (oid, station, sigma), rows in groups.items():
        rows.sort(key=lambda m: m.t)
        meta = tdm.TdmMetadata(
            comment=[f"{SIGMA_COMMENT} {sigma[0]!r} {math.degrees(sigma[1])!r} "
                     f"{math.degrees(sigma[2])!r}"],
            time_system="UTC", start_time=format_epoch(rows[0].t),
            stop_time=format_epoch(rows[-1].t), participant_1=station, participant_2=oid,
            mode=tdm.ModeType.SEQUENTIAL, path="1,2,1", angle_type=tdm.AngleTypeType.AZEL,
            range_units=tdm.RangeUnitsType.KM)
        obs = []
        for m in rows:
            epoch = format_epoch(m.t)
            r, az, el = (float(v) for v in m.z)
            obs.append(tdm.TrackingDataObservationType(epoch=epoch, range=r))
            obs.append(tdm.TrackingDataObservationType(
                epoch=epoch, angle_1=common.AngleType(value=math.degrees(az), units=deg)))
            obs.append(tdm.TrackingDataObservationType(
                epoch=epoch, angle_2=common.AngleType(value=math.degrees(el), units=deg)))
        segments.append(tdm.TdmSegment(metadata=meta, data=tdm.TdmData(observation=obs)))
    header = tdm.TdmHeader(creation_date=_now(), originator=ORIGINATOR)
    return master.Tdm(header=header, body=tdm.TdmBody(segment=segments)), skipped


@dataclass
class Imported:
    """Measurements read from a TDM and what was left out (epochs lacking a channel)."""

    measurements: list[types.Measurement]
    incomplete: int = 0


def tdm_measurements(doc: Any, sigma: Sequence[float] | None = None,
                     source: str = "TDM") -> Imported:
    """TDM object tree -> range/az/el measurements (km, rad), sorted by epoch.

    `sigma`: (range km, azimuth deg, elevation deg) noise for every measurement, else each
    segment's ``ssa_fusion sigma:`` comment, else its station's sensor preset. CcsdsError
    (naming `source` and the segment) for what this importer does not support.
    """
    if not hasattr(doc, "body") or not hasattr(doc.body, "segment") or \
            type(doc).__name__.lower() != "tdm":
        raise CcsdsError(f"{source}: not a TDM (it is {type(doc).__name__})")
    out = Imported([])
    for k, seg in enumerate(doc.body.segment, 1):
        where = f"{source}: segment {k}"
        station, oid = _participants(seg.metadata, where)
        noise = _segment_sigma(seg.metadata, station, sigma, where)
        R = np.diag(noise**2)
        epochs: dict[float, dict[str, float]] = defaultdict(dict)
        for ob in seg.data.observation:
            t = parse_epoch(ob.epoch)
            for key in ("range", "angle_1", "angle_2"):
                value = getattr(ob, key, None)
                if value is not None:
                    epochs[t][key] = float(getattr(value, "value", value))
        for t, ch in sorted(epochs.items()):
            if len(ch) < 3:
                out.incomplete += 1
                continue
            z = np.array([ch["range"], math.radians(ch["angle_1"]) % (2 * math.pi),
                          math.radians(ch["angle_2"])])
            out.measurements.append(types.Measurement(
                t=t, z=z, R=R.copy(), kind=types.Kind.RANGE_AZ_EL, source=types.Source.SENSOR,
                object_id=oid, frame_id=station))
    if not out.measurements:
        raise CcsdsError(f"{source}: no epoch with all of RANGE, ANGLE_1 and ANGLE_2")
    out.measurements.sort(key=lambda m: m.t)
    return out


def _participants(meta: Any, where: str) -> tuple[str, str]:
    """(station id, object id) of a TDM segment: the one participant that is a known station
    and the one that is not."""
    for key, want in (("time_system", "UTC"), ("angle_type", "AZEL"), ("range_units", "KM")):
        got = getattr(meta, key, None)
        got = str(getattr(got, "value", got) or want).upper()
        if got != want:
            raise CcsdsError(f"{where}: {key.upper()} = {got} is not supported (only {want})")
    names = [p for i in range(1, 6) if (p := getattr(meta, f"participant_{i}", None))]
    stations = [p for p in names if p.lower() in STATIONS]
    others = [p for p in names if p.lower() not in STATIONS]
    if len(stations) != 1 or len(others) != 1:
        raise CcsdsError(
            f"{where}: participants {', '.join(names)}: need one known station "
            f"({', '.join(sorted(STATIONS))}) and one object")
    return stations[0].lower(), others[0]


def _segment_sigma(meta: Any, station: str, sigma: Sequence[float] | None,
                   where: str) -> np.ndarray:
    """Noise (range km, azimuth rad, elevation rad) of a segment's measurements."""
    if sigma is None:
        for line in getattr(meta, "comment", None) or []:
            if line.strip().startswith(SIGMA_COMMENT):
                try:
                    sigma = [float(v) for v in line.strip()[len(SIGMA_COMMENT):].split()]
                except ValueError:
                    sigma = []
                if len(sigma) != 3:
                    raise CcsdsError(f"{where}: malformed comment {line.strip()!r} (want "
                                     f"'{SIGMA_COMMENT} RANGE_KM AZ_DEG EL_DEG')")
    if sigma is None:
        preset = SENSORS.get(station)
        if preset is None or len(preset.sigma) != 3:
            raise CcsdsError(f"{where}: no noise for station {station}: give --sigma")
        return np.asarray(preset.sigma, dtype=float)
    if not all(math.isfinite(s) and s > 0 for s in sigma):
        raise CcsdsError(f"{where}: noise must be finite and > 0, got {list(sigma)}")
    return np.array([sigma[0], math.radians(sigma[1]), math.radians(sigma[2])])


def write_measurement_bag(out: Path, measurements: Sequence[types.Measurement]) -> None:
    """A bag of `measurements` on /ssa/measurement, each logged at its own stamp (what
    `replay` plays; it derives /clock from the stamps)."""
    classes = bagio.rosbags_classes()
    writer = bagio.BagWriter(out)
    try:
        writer.add_topic(TOPIC_MEASUREMENT, f"{bagio.MSG_PACKAGE}/msg/Measurement")
        for m in measurements:
            msg = messages.measurement_to_msg(m, classes)
            stamp = msg.header.stamp
            writer.write_msg(TOPIC_MEASUREMENT, stamp.sec * 1_000_000_000 + stamp.nanosec, msg)
    finally:
        writer.close()


# ------------------------------------------------------------------------------------------
# command line
# ------------------------------------------------------------------------------------------
def add_arguments(p: argparse.ArgumentParser) -> None:
    if p.prog.split()[-1] == "import":
        _add_import(p)
    else:
        _add_export(p)


def _add_format(p: argparse.ArgumentParser) -> None:
    p.add_argument("--format", choices=("kvn", "xml"), default=None,
                   help="file format (default: xml if --out ends in .xml, else kvn)")


def _add_export(p: argparse.ArgumentParser) -> None:
    sub = p.add_subparsers(dest="ccsds_command", required=True, metavar="{oem,tdm}")
    o = sub.add_parser("oem", help="the filter's estimates with covariance as a CCSDS OEM",
                       description="Write the estimates of a bag (/ssa/estimate) as a CCSDS "
                                   "Orbit Ephemeris Message: one segment per object, state "
                                   "(km, km/s) and 6x6 covariance (km^2 ...) per epoch.")
    t = sub.add_parser("tdm", help="the real range/az/el measurements as a CCSDS TDM",
                       description="Write the sensor range/azimuth/elevation measurements of "
                                   "a bag (/ssa/measurement) as a CCSDS Tracking Data "
                                   "Message: RANGE km, ANGLE_1/ANGLE_2 az/el deg.")
    for q, suffix in ((o, ".oem"), (t, ".tdm")):
        q.add_argument("bag", type=Path, help="rosbag2 directory or .mcap file")
        q.add_argument("--object", default=None, help="only this object_id (default: all)")
        q.add_argument("--out", type=Path, default=None,
                       help=f"file to write; must not exist (default: BAG{suffix})")
        _add_format(q)
        q.set_defaults(_ccsds_run=run_export_oem if q is o else run_export_tdm,
                       _suffix=suffix)


def _add_import(p: argparse.ArgumentParser) -> None:
    sub = p.add_subparsers(dest="ccsds_command", required=True, metavar="{tdm}")
    t = sub.add_parser("tdm", help="a CCSDS TDM (range, az/el) into a bag `replay` runs",
                       description="Read a CCSDS Tracking Data Message (KVN or XML): RANGE "
                                   "(km), ANGLE_1/ANGLE_2 (AZEL, deg) of a known station and "
                                   "one object, into a bag of /ssa/measurement that "
                                   "`ssa-fusion replay` runs through surrogate and filter.")
    t.add_argument("file", type=Path, help="the TDM file")
    t.add_argument("--bag", type=Path, required=True, help="bag to write; must not exist")
    t.add_argument("--sigma", type=float, nargs=3, default=None,
                   metavar=("RANGE_KM", "AZ_DEG", "EL_DEG"),
                   help="measurement noise (1 sigma) for every measurement (default: the "
                        "TDM's 'ssa_fusion sigma:' comment, else the station's sensor preset)")
    t.set_defaults(_ccsds_run=run_import_tdm)


def run(args: argparse.Namespace) -> int:
    """Exit 0 with one summary line; 2 with one `error:` line."""
    try:
        return int(args._ccsds_run(args))
    except (CcsdsError, bagio.BagError, OSError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2


def _output(args: argparse.Namespace) -> tuple[Path, str]:
    bag: Path = args.bag
    out = args.out or (bag.with_suffix("") if bag.suffix == ".mcap" else bag).with_name(
        bag.name.removesuffix(".mcap") + args._suffix)
    if out.exists():
        raise CcsdsError(f"{out} exists already; choose another --out")
    return out, args.format or ("xml" if out.suffix == ".xml" else "kvn")


def run_export_oem(args: argparse.Namespace) -> int:
    out, fmt = _output(args)
    ephem = ephemerides(evaluate.load(args.bag).estimates, args.object)
    write_ndm(oem_document(ephem), out, fmt)
    n = sum(len(v) for v in ephem.values())
    print(f"export oem: {n} states with covariance of {len(ephem)} object(s) "
          f"({', '.join(ephem)}) -> {out} ({fmt.upper()})")
    return 0


def run_export_tdm(args: argparse.Namespace) -> int:
    out, fmt = _output(args)
    ms = evaluate.load(args.bag).measurements
    if args.object is not None:
        ms = [m for m in ms if m.object_id == args.object]
    doc, skipped = tdm_document(ms)
    write_ndm(doc, out, fmt)
    n = sum(len(s.data.observation) for s in doc.body.segment) // 3
    print(f"export tdm: {n} range/az/el measurements in {len(doc.body.segment)} segment(s)"
          f"{f', {skipped} not range/az/el sensor measurements left out' if skipped else ''}"
          f" -> {out} ({fmt.upper()})")
    return 0


def run_import_tdm(args: argparse.Namespace) -> int:
    if args.bag.exists():
        raise CcsdsError(f"{args.bag} exists already; choose another --bag")
    imported = tdm_measurements(read_ndm(args.file), args.sigma, str(args.file))
    write_measurement_bag(args.bag, imported.measurements)
    ms = imported.measurements
    objects = sorted({m.object_id for m in ms})
    stations = sorted({m.frame_id for m in ms})
    note = (f"; {imported.incomplete} epoch(s) without all of RANGE, ANGLE_1, ANGLE_2 "
            f"left out" if imported.incomplete else "")
    print(f"import tdm: {len(ms)} measurements of {', '.join(objects)} from "
          f"{', '.join(stations)}{note} -> {args.bag}; run it with "
          f"`ssa-fusion replay {args.bag}`")
    return 0

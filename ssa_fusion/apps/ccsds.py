"""CCSDS in and out: `ssa-fusion export oem|tdm BAG` and `ssa-fusion import tdm FILE --bag OUT`.

* **OEM** (Orbit Ephemeris Message, CCSDS 502.0, version 3.0) out of a bag: the filter's
  estimates (``/ssa/estimate``), one segment per object (all objects, or ``--object ID``),
  a state vector and a 6x6 covariance per epoch (the last estimate published for that
  epoch). Units km, km/s, km², km²/s, km²/s² as OEM prescribes; ``TIME_SYSTEM = UTC``.
  ``REF_FRAME`` is ``GCRF`` (the estimates' own frame, `core.frames`), or on ``--frame``
  ``EME2000`` (rotated by the IAU 2006 frame bias, `frame_bias`) or ``TEME`` (rotated as
  `frames.gcrs_to_teme` does); covariances are rotated with the states. A bag whose
  estimates say another frame than ``gcrf`` (``eci``: recorded before the frames were the
  real Earth's) is refused.
* **TDM** (Tracking Data Message, CCSDS 503.0, version 2.0) out of a bag: its real
  range/azimuth/elevation (``ANGLE_TYPE = AZEL``) and right ascension/declination
  (``ANGLE_TYPE = RADEC``, astrometric, ``REFERENCE_FRAME = ICRF`` or ``EME2000``)
  measurements (``/ssa/measurement``, SENSOR), one segment per object, station, kind and
  noise level, ``TIME_SYSTEM = UTC``.
* **TDM into a bag** that `ssa-fusion replay` runs through surrogate and filter: of one
  station participant and one object participant, RANGE (km), ANGLE_1 / ANGLE_2 (azimuth /
  elevation, deg, ``AZEL``: the three at one epoch make one RANGE_AZ_EL measurement) or
  ANGLE_1 / ANGLE_2 (right ascension / declination, deg, ``RADEC`` in ``GCRF``, ``ICRF``
  or ``EME2000``: the two at one epoch make one RA_DEC measurement, in GCRF); epochs in
  ``UTC``, ``TAI``, ``TT`` or ``GPS`` (converted to UTC stamps, `timescales`).

Frames: the GCRF has the axes of the ICRF (they differ by origin only, which a direction
does not have), so RA/Dec "in GCRF" and "in ICRF" are the same numbers. The TDM 2.0 schema
(and with it ccsds-ndm) knows ``ICRF`` but not ``GCRF`` as a ``REFERENCE_FRAME``: exports
say ``ICRF``; imports read ``GCRF`` as ``ICRF``.

Files are written and read with the ``ccsds-ndm`` library (KVN or XML; reading tells the
format from the content). Conventions, and what is not supported: docs/CCSDS.md.

TDM carries no measurement noise. The noise of imported measurements is, in this order,
``--sigma`` (AZEL) / ``--sigma-radec`` (RADEC), the metadata comment ``ssa_fusion sigma:``
that `export tdm` writes, else the station's sensor preset (`stations.SENSORS`).

`cli` registers this module under two commands, ``export`` and ``import``; the parser's
name (its last word) says which one `add_arguments` builds.
"""

from __future__ import annotations

import argparse
import dataclasses
import datetime as dt
import enum
import functools
import math
import re
import sys
import warnings
from collections import Counter, defaultdict
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from types import ModuleType
from typing import TYPE_CHECKING, Any, TypeVar

import erfa
import numpy as np
from numpy.typing import NDArray

from ssa_fusion.core import eop, frames, timescales, types
from ssa_fusion.core.frames import Frame
from ssa_fusion.core.stations import SENSORS, STATIONS
from ssa_fusion.ros import bagio, messages
from ssa_fusion.ros.topics import TOPIC_ESTIMATE, TOPIC_MEASUREMENT, TOPIC_TRUTH

if TYPE_CHECKING:  # ccsds-ndm is imported on use (`_ndm`)
    from ccsds_ndm.mapping import NDMFileFormats
    from ccsds_ndm.models.ndmxml4.ndmxml_4_0_0_master_4_0 import Oem, Tdm
    from ccsds_ndm.models.ndmxml4.ndmxml_4_0_0_tdm_2_0 import TrackingDataObservationType
    from ccsds_ndm.ndm_io import NdmIo

Array = NDArray[np.float64]

ORIGINATOR = "ssa_fusion"
SIGMA_COMMENT = "ssa_fusion sigma:"
"""Start of the TDM metadata comment that carries the measurement noise, one standard
deviation per channel in the TDM's units: ``RANGE_KM AZ_DEG EL_DEG`` (AZEL) or ``RA_DEG
DEC_DEG`` (RADEC)."""
_COV = ("x", "y", "z", "x_dot", "y_dot", "z_dot")
"""OEM covariance element names by state index (CX_X, CY_X, ..., CZ_DOT_Z_DOT)."""

GPS_MINUS_TAI_NS = -19_000_000_000
"""GPS time - TAI, ns (constant: GPS time was UTC at 1980-01-06, when TAI - UTC was 19 s)."""
TT_MINUS_TAI_NS = round(timescales.TT_MINUS_TAI * 1e9)
"""TT - TAI, ns (32.184 s, exact)."""


class OemFrame(enum.StrEnum):
    """``REF_FRAME`` of an exported OEM (CCSDS/SANA names)."""

    GCRF = "GCRF"
    """The estimates' own frame (`core.frames`), as they are."""
    EME2000 = "EME2000"
    """Mean equator and equinox of J2000: GCRF rotated by the frame bias (`frame_bias`)."""
    TEME = "TEME"
    """SGP4's True Equator, Mean Equinox of date (Vallado 2006), as `frames.gcrs_to_teme`."""


class AngleFrame(enum.StrEnum):
    """``REFERENCE_FRAME`` of RADEC angles in a TDM (what the importer takes)."""

    ICRF = "ICRF"
    """The axes of the GCRF (same numbers); what `export tdm` writes by default."""
    GCRF = "GCRF"
    """Read as ICRF (not in the TDM 2.0 schema; some tools write it)."""
    EME2000 = "EME2000"
    """Rotated to GCRF by the frame bias (`frame_bias`)."""


TDM_EXPORT_FRAMES = (AngleFrame.ICRF, AngleFrame.EME2000)
"""The ``REFERENCE_FRAME`` values `export tdm --frame` writes RADEC angles in."""


class TimeSystem(enum.StrEnum):
    """``TIME_SYSTEM`` values the TDM importer converts to UTC stamps."""

    UTC = "UTC"
    TAI = "TAI"
    TT = "TT"
    GPS = "GPS"


_TIME_OFFSET_NS = {TimeSystem.TAI: 0, TimeSystem.TT: TT_MINUS_TAI_NS,
                   TimeSystem.GPS: GPS_MINUS_TAI_NS}
"""Time system - TAI, ns, of the time systems tied to TAI."""


class AngleType(enum.StrEnum):
    """``ANGLE_TYPE`` values the TDM exporter writes and the importer reads."""

    AZEL = "AZEL"
    RADEC = "RADEC"


# the ccsds-ndm field names of the TDM observation keywords read and written here
RANGE = "range"
"""``RANGE``, km."""
ANGLE_1 = "angle_1"
"""``ANGLE_1``: azimuth (AZEL) or right ascension (RADEC), deg."""
ANGLE_2 = "angle_2"
"""``ANGLE_2``: elevation (AZEL) or declination (RADEC), deg."""


@dataclass(frozen=True)
class Layout:
    """How one measurement kind is written into and read from a TDM segment.

    Attributes
    ----------
    kind : types.Kind
        The measurement kind.
    angle_type : AngleType
        The segment's ``ANGLE_TYPE``.
    keywords : tuple of str
        The observation fields (ccsds-ndm names) of the channels of ``z``, in order; an
        epoch with all of them makes one measurement.
    sigma_names : tuple of str
        The noise values of `SIGMA_COMMENT` and of `option`, in the TDM's units.
    option : str
        The import option giving the noise of every segment of this kind.
    path : str
        ``PATH`` of an exported segment (``1,2,1``: radar, transmitted and received at the
        station; ``2,1``: light from the object received at the station).
    what : str
        How messages name the measurements.
    """

    kind: types.Kind
    angle_type: AngleType
    keywords: tuple[str, ...]
    sigma_names: tuple[str, ...]
    option: str
    path: str
    what: str

    def to_tdm_units(self, v: Sequence[float] | Array) -> list[float]:
        """Channel values in core units (km, rad) -> TDM units (km, deg)."""
        return [float(x) if k == RANGE else math.degrees(float(x))
                for k, x in zip(self.keywords, v, strict=True)]

    def from_tdm_units(self, v: Sequence[float] | Array) -> Array:
        """Channel values in TDM units (km, deg) -> core units (km, rad)."""
        return np.array([float(x) if k == RANGE else math.radians(float(x))
                         for k, x in zip(self.keywords, v, strict=True)])


AZEL = Layout(types.Kind.RANGE_AZ_EL, AngleType.AZEL, (RANGE, ANGLE_1, ANGLE_2),
              ("RANGE_KM", "AZ_DEG", "EL_DEG"), "--sigma", "1,2,1", "range/az/el")
RADEC = Layout(types.Kind.RA_DEC, AngleType.RADEC, (ANGLE_1, ANGLE_2), ("RA_DEG", "DEC_DEG"),
               "--sigma-radec", "2,1", "ra/dec")
LAYOUTS = {layout.kind: layout for layout in (AZEL, RADEC)}
"""Layouts by measurement kind: the kinds a TDM carries here."""


class CcsdsError(ValueError):
    """Input that cannot become a CCSDS message or a bag; the message says why."""


@functools.cache
def frame_bias() -> Array:
    """Return the rotation GCRF -> EME2000 (3, 3): the IAU 2006 frame bias (`erfa.bp06`'s rb).

    A constant rotation of ~23 mas (0.6 m at 7000 km, 5 m at GEO), the same for positions,
    velocities and directions.
    """
    rb: Array = erfa.bp06(frames.J2000_JD, 0.0)[0]
    return rb


def gcrf_rotation(frame: OemFrame, t_unix: Array) -> Array:
    """Return the rotations GCRF -> `frame` at Unix (UTC) stamps `t_unix` (n,): (n, 3, 3)."""
    n = len(t_unix)
    if frame == OemFrame.EME2000:
        return np.broadcast_to(frame_bias(), (n, 3, 3)).copy()
    if frame == OemFrame.TEME:
        try:
            timescales.check_epochs(t_unix)
        except ValueError as exc:
            raise CcsdsError(str(exc)) from None
        # the matrix `frames.gcrs_to_teme` applies
        return np.swapaxes(frames.teme_to_gcrs_matrix(t_unix), -1, -2)
    return np.broadcast_to(np.eye(3), (n, 3, 3)).copy()


def rotate_radec(ra: float, dec: float, m: Array) -> tuple[float, float]:
    """Return the direction (ra, dec) (rad) rotated by `m` (3, 3): (ra in [0, 2 pi), dec)."""
    cd = math.cos(dec)
    u = m @ np.array([cd * math.cos(ra), cd * math.sin(ra), math.sin(dec)])
    return (math.atan2(u[1], u[0]) % (2 * math.pi),
            math.atan2(u[2], math.hypot(u[0], u[1])))


# ------------------------------------------------------------------------------------------
# epochs: Unix seconds (float, as the bag stamps give them) <-> CCSDS strings, to the ns
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


def _parse_ns(text: str) -> int:
    """CCSDS epoch (calendar or day-of-year form) -> ns since 1970-01-01 of its calendar."""
    m = _EPOCH.match(text.strip())
    if m is None:
        raise CcsdsError(f"epoch {text!r} is not a CCSDS epoch (YYYY-MM-DDThh:mm:ss[.f] "
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
    return sec * 1_000_000_000 + (round(float(f"0.{frac}") * 1e9) if frac else 0)


def _ns_to_seconds(ns: int) -> float:
    """Convert ns to Unix seconds as `messages.stamp_to_seconds` does.

    So a bag's stamps round-trip exactly.
    """
    return messages.stamp_to_seconds(_Stamp(ns // 1_000_000_000, ns % 1_000_000_000))


def parse_epoch(text: str, time_system: TimeSystem = TimeSystem.UTC) -> float:
    """CCSDS epoch in `time_system` (calendar or day-of-year form) -> Unix (UTC) seconds.

    UTC: to the nanosecond, computed as `messages.stamp_to_seconds` does. TAI, TT and GPS:
    shifted to TAI (whole nanoseconds), then by TAI - UTC (`timescales.tai_minus_utc`) of
    the UTC epoch (37 s since 2017); an epoch inside an inserted leap second, which Unix
    stamps cannot hold, lands on the second after it.
    """
    ns = _parse_ns(text)
    if time_system == TimeSystem.UTC:
        return _ns_to_seconds(ns)
    tai_ns = ns - _TIME_OFFSET_NS[time_system]
    t_tai = tai_ns * 1e-9
    dat = float(timescales.tai_minus_utc(t_tai - float(timescales.tai_minus_utc(t_tai))))
    return _ns_to_seconds(tai_ns - round(dat * 1e9))


@dataclass(frozen=True)
class _Stamp:
    """A stamp as the messages hold it: whole seconds and nanoseconds."""

    sec: int
    nanosec: int


def _ndm() -> tuple[NdmIo, type[NDMFileFormats], ModuleType, ModuleType, ModuleType,
                    ModuleType]:
    """Return the ccsds-ndm reader/writer, its formats and its common, master, OEM, TDM models.

    Imported on use: only these commands need the library.
    """
    from ccsds_ndm.mapping import NDMFileFormats
    from ccsds_ndm.models.ndmxml4 import ndmxml_4_0_0_common_4_0 as common
    from ccsds_ndm.models.ndmxml4 import ndmxml_4_0_0_master_4_0 as master
    from ccsds_ndm.models.ndmxml4 import ndmxml_4_0_0_oem_3_0 as oem
    from ccsds_ndm.models.ndmxml4 import ndmxml_4_0_0_tdm_2_0 as tdm
    from ccsds_ndm.ndm_io import NdmIo

    return NdmIo(), NDMFileFormats, common, master, oem, tdm


def _now() -> str:
    """Return the time now, UTC, as a CCSDS epoch to the second (``CREATION_DATE``)."""
    return f"{dt.datetime.now(dt.UTC):%Y-%m-%dT%H:%M:%S}"


def _one_line(exc: BaseException | str) -> str:
    """Return an exception's (or warning's) message on one line (or its type's name)."""
    return " ".join(str(exc).split()) or type(exc).__name__


def write_ndm(doc: object, out: Path, fmt: str) -> None:
    """Write an NDM object tree to `out` as ``kvn`` or ``xml`` (ccsds-ndm)."""
    io, formats, *_ = _ndm()
    text = io.to_string(doc, formats.XML if fmt == "xml" else formats.KVN)
    out.write_text(text if text.endswith("\n") else text + "\n")


_GCRF_REFERENCE = re.compile(r"(REFERENCE_FRAME\s*(?:=|>)\s*)GCRF(?=\s*(?:<|$))",
                             re.IGNORECASE | re.MULTILINE)
"""``REFERENCE_FRAME = GCRF`` (KVN) or ``<REFERENCE_FRAME>GCRF<`` (XML): read as ICRF."""


def read_ndm(path: Path) -> object:
    """Parse a CCSDS NDM file (KVN or XML) with ccsds-ndm; return its object tree.

    CcsdsError (one line naming the file) if it cannot, or if the library could not convert
    a value (XML).

    A TDM ``REFERENCE_FRAME = GCRF``, which the TDM 2.0 schema lacks, is read as ``ICRF``
    (the same axes; module docstring).
    """
    from xsdata.exceptions import ConverterWarning

    io, *_ = _ndm()
    try:
        text = path.read_text()
    except (OSError, UnicodeDecodeError) as exc:
        raise CcsdsError(f"{path}: cannot read: {getattr(exc, 'strerror', None) or exc}") \
            from None
    text = _GCRF_REFERENCE.sub(rf"\g<1>{AngleFrame.ICRF}", text)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", ConverterWarning)
        try:
            doc = io.from_string(text)
        except Exception as exc:  # the parser raises many unrelated types; name the file
            raise CcsdsError(f"{path}: not a readable CCSDS message: {_one_line(exc)}") \
                from None
    for w in caught:
        if issubclass(w.category, ConverterWarning):
            raise CcsdsError(f"{path}: not a readable CCSDS message: {_one_line(w.message)}")
        warnings.warn_explicit(w.message, w.category, w.filename, w.lineno)
    return doc


# ------------------------------------------------------------------------------------------
# bags
# ------------------------------------------------------------------------------------------
@dataclass
class BagContents:
    """What the exports read from a bag (core units), and the frames its states say."""

    estimates: list[types.StateEstimate] = field(default_factory=list)
    measurements: list[types.Measurement] = field(default_factory=list)
    state_frames: dict[str, set[str]] = field(default_factory=lambda: defaultdict(set))
    """``header.frame_id`` of the StateEstimate messages by topic (/ssa/estimate,
    /ssa/truth); `messages.estimate_from_msg` does not keep it."""


def load_bag(bag: Path) -> BagContents:
    """Return the estimates and measurements of `bag`, and the frames of its state messages.

    Messages that do not decode are skipped with a warning (as `evaluate.load` does).
    """
    out = BagContents()
    undecodable: Counter[str] = Counter()
    topics = (TOPIC_ESTIMATE, TOPIC_TRUTH, TOPIC_MEASUREMENT)
    for m in bagio.read_bag(bag, topics=topics, undecodable=undecodable):
        if m.topic == TOPIC_MEASUREMENT:
            out.measurements.append(messages.measurement_from_msg(m.msg))
            continue
        out.state_frames[m.topic].add(str(m.msg.header.frame_id))
        if m.topic == TOPIC_ESTIMATE:
            out.estimates.append(messages.estimate_from_msg(m.msg))
    for topic, n in undecodable.items():
        print(f"warning: {bag}: {n} message(s) on {topic} do not decode as their type; "
              "skipped", file=sys.stderr)
    return out


def require_gcrf(bag: Path, contents: BagContents, topics: Iterable[str], what: str) -> None:
    """Check that every state message on `topics` says frame ``gcrf``.

    CcsdsError (one line naming the bag and the frame) otherwise: `what` (e.g. "estimates")
    would be exported as GCRF.
    """
    for topic in topics:
        other = sorted(f for f in contents.state_frames.get(topic, ()) if f != Frame.GCRF)
        if other:
            raise CcsdsError(
                f"{bag}: its {topic} messages say frame {other[0]!r}, not {Frame.GCRF!r} "
                f"(recorded before ssa_fusion's frames were the real Earth's): its {what} "
                f"are not GCRF; re-record the bag with this version to export it")


# ------------------------------------------------------------------------------------------
# OEM
# ------------------------------------------------------------------------------------------
def ephemerides(estimates: Iterable[types.StateEstimate],
                object_id: str | None = None) -> dict[str, list[types.StateEstimate]]:
    """Return the estimates by object id, for one object or all.

    Sorted by epoch, the last one published per epoch; CcsdsError if there are none (naming
    the objects there are).
    """
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


def in_frame(rows: Sequence[types.StateEstimate],
             frame: OemFrame) -> list[types.StateEstimate]:
    """Rotate GCRF estimates (km, km/s, km²...) to `frame`.

    ``x' = B x``, ``P' = B P B^T`` with ``B = diag(M, M)``, ``M`` the rotation GCRF ->
    `frame` at each epoch (`gcrf_rotation`).
    """
    if frame == OemFrame.GCRF:
        return list(rows)
    m = gcrf_rotation(frame, np.array([e.t for e in rows], dtype=float))
    b = np.zeros((len(rows), 6, 6))
    b[:, :3, :3] = b[:, 3:, 3:] = m
    x = np.einsum("nij,nj->ni", b, np.array([e.x for e in rows], dtype=float))
    p = b @ np.array([e.P for e in rows], dtype=float) @ np.swapaxes(b, -1, -2)
    return [dataclasses.replace(e, x=xi, P=0.5 * (pi + pi.T))
            for e, xi, pi in zip(rows, x, p, strict=True)]


def _oem_comment(frame: OemFrame) -> str:
    """Return a comment saying what the segment's REF_FRAME is and how it was computed."""
    source = Path(eop.default().source).name
    return {
        OemFrame.GCRF: f"GCRF: the estimates as ssa_fusion computes them (IERS 2010, "
                       f"IAU 2006/2000A, EOP {source})",
        OemFrame.EME2000: "EME2000: the GCRF estimates rotated by the IAU 2006 frame bias "
                          "(ERFA bp06)",
        OemFrame.TEME: f"TEME (Vallado 2006, GMST 1982): the GCRF estimates rotated to it, "
                       f"EOP {source}",
    }[frame]


def oem_document(ephem: dict[str, list[types.StateEstimate]],
                 frame: OemFrame = OemFrame.GCRF) -> Oem:
    """Return an OEM 3.0 object tree of the GCRF estimates `ephem`.

    One segment per object, state + covariance per epoch, in `frame` (the estimates are
    GCRF; `in_frame`), TIME_SYSTEM UTC.
    """
    _, _, common, master, oem, _ = _ndm()
    km, kms = common.PositionUnits.KM, common.VelocityUnits.KM_S
    cov_types = {f: _cov_type(common, f) for f in _cov_fields()}
    segments = []
    for oid, gcrf_rows in ephem.items():
        rows = in_frame(gcrf_rows, frame)
        meta = oem.OemMetadata(
            comment=[_oem_comment(frame)], object_name=oid, object_id=oid,
            center_name="EARTH", ref_frame=str(frame), time_system=TimeSystem.UTC.value,
            start_time=format_epoch(rows[0].t), stop_time=format_epoch(rows[-1].t))
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


def _cov_type(common: ModuleType, name: str) -> Callable[..., object]:
    """Return the ccsds-ndm wrapper type of covariance field `name` (km², km²/s or km²/s²)."""
    wrappers: tuple[Callable[..., object], ...] = (
        common.PositionCovarianceType, common.PositionVelocityCovarianceType,
        common.VelocityCovarianceType)
    return wrappers[name.count("dot")]


def oem_states(doc: Oem) -> dict[str, list[types.StateEstimate]]:
    """Return the estimates of an OEM object tree (as ccsds-ndm parses it) by OBJECT_ID.

    In km, km/s, km², in the file's REF_FRAME and UTC epochs (not converted).

    Only segments with covariances at the state vectors' epochs keep them; others get
    zero covariance.
    """
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
# TDM out
# ------------------------------------------------------------------------------------------
@dataclass
class TdmExport:
    """A TDM object tree, the measurements in it by kind, and how many were left out."""

    doc: Tdm
    counts: Counter[int]
    skipped: int


def _radec_frame_comment(frame: AngleFrame) -> str:
    """Return a comment saying how the RADEC angles of a segment in `frame` were computed."""
    return ("RA/Dec astrometric (station to object, no aberration), "
            + ("GCRF axes, which are the ICRF axes" if frame == AngleFrame.ICRF else
               "GCRF rotated to EME2000 by the IAU 2006 frame bias (ERFA bp06)"))


def tdm_document(measurements: Iterable[types.Measurement],
                 frame: AngleFrame = AngleFrame.ICRF) -> TdmExport:
    """Return a TDM 2.0 object tree of the real range/az/el and ra/dec measurements.

    One segment per object, station, kind and noise level, TIME_SYSTEM UTC; RADEC in
    `frame` (ICRF: the GCRF values; EME2000: rotated by `frame_bias`). CcsdsError if no
    measurement is left (forecasts and other kinds are left out and counted).
    """
    if frame not in TDM_EXPORT_FRAMES:
        raise CcsdsError(f"TDM export writes RADEC in {', '.join(TDM_EXPORT_FRAMES)}, "
                         f"not {frame}")
    _, _, common, master, _, tdm = _ndm()
    groups: dict[tuple[str, str, int, tuple[float, ...]], list[types.Measurement]] = \
        defaultdict(list)
    skipped = 0
    for m in measurements:
        if m.kind not in LAYOUTS or m.source != types.Source.SENSOR:
            skipped += 1
            continue
        sigma = tuple(float(s) for s in np.sqrt(np.diag(np.asarray(m.R, dtype=float))))
        groups[(m.object_id or "unknown", m.frame_id, int(m.kind), sigma)].append(m)
    if not groups:
        raise CcsdsError("no real range/azimuth/elevation or right ascension/declination "
                         "measurements to export (TDM export supports RANGE_AZ_EL and RA_DEC "
                         "sensor measurements)")
    deg = common.AngleUnits.DEG
    bias = frame_bias() if frame == AngleFrame.EME2000 else None
    segments = []
    counts: Counter[int] = Counter()
    for (oid, station, kind, sigma), rows in groups.items():
        layout = LAYOUTS[types.Kind(kind)]
        rows.sort(key=lambda m: m.t)
        comment = [f"{SIGMA_COMMENT} " + " ".join(repr(v) for v in layout.to_tdm_units(sigma))]
        extra: dict[str, Any] = {"range_units": tdm.RangeUnitsType.KM} if layout is AZEL else {
            "reference_frame": tdm.RefFrameType(str(frame))}
        if layout is RADEC:
            comment.append(_radec_frame_comment(frame))
        meta = tdm.TdmMetadata(
            comment=comment, time_system=TimeSystem.UTC.value,
            start_time=format_epoch(rows[0].t), stop_time=format_epoch(rows[-1].t),
            participant_1=station, participant_2=oid, mode=tdm.ModeType.SEQUENTIAL,
            path=layout.path, angle_type=tdm.AngleTypeType(str(layout.angle_type)), **extra)
        obs = []
        for m in rows:
            epoch = format_epoch(m.t)
            z = np.asarray(m.z, dtype=float)
            if bias is not None and layout is RADEC:
                z = np.array(rotate_radec(float(z[0]), float(z[1]), bias))
            for key, value in zip(layout.keywords, layout.to_tdm_units(z), strict=True):
                v = value if key == RANGE else common.AngleType(value=value, units=deg)
                obs.append(tdm.TrackingDataObservationType(epoch=epoch, **{key: v}))
        counts[kind] += len(rows)
        segments.append(tdm.TdmSegment(metadata=meta, data=tdm.TdmData(observation=obs)))
    header = tdm.TdmHeader(creation_date=_now(), originator=ORIGINATOR)
    doc = master.Tdm(header=header, body=tdm.TdmBody(segment=segments))
    return TdmExport(doc, counts, skipped)


# ------------------------------------------------------------------------------------------
# TDM in
# ------------------------------------------------------------------------------------------
@dataclass
class Imported:
    r"""Measurements read from a TDM, and what was left out (counted, never silently).

    Attributes
    ----------
    measurements : list of types.Measurement
        Sorted by epoch (UTC stamps).
    incomplete : int
        Epochs lacking one of their layout's keywords (`Layout.keywords`).
    invalid : int
        Epochs with a non-finite or impossible value (negative range, \|el\| or \|dec\|
        over 90 deg); `first_invalid` says the first one read.
    unused : Counter
        Observations of keywords not read (e.g. DOPPLER_INSTANTANEOUS, RANGE in a RADEC
        segment), by keyword.
    """

    measurements: list[types.Measurement]
    incomplete: int = 0
    invalid: int = 0
    first_invalid: str = ""
    unused: Counter[str] = field(default_factory=Counter)

    def left_out(self) -> str:
        """Return what was left out, as a clause of the summary line ("" if nothing)."""
        parts = []
        if self.incomplete:
            parts.append(f"{self.incomplete} epoch(s) without all their keywords")
        if self.invalid:
            parts.append(f"{self.invalid} epoch(s) with invalid values (first: "
                         f"{self.first_invalid})")
        if self.unused:
            parts.append("observations not used: " + ", ".join(
                f"{n} {k}" for k, n in sorted(self.unused.items())))
        return f"; left out: {'; '.join(parts)}" if parts else ""


_E = TypeVar("_E", bound=enum.StrEnum)


def _meta_value(meta: object, key: str) -> str | None:
    """Return a metadata keyword's value (enum or str) in capitals, or None if absent."""
    got = getattr(meta, key, None)
    got = getattr(got, "value", got)
    return None if got is None or str(got).strip() == "" else str(got).strip().upper()


def _choice(meta: object, key: str, allowed: Iterable[_E], where: str,
            default: _E | None = None) -> _E:
    """Return the metadata keyword `key` as one of `allowed` (its `default` if absent).

    CcsdsError (one line naming `where` and the value) otherwise.
    """
    allowed = list(allowed)
    got = _meta_value(meta, key)
    if got is None and default is not None:
        return default
    for a in allowed:
        if got == a.value:
            return a
    said = "missing" if got is None else f"= {got} is not supported"
    raise CcsdsError(f"{where}: {key.upper()} {said} (supported: "
                     f"{', '.join(a.value for a in allowed)})")


class _RangeUnits(enum.StrEnum):
    """``RANGE_UNITS`` the importer takes (TDM's default)."""

    KM = "KM"


def _segment_layout(meta: object, where: str) -> tuple[Layout, Array | None]:
    """Return the segment's layout (ANGLE_TYPE, RANGE_UNITS) and its RADEC frame's rotation.

    For RADEC, the rotation of its REFERENCE_FRAME to GCRF (None: none needed).
    """
    angle_type = _choice(meta, "angle_type", AngleType, where)
    if angle_type == AngleType.AZEL:
        _choice(meta, "range_units", _RangeUnits, where, default=_RangeUnits.KM)
        return AZEL, None
    ref = _choice(meta, "reference_frame", AngleFrame, where)
    return RADEC, (frame_bias().T if ref == AngleFrame.EME2000 else None)


def _participants(meta: object, where: str) -> tuple[str, str]:
    """Return (station id, object id) of a TDM segment.

    The one participant that is a known station and the one that is not.
    """
    names = [p for i in range(1, 6) if (p := getattr(meta, f"participant_{i}", None))]
    stations = [p for p in names if p.lower() in STATIONS]
    others = [p for p in names if p.lower() not in STATIONS]
    if len(stations) != 1 or len(others) != 1:
        raise CcsdsError(
            f"{where}: participants {', '.join(names)}: need one known station "
            f"({', '.join(sorted(STATIONS))}) and one object")
    return stations[0].lower(), others[0]


def _segment_sigma(meta: object, station: str, layout: Layout,
                   sigma: Sequence[float] | None, where: str) -> Array:
    """Return the noise of a segment's measurements in core units (km, rad).

    `sigma` (TDM units), else the segment's `SIGMA_COMMENT`, else the station's sensor
    preset of that kind.
    """
    want = " ".join(layout.sigma_names)
    if sigma is None:
        for line in getattr(meta, "comment", None) or []:
            if line.strip().startswith(SIGMA_COMMENT):
                try:
                    sigma = [float(v) for v in line.strip()[len(SIGMA_COMMENT):].split()]
                except ValueError:
                    sigma = []
                if len(sigma) != len(layout.sigma_names):
                    raise CcsdsError(f"{where}: malformed comment {line.strip()!r} (want "
                                     f"'{SIGMA_COMMENT} {want}' for {layout.angle_type})")
    if sigma is None:
        preset = SENSORS.get(station)
        if preset is None or preset.kind != layout.kind:
            raise CcsdsError(f"{where}: no noise for {layout.angle_type} measurements of "
                             f"station {station}: give {layout.option} {want}")
        return np.asarray(preset.sigma, dtype=float)
    if len(sigma) != len(layout.sigma_names) or not all(
            math.isfinite(s) and s > 0 for s in sigma):
        raise CcsdsError(f"{where}: noise must be {want}, finite and > 0, got {list(sigma)}")
    return layout.from_tdm_units(sigma)


_FIELDS: dict[type, tuple[str, ...]] = {}


def _observation_fields(ob: TrackingDataObservationType) -> tuple[str, ...]:
    """Return the value fields of a ccsds-ndm observation (all but EPOCH and COMMENT)."""
    cls = type(ob)
    if cls not in _FIELDS:
        _FIELDS[cls] = tuple(f.name for f in dataclasses.fields(cls)
                             if f.name not in ("epoch", "comment"))
    return _FIELDS[cls]


def _why_invalid(layout: Layout, v: Array) -> str:
    """Why channel values in TDM units (km, deg) are not a measurement ("" if they are)."""
    names = dict(zip(layout.keywords, v.tolist(), strict=True))
    if not np.all(np.isfinite(v)):
        return "non-finite " + ", ".join(k.upper() for k, x in names.items()
                                         if not math.isfinite(x))
    if layout is AZEL and names[RANGE] < 0:
        return f"negative RANGE {names[RANGE]!r} km"
    if abs(names[ANGLE_2]) > 90.0:
        return f"ANGLE_2 ({'elevation' if layout is AZEL else 'declination'}) " \
               f"{names[ANGLE_2]!r} deg beyond +-90"
    return ""


def tdm_measurements(doc: object, sigma: Mapping[types.Kind, Sequence[float]] | None = None,
                     source: str = "TDM") -> Imported:
    """Return the RANGE_AZ_EL (km, rad) and RA_DEC (rad, GCRF) measurements of a TDM.

    `doc` is the TDM's object tree (`read_ndm`); the measurements are sorted by epoch (UTC
    stamps).

    `sigma`: noise by measurement kind in TDM units (range km, azimuth deg, elevation deg;
    ra deg, dec deg) for every segment of that kind, else each segment's ``ssa_fusion
    sigma:`` comment, else its station's sensor preset. CcsdsError (one line naming
    `source`, the segment and the value) for what this importer does not support: time
    systems other than UTC, TAI, TT, GPS; angle types other than AZEL and RADEC; RADEC in
    frames other than GCRF, ICRF, EME2000; range units other than km; unknown stations;
    epochs outside `timescales.EPOCH_MIN` .. `EPOCH_MAX`. Epochs lacking a keyword, with
    non-finite or impossible values, and observations of other keywords are left out and
    counted (`Imported`).
    """
    if not hasattr(doc, "body") or not hasattr(doc.body, "segment") or \
            type(doc).__name__.lower() != "tdm":
        raise CcsdsError(f"{source}: not a TDM (it is {type(doc).__name__})")
    out = Imported([])
    sigma = sigma or {}
    for k, seg in enumerate(doc.body.segment, 1):
        where = f"{source}: segment {k}"
        meta = seg.metadata
        time_system = _choice(meta, "time_system", TimeSystem, where)
        layout, to_gcrf = _segment_layout(meta, where)
        station, oid = _participants(meta, where)
        R = np.diag(_segment_sigma(meta, station, layout, sigma.get(layout.kind), where)**2)
        stamps: dict[str, float] = {}  # epoch text -> UTC stamp
        epochs: dict[float, dict[str, float]] = defaultdict(dict)
        for ob in seg.data.observation:
            text = str(ob.epoch)
            if text not in stamps:
                try:
                    stamps[text] = parse_epoch(text, time_system)
                except CcsdsError as exc:
                    raise CcsdsError(f"{where}: {exc}") from None
            for key in _observation_fields(ob):
                value = getattr(ob, key)
                if value is None or value == []:
                    continue
                if key in layout.keywords:
                    epochs[stamps[text]][key] = float(getattr(value, "value", value))
                else:
                    out.unused[key.upper()] += 1
        try:
            timescales.check_epochs(list(epochs), f"{where}: epoch")
        except ValueError as exc:
            raise CcsdsError(str(exc)) from None
        for t, ch in sorted(epochs.items()):
            if len(ch) < len(layout.keywords):
                out.incomplete += 1
                continue
            v = np.array([ch[key] for key in layout.keywords])
            why = _why_invalid(layout, v)
            if why:
                out.invalid += 1
                out.first_invalid = out.first_invalid or f"{where}, {format_epoch(t)} UTC: {why}"
                continue
            z = layout.from_tdm_units(v)
            if layout is AZEL:
                z[1] %= 2 * math.pi
            else:
                z = np.array(rotate_radec(float(z[0]), float(z[1]),
                                          np.eye(3) if to_gcrf is None else to_gcrf))
            out.measurements.append(types.Measurement(
                t=t, z=z, R=R.copy(), kind=layout.kind,
                source=types.Source.SENSOR, object_id=oid, frame_id=station))
    if not out.measurements:
        raise CcsdsError(f"{source}: no usable epoch (need RANGE, ANGLE_1 and ANGLE_2 for "
                         f"AZEL, ANGLE_1 and ANGLE_2 for RADEC){out.left_out()}")
    out.measurements.sort(key=lambda m: m.t)
    return out


def write_measurement_bag(out: Path, measurements: Sequence[types.Measurement]) -> None:
    """Write the bag `out` of `measurements` on /ssa/measurement, each logged at its stamp.

    What `replay` plays; it derives /clock from the stamps.
    """
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
    """Add the `export` or the `import` subcommands to `p` (by the last word of its name)."""
    if p.prog.split()[-1] == "import":
        _add_import(p)
    else:
        _add_export(p)


def _add_format(p: argparse.ArgumentParser) -> None:
    """Add ``--format`` (kvn or xml) to `p`."""
    p.add_argument("--format", choices=("kvn", "xml"), default=None,
                   help="file format (default: xml if --out ends in .xml, else kvn)")


def _add_export(p: argparse.ArgumentParser) -> None:
    """Add `export oem` and `export tdm` to `p`."""
    sub = p.add_subparsers(dest="ccsds_command", required=True, metavar="{oem,tdm}")
    o = sub.add_parser("oem", help="the filter's estimates with covariance as a CCSDS OEM",
                       description="Write the estimates of a bag (/ssa/estimate) as a CCSDS "
                                   "Orbit Ephemeris Message: one segment per object, state "
                                   "(km, km/s) and 6x6 covariance (km^2 ...) per epoch, UTC, "
                                   "in GCRF (their frame), EME2000 or TEME.")
    o.add_argument("--frame", type=str.upper, choices=[f.value for f in OemFrame],
                   default=OemFrame.GCRF.value,
                   help="REF_FRAME: GCRF (the estimates as they are; default), EME2000 "
                        "(IAU 2006 frame bias) or TEME (SGP4's)")
    t = sub.add_parser("tdm", help="the real range/az/el and ra/dec measurements as a CCSDS "
                                   "TDM",
                       description="Write the sensor measurements of a bag (/ssa/measurement) "
                                   "as a CCSDS Tracking Data Message, UTC: range/azimuth/"
                                   "elevation as RANGE km, ANGLE_1/ANGLE_2 (AZEL, deg); "
                                   "right ascension/declination as ANGLE_1/ANGLE_2 (RADEC, "
                                   "deg, astrometric).")
    t.add_argument("--frame", type=str.upper, choices=[f.value for f in TDM_EXPORT_FRAMES],
                   default=AngleFrame.ICRF.value,
                   help="REFERENCE_FRAME of RADEC angles: ICRF (the GCRF values: the same "
                        "axes; default) or EME2000 (rotated by the IAU 2006 frame bias)")
    for q, suffix in ((o, ".oem"), (t, ".tdm")):
        q.add_argument("bag", type=Path, help="rosbag2 directory or .mcap file")
        q.add_argument("--object", default=None, help="only this object_id (default: all)")
        q.add_argument("--out", type=Path, default=None,
                       help=f"file to write; must not exist (default: BAG{suffix})")
        _add_format(q)
        q.set_defaults(_ccsds_run=run_export_oem if q is o else run_export_tdm,
                       _suffix=suffix)


def _add_import(p: argparse.ArgumentParser) -> None:
    """Add `import tdm` to `p`."""
    sub = p.add_subparsers(dest="ccsds_command", required=True, metavar="{tdm}")
    t = sub.add_parser("tdm", help="a CCSDS TDM (range, az/el or ra/dec) into a bag `replay` "
                                   "runs",
                       description="Read a CCSDS Tracking Data Message (KVN or XML; UTC, TAI, "
                                   "TT or GPS): RANGE (km), ANGLE_1/ANGLE_2 (AZEL, deg) or "
                                   "ANGLE_1/ANGLE_2 (RADEC in GCRF, ICRF or EME2000, deg) of a "
                                   "known station and one object, into a bag of "
                                   "/ssa/measurement that `ssa-fusion replay` runs through "
                                   "surrogate and filter.")
    t.add_argument("file", type=Path, help="the TDM file")
    t.add_argument("--bag", type=Path, required=True, help="bag to write; must not exist")
    for layout in LAYOUTS.values():
        t.add_argument(layout.option, type=float, nargs=len(layout.sigma_names), default=None,
                       metavar=layout.sigma_names, dest=f"sigma_{layout.angle_type.lower()}",
                       help=f"measurement noise (1 sigma) of every {layout.angle_type} "
                            f"measurement (default: the TDM's '{SIGMA_COMMENT}' comment, "
                            f"else the station's sensor preset)")
    t.set_defaults(_ccsds_run=run_import_tdm)


def run(args: argparse.Namespace) -> int:
    """Exit 0 with one summary line; 2 with one `error:` line."""
    try:
        return int(args._ccsds_run(args))
    except (CcsdsError, bagio.BagError, OSError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2


def _output(args: argparse.Namespace) -> tuple[Path, str]:
    """Return the file to write (``--out``, else next to the bag) and its format."""
    bag: Path = args.bag
    out = args.out or (bag.with_suffix("") if bag.suffix == ".mcap" else bag).with_name(
        bag.name.removesuffix(".mcap") + args._suffix)
    if out.exists():
        raise CcsdsError(f"{out} exists already; choose another --out")
    return out, args.format or ("xml" if out.suffix == ".xml" else "kvn")


def run_export_oem(args: argparse.Namespace) -> int:
    """Run `export oem`: write the bag's estimates as an OEM; return 0."""
    out, fmt = _output(args)
    contents = load_bag(args.bag)
    require_gcrf(args.bag, contents, (TOPIC_ESTIMATE,), "estimates")
    ephem = ephemerides(contents.estimates, args.object)
    write_ndm(oem_document(ephem, OemFrame(args.frame)), out, fmt)
    n = sum(len(v) for v in ephem.values())
    print(f"export oem: {n} states with covariance of {len(ephem)} object(s) "
          f"({', '.join(ephem)}) in {args.frame}, UTC -> {out} ({fmt.upper()})")
    return 0


def run_export_tdm(args: argparse.Namespace) -> int:
    """Run `export tdm`: write the bag's real measurements as a TDM; return 0."""
    out, fmt = _output(args)
    contents = load_bag(args.bag)
    ms = contents.measurements
    if args.object is not None:
        ms = [m for m in ms if m.object_id == args.object]
    if any(m.kind == types.Kind.RA_DEC for m in ms):  # their RA/Dec are in the states' frame
        require_gcrf(args.bag, contents, (TOPIC_ESTIMATE, TOPIC_TRUTH), "RA/Dec measurements")
    export = tdm_document(ms, AngleFrame(args.frame))
    write_ndm(export.doc, out, fmt)
    said = " and ".join(f"{n} {LAYOUTS[types.Kind(k)].what}" for k, n in
                        sorted(export.counts.items()))
    left = (f", {export.skipped} forecasts or other kinds left out" if export.skipped else "")
    print(f"export tdm: {said} measurements in {len(export.doc.body.segment)} segment(s)"
          f"{left} -> {out} ({fmt.upper()})")
    return 0


def run_import_tdm(args: argparse.Namespace) -> int:
    """Run `import tdm`: write the TDM's measurements to a new bag; return 0."""
    if args.bag.exists():
        raise CcsdsError(f"{args.bag} exists already; choose another --bag")
    sigma = {layout.kind: s for layout in LAYOUTS.values()
             if (s := getattr(args, f"sigma_{layout.angle_type.lower()}", None)) is not None}
    imported = tdm_measurements(read_ndm(args.file), sigma, str(args.file))
    write_measurement_bag(args.bag, imported.measurements)
    ms = imported.measurements
    objects = sorted({m.object_id for m in ms})
    stations = sorted({m.frame_id for m in ms})
    kinds = Counter(int(m.kind) for m in ms)
    said = " and ".join(f"{n} {LAYOUTS[types.Kind(k)].what}" for k, n in sorted(kinds.items()))
    print(f"import tdm: {said} measurements of {', '.join(objects)} from "
          f"{', '.join(stations)}{imported.left_out()} -> {args.bag}; run it with "
          f"`ssa-fusion replay {args.bag}`")
    return 0

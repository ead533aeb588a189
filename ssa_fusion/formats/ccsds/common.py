"""What the CCSDS messages of `ssa-fusion export` and `import` share.

* the error every step raises (`CcsdsError`: one line saying why);
* epochs: Unix seconds (as the bag stamps give them) <-> CCSDS epoch strings, to the
  nanosecond, in the time systems the TDM importer takes (`TimeSystem`: UTC, TAI, TT, GPS);
* frames: the OEM's ``REF_FRAME`` (`OemFrame`) and the TDM's RADEC ``REFERENCE_FRAME``
  (`AngleFrame`), the IAU 2006 frame bias (`frame_bias`) and the rotations out of the GCRF;
* how a measurement kind is written into and read from a TDM segment (`Layout`: `AZEL`,
  `RADEC`);
* writing NDM files (KVN or XML, `ndm_format` tells which from the file name) with the
  ``ccsds-ndm`` library, imported on use (a TDM is read as a stream by `tdm_reader`, which
  needs no model of the whole file); measurement counts in words (`counts_said`).

The messages themselves: `oem` (OEM out), `tdm_out` (TDM out), `tdm_in` (TDM in, read by
`tdm_reader`); the commands: `apps.ccsds`. Conventions: docs/CCSDS.md.
"""

from __future__ import annotations

import calendar
import datetime as dt
import enum
import functools
import math
import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from types import ModuleType
from typing import TYPE_CHECKING

import erfa
import numpy as np
from numpy.typing import NDArray

from ssa_fusion.core.base import types
from ssa_fusion.core.base.quoting import quote
from ssa_fusion.core.earth import frames, timescales

if TYPE_CHECKING:  # ccsds-ndm is imported on use (`ndm`)
    from ccsds_ndm.mapping import NDMFileFormats
    from ccsds_ndm.ndm_io import NdmIo

Array = NDArray[np.float64]

ORIGINATOR = "ssa_fusion"
SIGMA_COMMENT = "ssa_fusion sigma:"
"""Start of the TDM metadata comment that carries the measurement noise, one standard
deviation per channel in the TDM's units: ``RANGE_KM AZ_DEG EL_DEG`` (AZEL) or ``RA_DEG
DEC_DEG`` (RADEC)."""

GPS_MINUS_TAI_NS = -19_000_000_000
"""GPS time - TAI, ns (constant: GPS time was UTC at 1980-01-06, when TAI - UTC was 19 s)."""
TT_MINUS_TAI_NS = round(timescales.TT_MINUS_TAI * 1e9)
"""TT - TAI, ns (32.184 s, exact)."""


class OemFrame(enum.StrEnum):
    """``REF_FRAME`` of an exported OEM (CCSDS/SANA names)."""

    GCRF = "GCRF"
    """The estimates' own frame (`core.earth.frames`), as they are."""
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


def counts_said(counts: Mapping[int, int]) -> str:
    """Return measurement counts by kind (`types.Kind`) as words: "20 range/az/el and 8 ra/dec"."""
    return " and ".join(f"{n} {LAYOUTS[types.Kind(k)].what}" for k, n in sorted(counts.items()))


# ------------------------------------------------------------------------------------------
# frames
# ------------------------------------------------------------------------------------------
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
_EPOCH = re.compile(r"^(\d{4})-(?:(\d{2})-(\d{2})|(\d{3}))T(\d{2}):(\d{2}):(\d{2})(?:\.(\d+))?Z?$",
                    re.ASCII)


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
        raise CcsdsError(f"epoch {quote(text)} is not a CCSDS epoch (YYYY-MM-DDThh:mm:ss[.f] "
                         f"or YYYY-DDDThh:mm:ss[.f])")
    year, month, day, doy, hh, mm, ss, frac = m.groups()
    try:
        if doy is not None:
            if not 1 <= int(doy) <= (366 if calendar.isleap(int(year)) else 365):
                raise ValueError(f"day of year {doy} is not in the year {year}")
            date = dt.datetime(int(year), 1, 1, tzinfo=dt.UTC) + dt.timedelta(days=int(doy) - 1)
        else:
            date = dt.datetime(int(year), int(month), int(day), tzinfo=dt.UTC)
        if int(hh) > 23 or int(mm) > 59 or int(ss) > 60:
            raise ValueError(f"time of day {hh}:{mm}:{ss} is not one (hh <= 23, mm <= 59, "
                             f"ss <= 60)")
    except (ValueError, OverflowError) as exc:
        raise CcsdsError(f"epoch {quote(text)}: {exc}") from None
    sec = int(date.timestamp()) + int(hh) * 3600 + int(mm) * 60 + int(ss)
    return sec * 1_000_000_000 + (round(float(f"0.{frac}") * 1e9) if frac else 0)


def _ns_to_seconds(ns: int) -> float:
    """Convert ns to Unix seconds as a bag's stamps are read (`timescales.stamp_seconds`).

    So a bag's stamps round-trip exactly.
    """
    return timescales.stamp_seconds(ns // 1_000_000_000, ns % 1_000_000_000)


def parse_epoch(text: str, time_system: TimeSystem = TimeSystem.UTC) -> float:
    """CCSDS epoch in `time_system` (calendar or day-of-year form) -> Unix (UTC) seconds.

    UTC: to the nanosecond, computed as `timescales.stamp_seconds` does. TAI, TT and GPS:
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


# ------------------------------------------------------------------------------------------
# NDM files (ccsds-ndm)
# ------------------------------------------------------------------------------------------
def ndm() -> tuple[NdmIo, type[NDMFileFormats], ModuleType, ModuleType, ModuleType,
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


def creation_date() -> str:
    """Return the time now, UTC, as a CCSDS epoch to the second (``CREATION_DATE``)."""
    return f"{dt.datetime.now(dt.UTC):%Y-%m-%dT%H:%M:%S}"


def ndm_format(out: Path, given: str | None = None) -> str:
    """Return the NDM format of a file to write: `given` ("kvn", "xml"), else by its name.

    ``xml`` for a name ending in ``.xml``, else ``kvn``.
    """
    return given or ("xml" if out.suffix == ".xml" else "kvn")


def write_ndm(doc: object, out: Path, fmt: str) -> None:
    """Write an NDM object tree to `out` as ``kvn`` or ``xml`` (ccsds-ndm)."""
    io, formats, *_ = ndm()
    text = io.to_string(doc, formats.XML if fmt == "xml" else formats.KVN)
    out.write_text(text if text.endswith("\n") else text + "\n")

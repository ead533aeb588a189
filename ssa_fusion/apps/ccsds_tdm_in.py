"""`ssa-fusion import tdm`'s reading: the measurements of a CCSDS TDM.

Of one station participant and one object participant: RANGE (km), ANGLE_1 / ANGLE_2
(azimuth / elevation, deg, ``AZEL``: the three at one epoch make one RANGE_AZ_EL
measurement) or ANGLE_1 / ANGLE_2 (right ascension / declination, deg, ``RADEC`` in
``GCRF``, ``ICRF`` or ``EME2000``: the two at one epoch make one RA_DEC measurement, in
GCRF); epochs in ``UTC``, ``TAI``, ``TT`` or ``GPS`` (converted to UTC stamps,
`timescales`). TDM carries no measurement noise: it is given per kind, else read from the
metadata comment `ccsds_format.SIGMA_COMMENT` that `export tdm` writes, else the station's
sensor (a sites file's, `core.site_file`, or the built-in preset, `stations.SENSORS`).
Participants name built-in stations or those of a sites file (``--sites``).
"""

from __future__ import annotations

import dataclasses
import enum
import math
from collections import Counter, defaultdict
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, TypeVar

import numpy as np

from ssa_fusion.apps.ccsds_format import (
    ANGLE_2,
    AZEL,
    RADEC,
    RANGE,
    SIGMA_COMMENT,
    AngleFrame,
    AngleType,
    Array,
    CcsdsError,
    Layout,
    TimeSystem,
    format_epoch,
    frame_bias,
    parse_epoch,
    rotate_radec,
)
from ssa_fusion.core import timescales, types
from ssa_fusion.core.stations import SENSORS, STATIONS, Sensor

if TYPE_CHECKING:  # ccsds-ndm is imported on use (`ccsds_format.ndm`)
    from ccsds_ndm.models.ndmxml4.ndmxml_4_0_0_tdm_2_0 import TrackingDataObservationType

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


def _number(value: object) -> float:
    """Return an observation's value as a float, NaN when it is not a number.

    An empty ``<RANGE></RANGE>`` or text: left out as invalid, like a NaN.
    """
    try:
        return float(value)  # type: ignore[arg-type]
    except (TypeError, ValueError):
        return math.nan


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


def _participants(meta: object, where: str, sites: Mapping[str, Sensor]) -> tuple[str, str]:
    """Return (station id, object id) of a TDM segment.

    The one participant that is a known station (built in, or of `sites`; by its id in
    lowercase) and the one that is not.
    """
    names = [p for i in range(1, 6) if (p := getattr(meta, f"participant_{i}", None))]
    known = {*STATIONS, *sites}
    stations = [p for p in names if p.lower() in known]
    others = [p for p in names if p.lower() not in known]
    if len(stations) != 1 or len(others) != 1:
        own = (f"; your sites: {', '.join(sites)}" if sites else
               "; a station of your own: --sites FILE (docs/SITES.md)")
        raise CcsdsError(
            f"{where}: participants {', '.join(names)}: need one known station "
            f"({', '.join(sorted(STATIONS))}{own}) and one object")
    return stations[0].lower(), others[0]


def _segment_sigma(meta: object, station: str, layout: Layout,
                   sigma: Sequence[float] | None, where: str,
                   sites: Mapping[str, Sensor]) -> Array:
    """Return the noise of a segment's measurements in core units (km, rad).

    `sigma` (TDM units), else the segment's `SIGMA_COMMENT`, else the station's sensor
    (of `sites`, else its built-in preset) if it measures that kind.
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
        preset = sites.get(station) or SENSORS.get(station)
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
        return "non-finite or unreadable " + ", ".join(k.upper() for k, x in names.items()
                                         if not math.isfinite(x))
    if layout is AZEL and names[RANGE] < 0:
        return f"negative RANGE {names[RANGE]!r} km"
    if abs(names[ANGLE_2]) > 90.0:
        return f"ANGLE_2 ({'elevation' if layout is AZEL else 'declination'}) " \
               f"{names[ANGLE_2]!r} deg beyond +-90"
    return ""


def tdm_measurements(doc: object, sigma: Mapping[types.Kind, Sequence[float]] | None = None,
                     source: str = "TDM", sites: Mapping[str, Sensor] | None = None) -> Imported:
    """Return the RANGE_AZ_EL (km, rad) and RA_DEC (rad, GCRF) measurements of a TDM.

    `doc` is the TDM's object tree (`read_ndm`); the measurements are sorted by epoch (UTC
    stamps).

    `sigma`: noise by measurement kind in TDM units (range km, azimuth deg, elevation deg;
    ra deg, dec deg) for every segment of that kind, else each segment's ``ssa_fusion
    sigma:`` comment, else its station's sensor. `sites`: stations of one's own by id
    (`core.site_file.load_sites`), which participants may name besides the built-in
    stations. CcsdsError (one line naming
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
    sites = sites or {}
    for k, seg in enumerate(doc.body.segment, 1):
        where = f"{source}: segment {k}"
        meta = seg.metadata
        time_system = _choice(meta, "time_system", TimeSystem, where)
        layout, to_gcrf = _segment_layout(meta, where)
        station, oid = _participants(meta, where, sites)
        R = np.diag(_segment_sigma(meta, station, layout, sigma.get(layout.kind), where,
                                   sites)**2)
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
                    epochs[stamps[text]][key] = _number(getattr(value, "value", value))
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


"""`ssa-fusion import tdm`'s reading: the measurements of a CCSDS TDM, streamed.

Of one station participant and one object participant: RANGE (km), ANGLE_1 / ANGLE_2
(azimuth / elevation, deg, ``AZEL``: the three at one epoch make one RANGE_AZ_EL
measurement) or ANGLE_1 / ANGLE_2 (right ascension / declination, deg, ``RADEC`` in
``GCRF``, ``ICRF`` or ``EME2000``: the two at one epoch make one RA_DEC measurement, in
GCRF); epochs in ``UTC``, ``TAI``, ``TT`` or ``GPS`` (converted to UTC stamps,
`timescales`). TDM carries no measurement noise: it is given per kind, else read from the
metadata comment `common.SIGMA_COMMENT` that `export tdm` writes, else the station's
sensor (a sites file's, `formats.sites`, or the built-in preset, `stations.SENSORS`).
Participants name built-in stations or those of a sites file (``--sites``).

A file of any size: `read_tdm` reads it as a stream (`tdm_reader.TdmReader`), keeps
each epoch's values only until its measurement is complete, and keeps the measurements
compactly (epoch, the TDM's values, the segment: ~100 bytes each with their sorting, 45 MB
for a 100 MB file), so that the bag can be written in epoch order, one message at a time
(`Imported.measurements`), after the whole file has been judged: an error on its last line
leaves no bag behind.
"""

from __future__ import annotations

import enum
import math
import re
import unicodedata
from array import array
from collections import Counter
from collections.abc import Callable, Iterable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TypeVar

import numpy as np
from numpy.typing import NDArray

from ssa_fusion.core.base import types
from ssa_fusion.core.base.quoting import quote, shown
from ssa_fusion.core.earth import timescales
from ssa_fusion.core.earth.stations import SENSORS, STATIONS, Sensor
from ssa_fusion.core.measure.validation import MAX_ID_CHARS, MAX_RANGE_KM, MIN_RANGE_KM
from ssa_fusion.formats.ccsds.common import (
    ANGLE_1,
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
    frame_bias,
    parse_epoch,
    rotate_radec,
)
from ssa_fusion.formats.ccsds.tdm_reader import Observation, SegmentMeta, TdmReader

PROGRESS_EVERY = 16384
"""Observations between two calls of `read_tdm`'s progress callback."""
_CHUNK = 8192
"""Measurements made Python objects at a time by `Imported.measurements`."""

_NUMBER = re.compile(r"[+-]?(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?|[+-]?(?:inf|infinity|nan)",
                     re.IGNORECASE | re.ASCII)
"""A value a TDM gives: a decimal number of ASCII digits (xsd:double's forms; ``NaN``,
``INF`` read as the non-finite values that are then left out and counted). Python's float()
also takes other scripts' digits (full-width ``１２３``): a TDM's are ASCII."""
_UNITS = {RANGE: "KM", "angle_1": "DEG", "angle_2": "DEG"}
"""The unit a data keyword read here may name (``[unit]``, ``units=``), in capitals."""


@dataclass(frozen=True)
class SegmentInfo:
    """What the measurements of one TDM segment share."""

    layout: Layout
    to_gcrf: Array | None
    """RADEC: the rotation of its REFERENCE_FRAME to GCRF (None: none needed)."""
    station: str
    object_id: str
    R: Array
    """Noise covariance of its measurements, core units (km, rad)."""


@dataclass
class Imported:
    r"""Measurements read from a TDM, and what was left out (counted, never silently).

    The measurements are held compactly (`t`, `values`, `segment`) and given one at a time
    by `measurements`, sorted by epoch.

    Attributes
    ----------
    segments : list of SegmentInfo
        The file's segments, in file order.
    t : ndarray (n,)
        UTC stamps of the measurements, in epoch order (the first of an epoch given twice
        in one segment kept).
    values : ndarray (n, 3)
        Their values in TDM units (km, deg; RADEC: the last column 0).
    segment : ndarray (n,) of int
        Index of each one's segment in `segments`.
    incomplete : int
        Epochs lacking one of their layout's keywords (`Layout.keywords`).
    invalid : int
        Epochs with a non-finite or impossible value (negative range, \|el\| or \|dec\|
        over 90 deg); `first_invalid` says the first one read.
    duplicate : int
        Epochs given twice in one segment (the first kept).
    unused : Counter
        Observations of keywords not read (e.g. DOPPLER_INSTANTANEOUS, RANGE in a RADEC
        segment), by keyword.
    """

    segments: list[SegmentInfo] = field(default_factory=list)
    t: NDArray[np.float64] = field(default_factory=lambda: np.zeros(0))
    values: NDArray[np.float64] = field(default_factory=lambda: np.zeros((0, 3)))
    segment: NDArray[np.int32] = field(default_factory=lambda: np.zeros(0, np.int32))
    incomplete: int = 0
    invalid: int = 0
    first_invalid: str = ""
    duplicate: int = 0
    unused: Counter[str] = field(default_factory=Counter)

    def __len__(self) -> int:
        """Return the number of measurements."""
        return len(self.t)

    def measurements(self) -> Iterator[types.Measurement]:
        """Yield the measurements in epoch order (core units: km, rad; RA/Dec in GCRF)."""
        for i in range(0, len(self.t), _CHUNK):  # Python floats for a chunk at a time
            yield from self._measurements(slice(i, i + _CHUNK))

    def _measurements(self, rows: slice) -> Iterator[types.Measurement]:
        """Yield the measurements of `rows`."""
        for t, v, k in zip(self.t[rows].tolist(), self.values[rows].tolist(),
                           self.segment[rows].tolist(), strict=True):
            s = self.segments[k]
            layout = s.layout
            z = layout.from_tdm_units(v[:len(layout.keywords)])
            if layout is AZEL:
                z[1] %= 2 * math.pi
            else:
                z = np.array(rotate_radec(float(z[0]), float(z[1]),
                                          np.eye(3) if s.to_gcrf is None else s.to_gcrf))
            yield types.Measurement(t=t, z=z, R=s.R.copy(), kind=layout.kind,
                                    source=types.Source.SENSOR, object_id=s.object_id,
                                    frame_id=s.station)

    def counts(self) -> Counter[int]:
        """Return the number of measurements by kind."""
        per_segment = np.bincount(self.segment, minlength=len(self.segments))
        out: Counter[int] = Counter()
        for s, n in zip(self.segments, per_segment.tolist(), strict=True):
            if n:
                out[int(s.layout.kind)] += n
        return out

    def used_segments(self) -> list[SegmentInfo]:
        """Return the segments that gave at least one measurement."""
        per_segment = np.bincount(self.segment, minlength=len(self.segments))
        return [s for s, n in zip(self.segments, per_segment.tolist(), strict=True) if n]

    def left_out(self) -> str:
        """Return what was left out, as a clause of the summary line ("" if nothing)."""
        parts = []
        if self.incomplete:
            parts.append(f"{self.incomplete} epoch(s) without all their keywords")
        if self.invalid:
            parts.append(f"{self.invalid} epoch(s) with invalid values (first: "
                         f"{self.first_invalid})")
        if self.duplicate:
            parts.append(f"{self.duplicate} epoch(s) given twice in a segment (the first "
                         f"kept)")
        if self.unused:
            unused = sorted(self.unused.items())
            more = f" and {len(unused) - 5} more keyword(s)" if len(unused) > 5 else ""
            parts.append("observations not used: " + ", ".join(
                f"{n} {k}" for k, n in unused[:5]) + more)
        return f"; left out: {'; '.join(parts)}" if parts else ""


_E = TypeVar("_E", bound=enum.StrEnum)


def _where(source: str, meta: SegmentMeta, keyword: str) -> str:
    """Return how an error names a segment's keyword: ``FILE:LINE: segment N``."""
    return f"{source}:{meta.line_of(keyword)}: segment {meta.number}"


def _choice(meta: SegmentMeta, key: str, allowed: Iterable[_E], source: str,
            default: _E | None = None) -> _E:
    """Return the metadata keyword `key` as one of `allowed` (its `default` if absent).

    CcsdsError (one line naming the file, line, segment and value) otherwise.
    """
    allowed = list(allowed)
    got = meta.get(key)
    if got is None and default is not None:
        return default
    for a in allowed:
        if got is not None and got.upper() == a.value:
            return a
    said = "missing" if got is None else f"= {shown(got.upper())} is not supported"
    raise CcsdsError(f"{_where(source, meta, key)}: {key} {said} (supported: "
                     f"{', '.join(a.value for a in allowed)})")


class _RangeUnits(enum.StrEnum):
    """``RANGE_UNITS`` the importer takes (TDM's default)."""

    KM = "KM"


def _segment_layout(meta: SegmentMeta, source: str) -> tuple[Layout, Array | None]:
    """Return the segment's layout (ANGLE_TYPE, RANGE_UNITS) and its RADEC frame's rotation.

    For RADEC, the rotation of its REFERENCE_FRAME to GCRF (None: none needed).
    """
    angle_type = _choice(meta, "ANGLE_TYPE", AngleType, source)
    if angle_type == AngleType.AZEL:
        _choice(meta, "RANGE_UNITS", _RangeUnits, source, default=_RangeUnits.KM)
        return AZEL, None
    ref = _choice(meta, "REFERENCE_FRAME", AngleFrame, source)
    return RADEC, (frame_bias().T if ref == AngleFrame.EME2000 else None)


def _participants(meta: SegmentMeta, source: str, sites: Mapping[str, Sensor]
                  ) -> tuple[str, str]:
    """Return (station id, object id) of a TDM segment.

    The one participant that is a known station (built in, or of `sites`; by its id in
    lowercase) and the one that is not.
    """
    keys = [k for i in range(1, 6) if meta.get(k := f"PARTICIPANT_{i}")]
    names = [meta.get(k) or "" for k in keys]
    known = {*STATIONS, *sites}
    stations = [p for p in names if p.lower() in known]
    others = [p for p in names if p.lower() not in known]
    if len(stations) != 1 or len(others) != 1:
        own = (f"; your sites: {shown(', '.join(sites), 120)}" if sites else
               "; a station of your own: --sites FILE (docs/SITES.md)")
        raise CcsdsError(
            f"{_where(source, meta, 'PARTICIPANT_1')}: participants "
            f"{', '.join(shown(p, 40) for p in names) or 'none'}: need one known station "
            f"({', '.join(sorted(STATIONS))}{own}) and one object")
    oid = others[0]
    if any(unicodedata.category(c) == "Cc" for c in oid):  # NUL, escape: stored and echoed
        key = keys[names.index(oid)]
        raise CcsdsError(f"{_where(source, meta, key)}: {key}: an object id with control "
                         f"characters (NUL, escape, ...): {quote(oid)}")
    if len(oid) > MAX_ID_CHARS:  # every measurement of it would be refused (`validation`)
        key = keys[names.index(oid)]
        raise CcsdsError(f"{_where(source, meta, key)}: {key}: an object id of {len(oid)} "
                         f"characters (at most {MAX_ID_CHARS}): {quote(oid)}")
    return stations[0].lower(), oid


def _check_path(meta: SegmentMeta, layout: Layout, source: str) -> None:
    """Refuse a ``PATH`` that is not what the segment's measurements are.

    RANGE of an AZEL segment is a round trip (``PATH = 1,2,1``: from a participant and back
    to it); a one-way path (``1,2``) would be a different measurement (a one-way range,
    half the light time) imported as a two-way one. Angles (RADEC) take any path.
    """
    path = meta.get("PATH")
    if path is None or layout is not AZEL:
        return
    legs = [p.strip() for p in path.split(",")]
    if not (len(legs) == 3 and legs[0] == legs[2] and legs[0] != legs[1]
            and all(p.isascii() and p.isdigit() for p in legs)):
        raise CcsdsError(f"{_where(source, meta, 'PATH')}: PATH = {shown(path)}: RANGE is "
                         f"imported as a two-way (round-trip) range: PATH = 1,2,1 (or 2,1,2)")


def _time_span(meta: SegmentMeta, time_system: TimeSystem, source: str
               ) -> tuple[float, float]:
    """Return the segment's ``START_TIME`` .. ``STOP_TIME`` (UTC stamps; +-inf if absent)."""
    span = []
    for key, default in (("START_TIME", -math.inf), ("STOP_TIME", math.inf)):
        text = meta.get(key)
        try:
            span.append(default if text is None else parse_epoch(text, time_system))
        except CcsdsError as exc:
            raise CcsdsError(f"{_where(source, meta, key)}: {key}: {exc}") from None
    if span[0] > span[1]:
        raise CcsdsError(f"{_where(source, meta, 'STOP_TIME')}: STOP_TIME is before "
                         f"START_TIME")
    return span[0], span[1]


def _segment_sigma(meta: SegmentMeta, station: str, layout: Layout,
                   sigma: Sequence[float] | None, source: str,
                   sites: Mapping[str, Sensor]) -> Array:
    """Return the noise of a segment's measurements in core units (km, rad).

    `sigma` (TDM units), else the segment's `SIGMA_COMMENT`, else the station's sensor
    (of `sites`, else its built-in preset) if it measures that kind.
    """
    want = " ".join(layout.sigma_names)
    where = f"{source}:{meta.line}: segment {meta.number}"
    if sigma is None:
        for text, line in meta.comments:
            if text.startswith(SIGMA_COMMENT):
                try:
                    sigma = [float(v) for v in text[len(SIGMA_COMMENT):].split()]
                except ValueError:
                    sigma = []
                if len(sigma) != len(layout.sigma_names):
                    raise CcsdsError(f"{source}:{line}: segment {meta.number}: malformed "
                                     f"comment {quote(text)} (want '{SIGMA_COMMENT} {want}' "
                                     f"for {layout.angle_type})")
                where = f"{source}:{line}: segment {meta.number}: comment"
    if sigma is None:
        preset = sites.get(station) or SENSORS.get(station)
        if preset is None or preset.kind != layout.kind:
            raise CcsdsError(f"{where}: no noise for {layout.angle_type} measurements of "
                             f"station {station}: give {layout.option} {want}")
        return np.asarray(preset.sigma, dtype=float)
    if len(sigma) != len(layout.sigma_names) or not all(
            math.isfinite(s) and s > 0 for s in sigma):
        raise CcsdsError(f"{where}: noise must be {want}, finite and > 0, got "
                         f"{quote(list(sigma))}")
    return layout.from_tdm_units(sigma)


MAX_ANGLE_DEG = 1e6
"""Largest ANGLE_1 (azimuth, right ascension) taken, deg: it is wrapped into [0, 360),
which keeps 2e-10 deg at 1e6 and nothing at 1e308."""


def _why_invalid(layout: Layout, v: Sequence[float]) -> str:
    """Why channel values in TDM units (km, deg) are not a measurement ("" if they are)."""
    names = dict(zip(layout.keywords, v, strict=True))
    if not all(math.isfinite(x) for x in v):
        return "non-finite " + ", ".join(k.upper() for k, x in names.items()
                                         if not math.isfinite(x))
    if layout is AZEL and names[RANGE] < 0:
        return f"negative RANGE {names[RANGE]!r} km"
    if layout is AZEL and not MIN_RANGE_KM <= names[RANGE] <= MAX_RANGE_KM:
        # what every consumer refuses (`validation`): nothing in orbit is within 1 km of
        # its sensor, nothing tracked beyond 1e7 km
        return f"RANGE {names[RANGE]!r} km outside [{MIN_RANGE_KM:g}, {MAX_RANGE_KM:g}]"
    if abs(names[ANGLE_1]) > MAX_ANGLE_DEG:
        return f"ANGLE_1 {names[ANGLE_1]!r} deg beyond +-{MAX_ANGLE_DEG:g} (wrapping it " \
               "into a circle would keep only round-off)"
    if abs(names[ANGLE_2]) > 90.0:
        return f"ANGLE_2 ({'elevation' if layout is AZEL else 'declination'}) " \
               f"{names[ANGLE_2]!r} deg beyond +-90"
    return ""


class _Reading:
    """The state of `read_tdm`: the segment being read and the measurements so far."""

    def __init__(self, source: str, sigma: Mapping[types.Kind, Sequence[float]],
                 sites: Mapping[str, Sensor]) -> None:
        self.source, self.sigma, self.sites = source, sigma, sites
        self.out = Imported()
        self.t, self.seg = array("d"), array("i")
        self.v: tuple[array[float], array[float], array[float]] = (
            array("d"), array("d"), array("d"))
        self.meta: SegmentMeta | None = None
        self.layout = AZEL
        self.time_system = TimeSystem.UTC
        self.channel: dict[str, int] = {}
        self.pending: dict[float, list[float | None]] = {}
        self.epoch_text = ""
        self.stamp = 0.0
        self.span = (-math.inf, math.inf)

    def start(self, meta: SegmentMeta) -> None:
        """Begin a segment: judge its metadata (CcsdsError naming what is not supported)."""
        self.end()
        src = self.source
        self.time_system = _choice(meta, "TIME_SYSTEM", TimeSystem, src)
        self.layout, to_gcrf = _segment_layout(meta, src)
        _check_path(meta, self.layout, src)
        self.span = _time_span(meta, self.time_system, src)
        station, oid = _participants(meta, src, self.sites)
        R = np.diag(_segment_sigma(meta, station, self.layout,
                                   self.sigma.get(self.layout.kind), src, self.sites)**2)
        self.out.segments.append(SegmentInfo(self.layout, to_gcrf, station, oid, R))
        self.meta = meta
        self.channel = {k.upper(): i for i, k in enumerate(self.layout.keywords)}
        self.epoch_text = ""

    def end(self) -> None:
        """End the segment being read: its epochs still lacking a keyword are incomplete."""
        self.out.incomplete += len(self.pending)
        self.pending = {}

    def fail(self, ob: Observation, field: str, why: str) -> CcsdsError:
        """Return the one-line error of `field` of observation `ob`."""
        assert self.meta is not None
        return CcsdsError(f"{self.source}:{ob.line}: segment {self.meta.number}: {field}: {why}")

    def epoch(self, ob: Observation) -> float:
        """Return the UTC stamp of `ob`'s epoch (parsed once for a run of the same text)."""
        if ob.epoch == self.epoch_text:
            return self.stamp
        try:
            t = parse_epoch(ob.epoch, self.time_system)
        except CcsdsError as exc:
            raise self.fail(ob, "EPOCH", str(exc)) from None
        if not timescales.EPOCH_MIN <= t <= timescales.EPOCH_MAX:
            try:
                timescales.check_epochs([t], "epoch")
            except ValueError as exc:
                raise self.fail(ob, "EPOCH", str(exc)) from None
        if not self.span[0] <= t <= self.span[1]:
            raise self.fail(ob, "EPOCH", f"{ob.epoch} is outside the segment's START_TIME .. "
                                         f"STOP_TIME ({timescales.iso(self.span[0])} .. "
                                         f"{timescales.iso(self.span[1])})")
        self.epoch_text, self.stamp = ob.epoch, t
        return t

    def add(self, ob: Observation) -> None:
        """Take one observation of the segment being read."""
        if self.meta is None:
            raise CcsdsError(f"{self.source}:{ob.line}: an observation outside a segment")
        t = self.epoch(ob)
        i = self.channel.get(ob.keyword)
        if i is None:
            self.out.unused[ob.keyword] += 1
            return
        if not _NUMBER.fullmatch(ob.value):
            raise self.fail(ob, ob.keyword, f"{quote(ob.value)} is not a number")
        if ob.unit and ob.unit.upper() != _UNITS[self.layout.keywords[i]]:
            raise self.fail(ob, ob.keyword, f"unit {quote(ob.unit)}: this reader takes "
                                            f"{_UNITS[self.layout.keywords[i]].lower()}")
        rec = self.pending.get(t)
        if rec is None:
            rec = self.pending[t] = [None] * len(self.channel)
        rec[i] = float(ob.value)
        if None in rec:
            return
        del self.pending[t]
        v = [x for x in rec if x is not None]
        why = _why_invalid(self.layout, v)
        if why:
            self.out.invalid += 1
            if not self.out.first_invalid:
                assert self.meta is not None
                self.out.first_invalid = (f"{self.source}:{ob.line}: segment "
                                          f"{self.meta.number}, {shown(ob.epoch)} "
                                          f"{self.time_system}: {why}")
            return
        self.t.append(t)
        for col, x in zip(self.v, (*v, 0.0, 0.0), strict=False):
            col.append(x)
        self.seg.append(len(self.out.segments) - 1)

    def __len__(self) -> int:
        """Return the number of measurements so far."""
        return len(self.t)

    def result(self) -> Imported:
        """Return the measurements read, sorted by epoch, an epoch twice in a segment once."""
        self.end()
        out = self.out
        t = np.frombuffer(self.t, dtype=float) if len(self.t) else np.zeros(0)
        seg = np.frombuffer(self.seg, dtype=np.int32) if len(self.seg) else \
            np.zeros(0, np.int32)
        order = np.argsort(t, kind="stable")  # ties in file order: a segment's together
        t, seg = t[order], seg[order]
        keep = np.ones(len(t), dtype=bool)
        keep[1:] = (t[1:] != t[:-1]) | (seg[1:] != seg[:-1])
        out.duplicate = int(np.count_nonzero(~keep))
        order = order[keep]
        out.t, out.segment = t[keep], seg[keep]
        out.values = np.column_stack([np.frombuffer(c, dtype=float)[order] if len(c) else
                                      np.zeros(0) for c in self.v]).reshape(-1, 3)
        return out


def read_tdm(path: Path | str, sigma: Mapping[types.Kind, Sequence[float]] | None = None,
             sites: Mapping[str, Sensor] | None = None,
             progress: Callable[[int, int, int], None] | None = None) -> Imported:
    """Return the RANGE_AZ_EL (km, rad) and RA_DEC (rad, GCRF) measurements of a TDM file.

    The file (KVN or XML) is read as a stream (module docstring); `progress(bytes read,
    file size, measurements so far)` is called every `PROGRESS_EVERY` observations and at
    the end.

    `sigma`: noise by measurement kind in TDM units (range km, azimuth deg, elevation deg;
    ra deg, dec deg) for every segment of that kind, else each segment's ``ssa_fusion
    sigma:`` comment, else its station's sensor. `sites`: stations of one's own by id
    (`formats.sites.load_sites`), which participants may name besides the built-in
    stations. CcsdsError (one bounded line naming the file, the line, the segment and the
    keyword) for a file that is not a TDM (`tdm_reader`), a value that is not a number
    or an epoch, and what this importer does not support: time systems other than UTC,
    TAI, TT, GPS; angle types other than AZEL and RADEC; RADEC in frames other than GCRF,
    ICRF, EME2000; range units other than km; unknown stations; epochs outside
    `timescales.EPOCH_MIN` .. `EPOCH_MAX`. Epochs lacking a keyword, with non-finite or
    impossible values, given twice in a segment, and observations of other keywords are
    left out and counted (`Imported`); a file with no measurement left is refused.
    """
    source = str(path)
    reader = TdmReader(path)
    state = _Reading(source, sigma or {}, sites or {})
    n = 0
    for item in reader:
        if type(item) is Observation:
            state.add(item)
            n += 1
            if progress is not None and n % PROGRESS_EVERY == 0:
                progress(reader.bytes_read, reader.size, len(state))
        else:
            assert isinstance(item, SegmentMeta)
            state.start(item)
    if progress is not None:
        progress(reader.bytes_read, reader.size, len(state))
    out = state.result()
    if not len(out):
        raise CcsdsError(f"{source}: no usable epoch (need RANGE, ANGLE_1 and ANGLE_2 for "
                         f"AZEL, ANGLE_1 and ANGLE_2 for RADEC){out.left_out()}")
    return out

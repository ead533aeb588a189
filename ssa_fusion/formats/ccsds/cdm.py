"""CCSDS Conjunction Data Messages (CDM, 508.0-B-1): read one (KVN or XML), for its Pc.

`read_cdm` returns a `Cdm`: TCA, miss distance, relative speed, the message's own Pc and its
method, the hard-body radius, and per object its state and RTN covariance, in the core's
units (km, km/s, km², km²/s, km²/s²; TCA as Unix seconds, UTC). `Cdm.inputs` gives what
`core.conjunction.collision_probability` takes: GCRF states and inertial covariances.
Writing a CDM: `cdm_out`.

What it checks, each a `CcsdsError` of one line naming the file, the line and the keyword:

* the file: at most `MAX_BYTES`, UTF-8, a KVN line at most `MAX_LINE` bytes, XML well formed
  (no DTD, entity or network access); ``CCSDS_CDM_VERS`` (KVN) or a ``<cdm>`` root (XML);
  exactly two objects, ``OBJECT1`` and ``OBJECT2``;
* every value the Pc needs: present (the covariance may be missing, wholly: the Pc is then
  an upper bound), a finite number, in its unit (``[km]``, ``[km/s]``, ``[m**2]``,
  ``[m**2/s]``, ``[m**2/s**2]``, ``[m]``, ``[m/s]``: `UNITS`; a value without a unit is in
  the standard's); variances not negative; ``REF_FRAME`` one the core can rotate
  (`FRAMES`); ``TCA`` a CCSDS epoch (UTC);
* the hard-body radius: the ``HBR`` keyword (CDM 2.0) or CARA's ``COMMENT HBR = 10 [m]``,
  in the relative metadata or an object's; a message without one is read (``hbr_km`` None).

The other keywords are kept as text (`CdmObject.fields`), not judged.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import NoReturn

import numpy as np
from numpy.typing import NDArray

from ssa_fusion.core.base.quoting import cut, one_line, quote
from ssa_fusion.core.conjunction.encounter import rtn_to_inertial
from ssa_fusion.core.earth import frames
from ssa_fusion.formats.ccsds.common import CcsdsError, frame_bias, parse_epoch

Array = NDArray[np.float64]

__all__ = ["COV_KEYWORDS", "FRAMES", "MAX_BYTES", "MAX_LINE", "UNITS", "Cdm", "CdmObject",
           "parse_cdm", "read_cdm"]

MAX_BYTES = 1_000_000
"""Largest CDM read, bytes (a CDM is about 10 kB)."""
MAX_LINE = 4096
"""Longest KVN line, bytes."""
STATE_KEYWORDS = ("X", "Y", "Z", "X_DOT", "Y_DOT", "Z_DOT")
"""The state vector's keywords, in order (km, km/s)."""
_AXES = ("R", "T", "N", "RDOT", "TDOT", "NDOT")
COV_KEYWORDS = tuple(f"C{_AXES[i]}_{_AXES[j]}" for i in range(6) for j in range(i + 1))
"""The 21 keywords of the 6x6 RTN covariance's lower triangle (CR_R, CT_R, CT_T, ...)."""
_COV_INDEX = {f"C{_AXES[i]}_{_AXES[j]}": (i, j) for i in range(6) for j in range(i + 1)}
UNITS: dict[str, tuple[str, float]] = {
    **{k: ("km", 1.0) for k in STATE_KEYWORDS[:3]},
    **{k: ("km/s", 1.0) for k in STATE_KEYWORDS[3:]},
    **{k: ("m**2" if i < 3 and j < 3 else "m**2/s" if j < 3 else "m**2/s**2",
           1e-6) for k, (i, j) in _COV_INDEX.items()},
    "MISS_DISTANCE": ("m", 1e-3), "RELATIVE_SPEED": ("m/s", 1e-3), "HBR": ("m", 1e-3)}
"""Per keyword read as a number: its CDM unit and the factor to the core's (km, km/s, km²)."""
FRAMES = ("EME2000", "GCRF", "ICRF", "ITRF", "TEME")
"""``REF_FRAME`` values read (rotated to GCRF at TCA)."""
_HBR_COMMENT = re.compile(r"^HBR\s*[=:]?\s*(\S+)\s*(?:\[([^\]]*)\])?\s*$", re.IGNORECASE)
_KVN = re.compile(r"^([A-Z0-9_]+)\s*=\s*(.*?)\s*(?:\[([^\]]*)\])?\s*$")


@dataclass
class _Section:
    """Keywords of one part of a CDM: value text, unit text (or None) and line."""

    values: dict[str, tuple[str, str | None, int]] = field(default_factory=dict)
    comments: list[tuple[str, int]] = field(default_factory=list)


@dataclass(frozen=True)
class CdmObject:
    """One object of a CDM.

    Attributes
    ----------
    name : str
        ``OBJECT`` (OBJECT1 or OBJECT2).
    designator, object_name : str
        ``OBJECT_DESIGNATOR`` and ``OBJECT_NAME`` ("" when absent).
    ref_frame : str
        ``REF_FRAME`` of the state.
    state : ndarray (6,)
        State at TCA in `ref_frame`, km, km/s.
    cov_rtn : ndarray (6, 6) or None
        Covariance in the object's RTN frame, km², km²/s, km²/s² (None: missing).
    fields : dict
        Every keyword of the object as text.
    """

    name: str
    designator: str
    object_name: str
    ref_frame: str
    state: Array
    cov_rtn: Array | None
    fields: dict[str, str]


@dataclass(frozen=True)
class Cdm:
    """A CDM as the Pc needs it (module docstring).

    Attributes
    ----------
    path : str
        The file read ("" for text).
    format : str
        ``kvn`` or ``xml``.
    message_id, originator, creation_date : str
        From the header ("" when absent).
    tca : float
        Time of closest approach, Unix seconds (UTC).
    tca_text : str
        ``TCA`` as written.
    miss_km, relative_speed_km_s : float or None
        ``MISS_DISTANCE`` and ``RELATIVE_SPEED``.
    pc, pc_method : float or None, str
        ``COLLISION_PROBABILITY`` and ``COLLISION_PROBABILITY_METHOD`` ("" when absent).
    hbr_km : float or None
        Combined hard-body radius (module docstring).
    objects : tuple of CdmObject
        OBJECT1, OBJECT2.
    """

    path: str
    format: str
    message_id: str
    originator: str
    creation_date: str
    tca: float
    tca_text: str
    miss_km: float | None
    relative_speed_km_s: float | None
    pc: float | None
    pc_method: str
    hbr_km: float | None
    objects: tuple[CdmObject, CdmObject]

    def inputs(self) -> tuple[Array, Array | None, Array, Array | None]:
        """Return (x1, p1, x2, p2): GCRF states (6,), km, km/s, and inertial covariances (6, 6).

        A missing covariance is None.
        """
        out: list[Array | None] = []
        for obj in self.objects:
            x = _to_gcrf(obj.state, obj.ref_frame, self.tca)
            out += [x, None if obj.cov_rtn is None else rtn_to_inertial(x, obj.cov_rtn)[0]]
        x1, p1, x2, p2 = out
        assert x1 is not None and x2 is not None
        return x1, p1, x2, p2


def _to_gcrf(x: Array, frame: str, t: float) -> Array:
    """Rotate a state (6,) in `frame` at Unix time t to GCRF, km, km/s."""
    if frame == "EME2000":
        rb = frame_bias().T
        return np.concatenate([rb @ x[:3], rb @ x[3:]])
    if frame == "ITRF":
        out: Array = frames.itrs_to_gcrs(x, t)
        return out
    if frame == "TEME":
        teme: Array = frames.teme_to_gcrs(x, t)
        return teme
    return x.copy()


class _Reader:
    """One CDM's text, split into header+relative metadata and the two objects."""

    def __init__(self, where: str) -> None:
        self.where = where
        self.top = _Section()
        self.objects: list[_Section] = []

    def fail(self, line: int, what: str) -> NoReturn:
        """Raise the one-line `CcsdsError` of `what` at `line` (0: of the whole message)."""
        raise CcsdsError(f"{self.where}:{line}: {what}" if line > 0 else f"{self.where}: {what}")

    def section_for(self, key: str, n: int) -> _Section:
        """Return the section a keyword goes to; ``OBJECT`` opens a new one."""
        if key == "OBJECT":
            if len(self.objects) == 2:
                self.fail(n, "a third OBJECT: a CDM has two")
            self.objects.append(_Section())
        return self.objects[-1] if self.objects else self.top

    def put(self, key: str, value: str, unit: str | None, n: int) -> None:
        """Store one keyword (each at most once per section)."""
        sec = self.section_for(key, n)
        if key in sec.values:
            self.fail(n, f"{key} given twice")
        sec.values[key] = (value, unit, n)

    def kvn(self, text: str) -> None:
        """Split a KVN CDM."""
        for n, raw in enumerate(text.splitlines(), 1):
            if len(raw.encode()) > MAX_LINE:
                self.fail(n, f"line longer than {MAX_LINE} bytes: not a CDM's")
            s = raw.strip()
            if not s:
                continue
            if s.startswith("COMMENT"):
                sec = self.objects[-1] if self.objects else self.top
                sec.comments.append((s[7:].strip(), n))
                continue
            m = _KVN.match(s)
            if m is None:
                self.fail(n, f"not a KEYWORD = value line: {quote(s)}")
            if not self.top.values and m.group(1) != "CCSDS_CDM_VERS":
                self.fail(n, f"starts with {cut(m.group(1))}, not CCSDS_CDM_VERS: not a "
                             f"CCSDS CDM (KVN)")
            self.put(m.group(1), m.group(2), m.group(3), n)

    def xml(self, data: bytes) -> None:
        """Split an XML CDM (``<cdm>``, alone or in an ``<ndm>``)."""
        from lxml import etree

        parser = etree.XMLParser(resolve_entities=False, no_network=True, load_dtd=False,
                                 huge_tree=False, remove_comments=True, remove_pis=True)
        try:
            root = etree.fromstring(data, parser)
        except etree.XMLSyntaxError as exc:
            self.fail(exc.lineno or 0, f"not well-formed XML: {one_line(exc.msg or exc, 200)}")
        cdm = root if _local(root.tag) == "cdm" else next(
            (e for e in root.iter() if _local(e.tag) == "cdm"), None)
        if cdm is None:
            self.fail(_line(root), f"not a CDM (its root element is "
                                            f"<{cut(_local(root.tag))}>)")
        self.put("CCSDS_CDM_VERS", str(cdm.get("version", "")), None, _line(cdm))
        for elem in cdm.iter():
            tag = _local(elem.tag)
            if len(elem) or not isinstance(elem.tag, str):
                continue
            n, text = _line(elem), (elem.text or "").strip()
            if tag == "COMMENT":
                (self.objects[-1] if self.objects else self.top).comments.append((text, n))
            else:
                self.put(tag, text, elem.get("units"), n)


def _line(elem: object) -> int:
    """Return the source line of an lxml element (0 when unknown)."""
    n = getattr(elem, "sourceline", None)
    return n if isinstance(n, int) else 0


def _local(tag: object) -> str:
    """Return an XML tag without its namespace."""
    return str(tag).rpartition("}")[2]


def _number(r: _Reader, sec: _Section, key: str, *, required: bool = True) -> float | None:
    """Return the keyword's value in core units, checked (module docstring)."""
    if key not in sec.values:
        if required:
            r.fail(0, f"no {key}: the Pc needs it")
        return None
    text, unit, n = sec.values[key]
    try:
        value = float(text)
    except ValueError:
        r.fail(n, f"{key} = {quote(text)}: not a number")
    if not math.isfinite(value):
        r.fail(n, f"{key} = {quote(text)}: not a finite number")
    want, factor = UNITS.get(key, ("", 1.0))
    if unit is not None and unit.strip() != want:
        r.fail(n, f"{key} in [{cut(unit)}], not [{want}]")
    return value * factor


def _covariance(r: _Reader, sec: _Section) -> Array | None:
    """Return the object's 6x6 RTN covariance, km² ... (None when none of its keywords is)."""
    present = [k for k in COV_KEYWORDS if k in sec.values]
    if not present:
        return None
    missing = [k for k in COV_KEYWORDS if k not in sec.values]
    if missing:
        r.fail(0, f"covariance incomplete: no {', '.join(missing[:4])}"
                  f"{' ...' if len(missing) > 4 else ''} (a CDM has all 21 or none)")
    c = np.zeros((6, 6))
    for k, (i, j) in _COV_INDEX.items():
        v = _number(r, sec, k)
        assert v is not None
        c[i, j] = c[j, i] = v
        if i == j and v < 0:
            r.fail(sec.values[k][2], f"{k} = {quote(sec.values[k][0])} < 0: not a variance")
    return c


def _object(r: _Reader, sec: _Section, expected: str) -> CdmObject:
    """Return one object, checked."""
    name = sec.values["OBJECT"][0].upper()
    if name != expected:
        r.fail(sec.values["OBJECT"][2], f"OBJECT = {quote(name)} where {expected} is due")
    frame = sec.values.get("REF_FRAME", ("", None, 0))
    if frame[0].upper() not in FRAMES:
        r.fail(frame[2], f"{name}: REF_FRAME = {quote(frame[0])}: not one of "
                         f"{', '.join(FRAMES)}")
    state = np.array([_number(r, sec, k) for k in STATE_KEYWORDS], dtype=float)
    if np.linalg.norm(state[:3]) == 0:
        r.fail(sec.values["X"][2], f"{name}: position (0, 0, 0): not an orbit")
    return CdmObject(name, sec.values.get("OBJECT_DESIGNATOR", ("",))[0],
                     sec.values.get("OBJECT_NAME", ("",))[0], frame[0].upper(), state,
                     _covariance(r, sec), {k: v[0] for k, v in sec.values.items()})


def _hbr(r: _Reader) -> float | None:
    """Return the hard-body radius, km, from HBR or CARA's comment (module docstring)."""
    for sec in (r.top, *r.objects):
        if "HBR" in sec.values:
            return _number(r, sec, "HBR")
    for sec in (r.top, *r.objects):
        for text, n in sec.comments:
            m = _HBR_COMMENT.match(text)
            if m is not None:
                fake = _Section({"HBR": (m.group(1), m.group(2), n)})
                value = _number(r, fake, "HBR")
                if value is None or value <= 0:
                    r.fail(n, f"HBR = {quote(m.group(1))}: not a positive radius")
                return value
    return None


def _pc(r: _Reader) -> float | None:
    """Return COLLISION_PROBABILITY, checked to be in [0, 1] (None when absent)."""
    if "COLLISION_PROBABILITY" not in r.top.values:
        return None
    text, _, n = r.top.values["COLLISION_PROBABILITY"]
    try:
        value = float(text)
    except ValueError:
        r.fail(n, f"COLLISION_PROBABILITY = {quote(text)}: not a number")
    if not 0.0 <= value <= 1.0:
        r.fail(n, f"COLLISION_PROBABILITY = {quote(text)}: not a probability")
    return value


def parse_cdm(data: bytes, where: str = "<text>") -> Cdm:
    """Read a CDM's bytes (KVN or XML, told from the content; module docstring).

    Parameters
    ----------
    data : bytes
        The message.
    where : str
        How errors name it (the file's path).

    Returns
    -------
    Cdm

    Raises
    ------
    CcsdsError
        One line saying why it cannot be read.
    """
    r = _Reader(where)
    if len(data) > MAX_BYTES:
        r.fail(0, f"{len(data)} bytes: larger than a CDM ({MAX_BYTES} at most)")
    head = data.removeprefix(b"\xef\xbb\xbf").lstrip()
    if not head:
        r.fail(0, "empty: not a CCSDS CDM")
    fmt = "xml" if head.startswith(b"<") else "kvn"
    if fmt == "xml":
        r.xml(head)
    else:
        try:
            text = head.decode("utf-8")
        except UnicodeDecodeError as exc:
            r.fail(0, f"not UTF-8 text (byte {exc.start + 1})")
        r.kvn(text)
    if len(r.objects) != 2:
        r.fail(0, f"{len(r.objects)} OBJECT section(s): a CDM has two")
    objs = (_object(r, r.objects[0], "OBJECT1"), _object(r, r.objects[1], "OBJECT2"))
    top = r.top.values
    if "TCA" not in top:
        r.fail(0, "no TCA: not a CDM")
    try:
        tca = parse_epoch(top["TCA"][0])
    except CcsdsError as exc:
        r.fail(top["TCA"][2], f"TCA: {exc}")
    return Cdm(where, fmt, top.get("MESSAGE_ID", ("",))[0], top.get("ORIGINATOR", ("",))[0],
               top.get("CREATION_DATE", ("",))[0], tca, top["TCA"][0],
               _number(r, r.top, "MISS_DISTANCE", required=False),
               _number(r, r.top, "RELATIVE_SPEED", required=False), _pc(r),
               top.get("COLLISION_PROBABILITY_METHOD", ("",))[0], _hbr(r), objs)


def read_cdm(path: Path | str) -> Cdm:
    """Read a CDM file (KVN or XML; module docstring); CcsdsError of one line if it cannot be."""
    p = Path(path)
    try:
        with p.open("rb") as f:
            data = f.read(MAX_BYTES + 1)
    except OSError as exc:
        raise CcsdsError(f"{p}: cannot read: {exc.strerror or one_line(exc)}") from None
    return parse_cdm(data, str(p))

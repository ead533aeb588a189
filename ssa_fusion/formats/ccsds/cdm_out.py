"""Writing a CDM (CCSDS 508.0-B-1, KVN or XML) for one of the project's own conjunctions.

`write_cdm` takes a `Conjunction`: both objects' GCRF states and inertial covariances at
TCA, the hard-body radius and the `PcResult` computed from them, and writes the message
`cdm.read_cdm` (and ccsds-ndm) reads back: states in ``EME2000`` (rotated by the IAU 2006
frame bias, as CARA's CDMs) or ``GCRF``, covariances in each object's RTN frame (m², m²/s,
m²/s²), the relative state in object 1's RTN frame, the Pc with its method, the hard-body
radius as CARA writes it (``COMMENT HBR = 10 [m]``; CDM 1.0 has no keyword for it) and the
Pc's warnings as a comment. A missing covariance is left out (CDM 1.0 asks for one; the
message is then read with the maximum-Pc methods).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from ssa_fusion.core.conjunction.encounter import inertial_to_rtn, relative_state_rtn
from ssa_fusion.core.conjunction.result import PcResult
from ssa_fusion.formats.ccsds.cdm import COV_KEYWORDS, STATE_KEYWORDS, UNITS
from ssa_fusion.formats.ccsds.common import (
    ORIGINATOR,
    CcsdsError,
    creation_date,
    format_epoch,
    frame_bias,
)

Array = NDArray[np.float64]

__all__ = ["WARNINGS_COMMENT", "Conjunction", "cdm_text", "write_cdm"]

WARNINGS_COMMENT = "ssa_fusion Pc warnings:"
"""Start of the relative metadata comment listing the Pc's warnings (`PcWarning` values)."""
CDM_FRAMES = ("EME2000", "GCRF")
"""``REF_FRAME`` values written."""

Item = tuple[str, "str | list[Item]", str | None]
"""A keyword, its value (text, or the items of an XML group) and its unit (or None)."""


@dataclass(frozen=True)
class Conjunction:
    """One of the project's conjunctions, as a CDM carries it.

    Attributes
    ----------
    tca : float
        Time of closest approach, Unix seconds (UTC).
    x1, x2 : ndarray (6,)
        GCRF states of objects 1 and 2 at TCA, km, km/s.
    p1, p2 : ndarray (6, 6) or None
        Their inertial (GCRF) covariances, km², km²/s, km²/s² (None: missing).
    hbr_km : float
        Combined hard-body radius, km.
    result : PcResult
        The Pc computed from them.
    ids : tuple of str
        ``OBJECT_DESIGNATOR`` of objects 1 and 2 (the catalog's ids).
    names : tuple of str
        ``OBJECT_NAME`` of objects 1 and 2.
    message_id : str
        ``MESSAGE_ID`` ("" for one made of the ids and TCA).
    """

    tca: float
    x1: Array
    x2: Array
    p1: Array | None
    p2: Array | None
    hbr_km: float
    result: PcResult
    ids: tuple[str, str] = ("1", "2")
    names: tuple[str, str] = ("UNKNOWN", "UNKNOWN")
    message_id: str = ""


def _num(v: float) -> str:
    """Return a number as written in the message (17 significant digits: exact)."""
    return f"{v:.17g}"


def _epoch(t: float) -> str:
    """Return a Unix time as a CCSDS epoch to the microsecond (what a float holds there)."""
    sec = int(np.floor(t))
    us = round((t - sec) * 1e6)
    sec, us = sec + us // 1_000_000, us % 1_000_000
    return f"{format_epoch(float(sec))[:19]}.{us:06d}"


def _relative(c: Conjunction) -> list[Item]:
    """Return the relative metadata/data items."""
    rel = relative_state_rtn(c.x1, c.x2)[0] * 1e3
    res = c.result
    items: list[Item] = [("TCA", _epoch(c.tca), None),
                         ("MISS_DISTANCE", _num(float(np.linalg.norm(rel[:3]))), "m"),
                         ("RELATIVE_SPEED", _num(float(np.linalg.norm(rel[3:]))), "m/s"),
                         ("relativeStateVector", [
                             (f"RELATIVE_{q}_{a}", _num(float(v)), u)
                             for (q, u), vs in ((("POSITION", "m"), rel[:3]),
                                                (("VELOCITY", "m/s"), rel[3:]))
                             for a, v in zip("RTN", vs, strict=True)], None)]
    if np.isfinite(res.pc):
        items += [("COLLISION_PROBABILITY", f"{res.pc:.6e}", None),
                  ("COLLISION_PROBABILITY_METHOD", res.method.value, None)]
    comments: list[Item] = [("COMMENT", f"HBR = {_num(c.hbr_km * 1e3)} [m]", None),
                            ("COMMENT", f"log10 Pc = {res.log10_pc:.6f}", None)]
    if res.warnings:
        comments.append(("COMMENT", f"{WARNINGS_COMMENT} "
                                    f"{' '.join(sorted(w.value for w in res.warnings))}", None))
    return comments + items


def _object(c: Conjunction, k: int, frame: str) -> list[Item]:
    """Return the segment of object k (0 or 1): metadata and data groups."""
    x, p = (c.x1, c.p1) if k == 0 else (c.x2, c.p2)
    rot = frame_bias() if frame == "EME2000" else np.eye(3)
    xs = np.concatenate([rot @ x[:3], rot @ x[3:]])
    meta: list[Item] = [("OBJECT", f"OBJECT{k + 1}", None),
                        ("OBJECT_DESIGNATOR", c.ids[k], None), ("CATALOG_NAME", "SSA_FUSION", None),
                        ("OBJECT_NAME", c.names[k], None),
                        ("INTERNATIONAL_DESIGNATOR", "UNKNOWN", None),
                        ("EPHEMERIS_NAME", "NONE", None),
                        ("COVARIANCE_METHOD", "CALCULATED", None),
                        ("MANEUVERABLE", "N/A", None), ("REF_FRAME", frame, None)]
    state: list[Item] = [(kw, _num(float(v)), UNITS[kw][0])
                         for kw, v in zip(STATE_KEYWORDS, xs, strict=True)]
    data: list[Item] = [("stateVector", state, None)]
    if p is not None:
        rtn = inertial_to_rtn(x, p)[0] * 1e6
        idx = [(i, j) for i in range(6) for j in range(i + 1)]
        data.append(("covarianceMatrix", [(kw, _num(float(rtn[i, j])), UNITS[kw][0])
                                          for kw, (i, j) in zip(COV_KEYWORDS, idx,
                                                                strict=True)], None))
    return [("metadata", meta, None), ("data", data, None)]


def _message(c: Conjunction, frame: str) -> list[Item]:
    """Return the whole message as items: header, relative metadata, two segments."""
    if frame not in CDM_FRAMES:
        raise CcsdsError(f"REF_FRAME {frame!r}: a CDM is written in {', '.join(CDM_FRAMES)}")
    mid = c.message_id or f"{c.ids[0]}_conj_{c.ids[1]}_{_epoch(c.tca)[:19]}"
    header: list[Item] = [("CREATION_DATE", creation_date(), None),
                          ("ORIGINATOR", ORIGINATOR, None), ("MESSAGE_ID", mid, None)]
    return [("header", header, None),
            ("body", [("relativeMetadataData", _relative(c), None),
                      ("segment", _object(c, 0, frame), None),
                      ("segment", _object(c, 1, frame), None)], None)]


def _kvn_lines(items: list[Item]) -> list[str]:
    """Return the KVN lines of items (groups flattened)."""
    out: list[str] = []
    for kw, value, unit in items:
        if isinstance(value, list):
            out += _kvn_lines(value)
        elif kw == "COMMENT":
            out.append(f"COMMENT {value}")
        else:
            out.append(f"{kw:<36} = {value}{f' [{unit}]' if unit else ''}")
    return out


def _xml(items: list[Item], parent: object) -> None:
    """Append items to an lxml element (groups as elements holding their items)."""
    from lxml import etree

    for kw, value, unit in items:
        elem = etree.SubElement(parent, kw)  # type: ignore[arg-type]
        if isinstance(value, list):
            _xml(value, elem)
        else:
            elem.text = value
            if unit:
                elem.set("units", unit)


def cdm_text(c: Conjunction, fmt: str = "kvn", frame: str = "EME2000") -> str:
    """Return the CDM of a conjunction as text (module docstring).

    Parameters
    ----------
    c : Conjunction
        The conjunction.
    fmt : str
        ``kvn`` or ``xml``.
    frame : str
        ``REF_FRAME`` of the states: ``EME2000`` (default) or ``GCRF``.
    """
    items = _message(c, frame)
    if fmt == "kvn":
        return "\n".join(["CCSDS_CDM_VERS                       = 1.0",
                          *_kvn_lines(items)]) + "\n"
    from lxml import etree

    root = etree.Element("cdm", id="CCSDS_CDM_VERS", version="1.0")
    _xml(items, root)
    etree.indent(root, space="  ")
    return etree.tostring(root, xml_declaration=True, encoding="UTF-8").decode() + "\n"


def write_cdm(c: Conjunction, out: Path | str, fmt: str = "kvn",
              frame: str = "EME2000") -> Path:
    """Write the CDM of a conjunction to `out` (`cdm_text`); return the path."""
    p = Path(out)
    p.write_text(cdm_text(c, fmt, frame))
    return p

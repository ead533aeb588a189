"""An independent orbit to judge an estimate by: a CPF or a CCSDS OEM, as GCRF states.

`read_reference` tells the format from the content (a CPF starts with ``H1``; an OEM is
KVN, ``CCSDS_OEM_VERS``, or XML) and returns a `ReferenceOrbit`: epochs (Unix s, UTC) and
GCRF states (km, km/s) of one object. A CPF's ITRF positions are turned to the GCRF with
their velocities (the file's, else the derivative of the degree-9 Lagrange polynomial
through them, `core.motion.tabulated`) by `frames.itrs_to_gcrs`; an OEM's states in GCRF,
ICRF, EME2000 or TEME by the frames' rotations, in ITRF (any realisation) by
`frames.itrs_to_gcrs`. An OEM must be in UTC and hold one object.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from ssa_fusion.core.base.quoting import one_line, shown
from ssa_fusion.core.earth.frames import itrs_to_gcrs
from ssa_fusion.core.motion.tabulated import TabulatedOrbit
from ssa_fusion.formats.ccsds.common import CcsdsError, OemFrame, gcrf_rotation, ndm, parse_epoch
from ssa_fusion.formats.ilrs.cpf import read_cpf
from ssa_fusion.formats.records import RecordError

Array = NDArray[np.float64]


@dataclass(frozen=True)
class ReferenceOrbit:
    """GCRF states (n, 6) km, km/s at epochs `t` (n,) of one object (its ids as known)."""

    source: str
    """"cpf" or "oem"."""
    path: str
    t: Array
    x: Array
    names: tuple[str, ...]
    """What the file calls the object: ids and names (any may match an import's)."""


def read_reference(path: Path | str) -> ReferenceOrbit:
    """Return the orbit of a CPF or OEM file as GCRF states (module docstring).

    `records.RecordError` or `CcsdsError` (one line naming the file) otherwise.
    """
    p = Path(path)
    try:
        with p.open("rb") as f:
            head = f.read(64).lstrip(b"\xef\xbb\xbf \t\r\n")
    except OSError as exc:
        raise RecordError(f"{shown(str(p), 200)}: cannot read: "
                          f"{exc.strerror or one_line(exc)}") from None
    if head[:2].upper() == b"H1":
        return _cpf(p)
    if head.startswith((b"CCSDS_OEM_VERS", b"<")):
        return _oem(p)
    raise RecordError(f"{shown(str(p), 200)}: neither a CPF (H1 first) nor a CCSDS OEM "
                      f"(CCSDS_OEM_VERS first, or XML)")


def _cpf(p: Path) -> ReferenceOrbit:
    """Return a CPF's orbit in the GCRF."""
    cpf = read_cpf(p)
    if cpf.com_applied:
        raise RecordError(f"{p}: its positions are of the reflectors (H2: centre-of-mass "
                          f"correction applied): a reference orbit is the centre of mass's")
    table = TabulatedOrbit(cpf.t, cpf.position_km, cpf.velocity_km_s)
    x = itrs_to_gcrs(table.states(cpf.t), cpf.t)
    names = (cpf.target, str(cpf.ilrs_id), *((str(cpf.norad),) if cpf.norad else ()))
    return ReferenceOrbit("cpf", str(p), cpf.t, x, names)


_STATE = ("x", "y", "z", "x_dot", "y_dot", "z_dot")
"""An OEM state vector's fields (km, km/s)."""


def _name(value: object) -> str:
    """Return a CCSDS enumeration value (or text) as its name in capitals."""
    text = str(getattr(value, "value", value))
    return text.upper().rsplit(".", 1)[-1]


def _to_gcrf(p: Path, frame: str, t: Array, x: Array) -> Array:
    """Return OEM states `x` (n, 6) of REF_FRAME `frame` at epochs `t` in the GCRF."""
    if frame.startswith("ITRF"):
        return itrs_to_gcrs(x, t)
    if frame in (OemFrame.EME2000, OemFrame.TEME):
        m = np.swapaxes(gcrf_rotation(OemFrame(frame), t), -1, -2)
        out: Array = np.concatenate([np.einsum("nij,nj->ni", m, x[:, :3]),
                                     np.einsum("nij,nj->ni", m, x[:, 3:])], -1)
        return out
    if frame not in ("GCRF", "ICRF"):
        raise CcsdsError(f"{p}: REF_FRAME {shown(frame)}: a reference OEM is in GCRF, ICRF, "
                         f"EME2000, TEME or ITRF")
    return x


def _oem(p: Path) -> ReferenceOrbit:
    """Return an OEM's orbit (one object, UTC) in the GCRF."""
    io, *_ = ndm()
    try:
        doc = io.from_path(p)
    except Exception as exc:  # ccsds-ndm's own errors, of many types
        raise CcsdsError(f"{p}: not an OEM ccsds-ndm reads: {one_line(exc, 200)}") from None
    if type(doc).__name__ != "Oem":
        raise CcsdsError(f"{p}: a {type(doc).__name__}, not an OEM")
    segs = list(doc.body.segment)
    ids = {s.metadata.object_id for s in segs}
    if len(ids) != 1:
        raise CcsdsError(f"{p}: states of {len(ids)} objects: a reference is one object's")
    t_all, x_all = [], []
    for seg in segs:
        meta = seg.metadata
        if _name(meta.time_system) != "UTC":
            raise CcsdsError(f"{p}: TIME_SYSTEM {shown(_name(meta.time_system))}: a reference "
                             f"OEM must be in UTC")
        t = np.array([parse_epoch(sv.epoch) for sv in seg.data.state_vector])
        x = np.array([[getattr(sv, n).value for n in _STATE] for sv in seg.data.state_vector],
                     dtype=float).reshape(-1, 6)
        t_all.append(t)
        x_all.append(_to_gcrf(p, _name(meta.ref_frame), t, x))
    t, x = np.concatenate(t_all), np.concatenate(x_all)
    order = np.argsort(t, kind="stable")
    return ReferenceOrbit("oem", str(p), t[order], x[order], (ids.pop(),))

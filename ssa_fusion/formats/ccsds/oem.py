"""`ssa-fusion export oem`'s message: a bag's estimates as a CCSDS OEM, and an OEM read back.

OEM (Orbit Ephemeris Message, CCSDS 502.0, version 3.0): one segment per object, a state
vector and a 6x6 covariance per epoch (the last estimate published for that epoch). Units
km, km/s, km², km²/s, km²/s² as OEM prescribes; ``TIME_SYSTEM = UTC``. ``REF_FRAME`` is
``GCRF`` (the estimates' own frame, `core.earth.frames`), ``EME2000`` (rotated by the IAU 2006
frame bias) or ``TEME`` (rotated as `frames.gcrs_to_teme` does); covariances are rotated
with the states.
"""

from __future__ import annotations

import dataclasses
from collections import defaultdict
from collections.abc import Callable, Iterable, Sequence
from pathlib import Path
from types import ModuleType
from typing import TYPE_CHECKING

import numpy as np

from ssa_fusion.core.base import types
from ssa_fusion.core.earth import eop
from ssa_fusion.formats.ccsds.common import (
    ORIGINATOR,
    CcsdsError,
    OemFrame,
    TimeSystem,
    creation_date,
    format_epoch,
    gcrf_rotation,
    ndm,
    parse_epoch,
)

if TYPE_CHECKING:  # ccsds-ndm is imported on use (`common.ndm`)
    from ccsds_ndm.models.ndmxml4.ndmxml_4_0_0_master_4_0 import Oem

_COV = ("x", "y", "z", "x_dot", "y_dot", "z_dot")
"""OEM covariance element names by state index (CX_X, CY_X, ..., CZ_DOT_Z_DOT)."""


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
    _, _, common, master, oem, _ = ndm()
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
    header = common.OdmHeader(creation_date=creation_date(), originator=ORIGINATOR)
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


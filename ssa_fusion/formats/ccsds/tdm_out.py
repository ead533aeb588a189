"""`ssa-fusion export tdm`'s message: a bag's real measurements as a CCSDS TDM.

TDM (Tracking Data Message, CCSDS 503.0, version 2.0): the real range/azimuth/elevation
(``ANGLE_TYPE = AZEL``) and right ascension/declination (``ANGLE_TYPE = RADEC``,
astrometric, ``REFERENCE_FRAME = ICRF`` or ``EME2000``) measurements, one segment per
object, station, kind and noise level, ``TIME_SYSTEM = UTC``; the noise in the metadata
comment `common.SIGMA_COMMENT`, which `tdm_in` reads back.
"""

from __future__ import annotations

from collections import Counter, defaultdict
from collections.abc import Iterable
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from ssa_fusion.core.base import types
from ssa_fusion.formats.ccsds.common import (
    AZEL,
    LAYOUTS,
    ORIGINATOR,
    RADEC,
    RANGE,
    SIGMA_COMMENT,
    TDM_EXPORT_FRAMES,
    AngleFrame,
    CcsdsError,
    TimeSystem,
    creation_date,
    format_epoch,
    frame_bias,
    ndm,
    rotate_radec,
)

if TYPE_CHECKING:  # ccsds-ndm is imported on use (`common.ndm`)
    from ccsds_ndm.models.ndmxml4.ndmxml_4_0_0_master_4_0 import Tdm

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
    _, _, common, master, _, tdm = ndm()
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
    header = tdm.TdmHeader(creation_date=creation_date(), originator=ORIGINATOR)
    doc = master.Tdm(header=header, body=tdm.TdmBody(segment=segments))
    return TdmExport(doc, counts, skipped)


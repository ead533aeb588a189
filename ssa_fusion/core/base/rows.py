"""Measurements and estimates as columns: many rows in a few arrays (core units).

A `MeasurementRows` holds M measurements as one array per field, row i of each being
measurement i, in the core's units (km, km/s, rad, s); a `EstimateRows` likewise M state
estimates. They are what a ``MeasurementBatch`` or ``EstimateBatch`` message carries
(`ssa_fusion.ros.messages` converts, in SI units), and what a catalog node admits and fuses
without a Python loop over the rows.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from ssa_fusion.core.base.types import Kind, Source, UpdateSource

Floats = NDArray[np.float64]


def _take_list(values: list[str], idx: NDArray[np.int64]) -> list[str]:
    """Return `values` at the indices `idx` (a list of strings has no fancy indexing)."""
    return np.asarray(values, dtype=object)[idx].tolist() if len(idx) else []


@dataclass
class MeasurementRows:
    """M measurements as columns (core units); every field has M rows.

    Attributes
    ----------
    t : ndarray (M,)
        Epochs, UTC (Unix) s, sim time.
    object_id, frame_id : list of str (M)
        The object measured; the frame of z: "gcrf" for POSITION, else the station id.
    kind, source : ndarray of uint8 (M,)
        `Kind` and `Source` values (a kind the core does not know stays as it came).
    z : ndarray (M, 3)
        Per kind: GCRF position km; range km, azimuth rad, elevation rad; right ascension
        rad, declination rad, 0.
    R : ndarray (M, 3, 3)
        Noise covariances of z in its units squared (RA_DEC: third row and column 0).
    horizon : ndarray (M,)
        s since the last real measurement a forecast was made from; 0 for SENSOR.
    shard_key : ndarray of uint32 (M,)
        The CRC-32 of each object_id's UTF-8 bytes, as its publisher set it.
    """

    t: Floats
    object_id: list[str]
    frame_id: list[str]
    z: Floats
    R: Floats
    kind: NDArray[np.uint8] = field(default_factory=lambda: np.zeros(0, np.uint8))
    source: NDArray[np.uint8] = field(default_factory=lambda: np.zeros(0, np.uint8))
    horizon: Floats = field(default_factory=lambda: np.zeros(0))
    shard_key: NDArray[np.uint32] = field(default_factory=lambda: np.zeros(0, np.uint32))

    def __post_init__(self) -> None:
        """Fill the defaults of the optional columns for M rows: RANGE_AZ_EL, SENSOR, 0."""
        m = len(self.t)
        if len(self.kind) != m:
            self.kind = np.full(m, Kind.RANGE_AZ_EL, np.uint8)
        if len(self.source) != m:
            self.source = np.full(m, Source.SENSOR, np.uint8)
        if len(self.horizon) != m:
            self.horizon = np.zeros(m)
        if len(self.shard_key) != m:
            self.shard_key = np.zeros(m, np.uint32)

    def __len__(self) -> int:
        """Return the number of rows."""
        return len(self.t)

    def take(self, idx: NDArray[np.int64]) -> MeasurementRows:
        """Return the rows at the indices `idx`, in that order."""
        return MeasurementRows(self.t[idx], _take_list(self.object_id, idx),
                               _take_list(self.frame_id, idx), self.z[idx], self.R[idx],
                               self.kind[idx], self.source[idx], self.horizon[idx],
                               self.shard_key[idx])

    @staticmethod
    def concat(parts: list[MeasurementRows]) -> MeasurementRows:
        """Return the rows of `parts`, one after the other (at least one part)."""
        return MeasurementRows(
            np.concatenate([p.t for p in parts]), [o for p in parts for o in p.object_id],
            [f for p in parts for f in p.frame_id], np.concatenate([p.z for p in parts]),
            np.concatenate([p.R for p in parts]), np.concatenate([p.kind for p in parts]),
            np.concatenate([p.source for p in parts]),
            np.concatenate([p.horizon for p in parts]),
            np.concatenate([p.shard_key for p in parts]))


@dataclass
class EstimateRows:
    """M state estimates as columns (core units), all of one update source.

    Attributes
    ----------
    t : ndarray (M,)
        Epochs of the estimates, UTC (Unix) s, sim time.
    object_id : list of str (M)
        The object estimated.
    x : ndarray (M, 6)
        GCRF states [x, y, z, vx, vy, vz], km and km/s.
    P : ndarray (M, 6, 6)
        Their covariances, km^2, km^2/s, km^2/s^2.
    nis : ndarray (M,)
        Normalized innovation squared of each update (0 for NONE).
    update_source : UpdateSource
        What the last update of every row fused.
    shard_key : ndarray of uint32 (M,)
        The CRC-32 of each object_id's UTF-8 bytes, as its publisher set it.
    """

    t: Floats
    object_id: list[str]
    x: Floats
    P: Floats
    nis: Floats
    update_source: UpdateSource = UpdateSource.SENSOR
    shard_key: NDArray[np.uint32] = field(default_factory=lambda: np.zeros(0, np.uint32))

    def __post_init__(self) -> None:
        """Fill a missing shard_key column with zeros for M rows."""
        if len(self.shard_key) != len(self.t):
            self.shard_key = np.zeros(len(self.t), np.uint32)

    def __len__(self) -> int:
        """Return the number of rows."""
        return len(self.t)

    def take(self, idx: NDArray[np.int64]) -> EstimateRows:
        """Return the rows at the indices `idx`, in that order."""
        return EstimateRows(self.t[idx], _take_list(self.object_id, idx), self.x[idx],
                            self.P[idx], self.nis[idx], self.update_source,
                            self.shard_key[idx])

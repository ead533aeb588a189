"""What the catalog filter does with what arrived between two fusions: `CatalogFusion`.

One policy for the catalog_filter node and for an offline replay of its bag
(`ssa-fusion replay --offline`), so that both give the same estimates for the same rows:

* the rows that wait for a fusion go in epoch order (stable: arrival order at a tie,
  `in_epoch_order`);
* the unlabelled ones (empty ``object_id``, `unlabelled.is_unlabelled`) go to the
  association (`unlabelled.RowAssociator`), whose confirmed tracks' estimates are
  published first;
* the labelled ones go to the `track_bank.TrackBank` (one track per ``object_id``), whose
  fused rows are published as estimates (update source SENSOR) under their object ids.

Which rows the filter takes at all is `row_causes`' (source, the measurement's own checks,
`validation.rows_problems`, and the station). Units: the core's (km, km/s, rad, Unix s;
states in the GCRF).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from ssa_fusion.core.base.rows import EstimateRows, MeasurementRows
from ssa_fusion.core.base.types import Cause, Kind, Source, UpdateSource
from ssa_fusion.core.catalog.track_bank import BankResult, TrackBank
from ssa_fusion.core.catalog.unlabelled import RowAssociator, RowsOutcome, is_unlabelled
from ssa_fusion.core.earth.frames import Station
from ssa_fusion.core.filter.options import FilterOptions
from ssa_fusion.core.measure import validation
from ssa_fusion.core.measure.validation import MAX_OBJECTS


def row_causes(rows: MeasurementRows, stations: Mapping[str, Station]) -> NDArray[np.object_]:
    """Return per row why the catalog filter refuses it ("" when it takes it).

    The first that applies of: a source other than SENSOR (``rejected_source``), the
    measurement's own problem as range/azimuth/elevation (`validation.rows_problems`:
    id, kind, values), a station not in `stations` (``rejected_frame``).
    """
    cause = np.full(len(rows), "", dtype=object)
    problems = validation.rows_problems(rows, Kind.RANGE_AZ_EL)
    unknown = ~np.isin(np.asarray(rows.frame_id, dtype=object), list(stations))
    for bad, why in ((rows.source != Source.SENSOR, Cause.REJECTED_SOURCE),
                     (problems != "", problems), (unknown, Cause.REJECTED_FRAME)):
        free = bad & (cause == "")
        cause[free] = why[free] if isinstance(why, np.ndarray) else why
    return cause


def in_epoch_order(parts: list[MeasurementRows]) -> MeasurementRows | None:
    """Return `parts` as one batch in epoch order, arrival order at a tie (None: no part)."""
    if not parts:
        return None
    rows = MeasurementRows.concat(parts)
    return rows.take(np.argsort(rows.t, kind="stable"))


@dataclass(frozen=True)
class Fused:
    """What one fusion did (`CatalogFusion.fuse`)."""

    unlabelled: RowsOutcome | None
    """The association's outcome for the unlabelled rows (None: there were none)."""
    labelled: MeasurementRows | None
    """The labelled rows the bank took, in its order (None: there were none)."""
    bank: BankResult | None
    """The bank's result for `labelled` (None with it)."""

    def estimates(self) -> list[EstimateRows]:
        """Return the estimates to publish, in the order they are published.

        The confirmed tracks' (`unlabelled`), then the bank's fused rows under their object
        ids (update source SENSOR); empty parts left out.
        """
        out = [self.unlabelled.estimates] if self.unlabelled is not None else []
        if self.labelled is not None and self.bank is not None:
            out.append(fused_estimates(self.labelled, self.bank))
        return [e for e in out if len(e)]


def fused_estimates(batch: MeasurementRows, res: BankResult) -> EstimateRows:
    """Return the estimates of the rows of `batch` the bank fused (`res`), its order."""
    ids = batch.take(res.fused).object_id
    return EstimateRows(batch.t[res.fused], ids, res.x, res.P, res.nis, UpdateSource.SENSOR)


class CatalogFusion:
    """The tracks of a catalog filter: a `TrackBank` and an association (module docstring).

    Parameters
    ----------
    options : FilterOptions
        Every track's filter (`track_bank.TrackBank`).
    stations : dict of str to frames.Station
        The network.
    masks_rad : mapping of str to float
        Each station's elevation mask, rad, for the association (`unlabelled.elevation_masks`).
    max_objects, evict_after_s : int, float
        The labelled bank's limits (`track_bank.TrackBank`).
    """

    def __init__(self, options: FilterOptions, stations: dict[str, Station],
                 masks_rad: Mapping[str, float], max_objects: int = MAX_OBJECTS,
                 evict_after_s: float = math.inf) -> None:
        self.options, self.stations, self.masks = options, stations, dict(masks_rad)
        self.max_objects, self.evict_after_s = int(max_objects), float(evict_after_s)
        self.bank = TrackBank(options, stations, max_objects=self.max_objects,
                              evict_after_s=self.evict_after_s)
        self.associator = RowAssociator(options, stations, self.masks)

    def reset(self) -> None:
        """Forget every track (a backward jump of the clock)."""
        self.bank = TrackBank(self.options, self.stations, max_objects=self.max_objects,
                              evict_after_s=self.evict_after_s)
        self.associator = RowAssociator(self.options, self.stations, self.masks)

    def associate(self, batch: MeasurementRows
                  ) -> tuple[RowsOutcome | None, MeasurementRows | None]:
        """Associate the unlabelled rows of `batch`: (their outcome, the labelled rest).

        None for a part that has no row.
        """
        mask = is_unlabelled(batch.object_id)
        if not mask.any():
            return None, batch
        out = self.associator.process(batch.take(np.flatnonzero(mask)))
        rest = np.flatnonzero(~mask)
        return out, (batch.take(rest) if rest.size else None)

    def track(self, batch: MeasurementRows) -> BankResult:
        """Fuse the labelled rows `batch` (epoch order) in the bank."""
        return self.bank.process(batch.t, batch.object_id, batch.frame_id, batch.z, batch.R)

    def fuse(self, batch: MeasurementRows) -> Fused:
        """Fuse one batch (epoch order: `in_epoch_order`): association, then the bank."""
        out, rest = self.associate(batch)
        return Fused(out, rest, None if rest is None else self.track(rest))

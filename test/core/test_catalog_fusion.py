"""core.catalog.fusion: the catalog filter's policy for one fusion.

Which rows it refuses and why (first cause that applies), the epoch order of what waits
for a fusion (stable at a tie), and a fusion of labelled and unlabelled rows at once
equals the association of the unlabelled rows and a bank of the labelled ones, each fed
alone.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np

from ssa_fusion.core.base.rows import MeasurementRows
from ssa_fusion.core.base.types import Cause, Kind, Source
from ssa_fusion.core.catalog.fusion import CatalogFusion, in_epoch_order, row_causes
from ssa_fusion.core.catalog.track_bank import TrackBank
from ssa_fusion.core.catalog.unlabelled import RowAssociator, elevation_masks, without_labels
from ssa_fusion.core.earth.stations import NETWORKS, SENSORS, network_stations
from ssa_fusion.formats import element_sets as catalog
from ssa_fusion.params import settings
from ssa_fusion.params.defaults import CATALOG_FILTER
from ssa_fusion.sim import survey

SAMPLE = Path(__file__).resolve().parents[2] / "config" / "catalogs" / "sample.tle"
STATIONS = network_stations("radar_network")
OPTIONS = settings.filter_options(dataclasses.asdict(CATALOG_FILTER))


def _rows(n: int) -> MeasurementRows:
    z = np.tile([1000.0, 1.0, 0.5], (n, 1))
    return MeasurementRows(np.arange(n, dtype=float) + 1.7e9, [f"o{i}" for i in range(n)],
                           ["millstone"] * n, z, np.tile(np.eye(3) * 1e-6, (n, 1, 1)))


def test_row_causes_name_the_first_problem_of_each_row():
    rows = _rows(6)
    rows.source[0] = Source.FORECAST
    rows.frame_id[0] = "atlantis"  # and an unknown station: the source comes first
    rows.object_id[1] = "x" * 10_000  # an id too long
    rows.frame_id[2] = "atlantis"
    rows.kind[3] = Kind.POSITION
    rows.z[4, 2] = np.nan
    got = row_causes(rows, STATIONS).tolist()
    assert got[:4] == [Cause.REJECTED_SOURCE, Cause.REJECTED_ID, Cause.REJECTED_FRAME,
                       Cause.REJECTED_KIND]
    assert got[4] not in ("", Cause.REJECTED_FRAME)  # the value's own problem
    assert got[5] == ""


def test_in_epoch_order_is_stable_and_none_for_nothing():
    a, b = _rows(3), _rows(3)
    b.t = np.array([a.t[1], a.t[0] - 1.0, a.t[2]])
    b.object_id = ["b0", "b1", "b2"]
    got = in_epoch_order([a, b])
    assert got is not None
    assert got.object_id == ["b1", "o0", "o1", "b0", "o2", "b2"]
    assert in_epoch_order([]) is None


def test_a_fusion_of_both_kinds_is_each_alone():
    base = catalog.read_catalog(SAMPLE)[0]
    cat = survey.synthetic_catalog(base, 4, seed=3)
    radars = [SENSORS[s] for s in NETWORKS["radar_network"]]
    obs = survey.observe_catalog(cat, radars, base.epoch_unix, 3 * 3600.0, seed=1)
    ids = [obs.object_ids[k] for k in obs.obj]
    rows = MeasurementRows(obs.t, ids, [obs.sensors[j].station.name for j in obs.sensor],
                           obs.z, np.stack([obs.sensors[j].R for j in obs.sensor]))
    rows = rows.take(np.argsort(rows.t, kind="stable"))
    two = np.isin(rows.object_id, [obs.object_ids[0], obs.object_ids[1]])
    labelled = rows.take(np.flatnonzero(two))
    unlabelled = without_labels(rows.take(np.flatnonzero(~two)))
    both = in_epoch_order([labelled, unlabelled])
    assert both is not None
    masks = elevation_masks(STATIONS)
    fused = CatalogFusion(OPTIONS, STATIONS, masks).fuse(both)
    out = fused.estimates()
    assert len(out) == 2  # the tracks' first, then the objects'
    want_tracks = RowAssociator(OPTIONS, STATIONS, masks).process(unlabelled).estimates
    assert out[0].object_id == want_tracks.object_id and len(want_tracks) > 20
    np.testing.assert_array_equal(out[0].x, want_tracks.x)
    bank = TrackBank(OPTIONS, STATIONS)
    res = bank.process(labelled.t, labelled.object_id, labelled.frame_id, labelled.z,
                       labelled.R)
    assert out[1].object_id == [labelled.object_id[i] for i in res.fused.tolist()]
    assert len(out[1]) > 20
    np.testing.assert_array_equal(out[1].x, res.x)
    np.testing.assert_array_equal(out[1].t, labelled.t[res.fused])

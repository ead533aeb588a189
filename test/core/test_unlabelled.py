"""core.catalog.unlabelled: a catalog node's unlabelled rows through the Associator.

On four well-separated objects seen by the radars of iss_network for 6 h (SGP4 truth,
radar noise): every detection has a fate, those kept come back relabelled with their
track's id, only confirmed tracks publish estimates, each track is one object's, and the
tracks do not depend on how the rows are cut into calls."""

import itertools
import math
from dataclasses import asdict
from pathlib import Path

import numpy as np
import pytest

from ssa_fusion.core.base.rows import MeasurementRows
from ssa_fusion.core.catalog.association import DetectionFate, TrackEvent, TrackStatus
from ssa_fusion.core.catalog.unlabelled import (
    UNLABELLED,
    RowAssociator,
    elevation_masks,
    is_unlabelled,
    track_name,
    without_labels,
)
from ssa_fusion.core.earth.stations import SENSORS, Sensor, SensorType, network_stations
from ssa_fusion.formats import element_sets as catalog_io
from ssa_fusion.params import settings
from ssa_fusion.params.defaults import CATALOG_FILTER
from ssa_fusion.sim import sky, survey

SAMPLE = Path(__file__).resolve().parents[2] / "config" / "catalogs" / "sample.tle"
STATIONS = "millstone,tira,altair"


@pytest.fixture(scope="module")
def detections() -> MeasurementRows:
    """Every measurement of four synthetic objects, labelled (the truth), in epoch order."""
    radars = sky.SKY_SCENARIOS["iss_network"].radars
    entries = survey.synthetic_catalog(catalog_io.read_catalog(SAMPLE)[0], 4, seed=4)
    obs = survey.observe_catalog(entries, radars, survey.catalog_start(entries), 6 * 3600.0,
                                 seed=4)
    ids = np.asarray(obs.object_ids, dtype=object)[obs.obj].tolist()
    frames = np.asarray([r.station.name for r in radars], dtype=object)[obs.sensor].tolist()
    return MeasurementRows(obs.t, ids, frames, obs.z, np.array([r.R for r in radars])[obs.sensor])


def _associator() -> RowAssociator:
    stations = network_stations(STATIONS, {})
    return RowAssociator(settings.filter_options({**asdict(CATALOG_FILTER), "station": STATIONS}),
                         stations, elevation_masks(stations))


def test_track_names_are_stable_and_padded():
    assert track_name("T1") == "track-000001"
    assert track_name("T1234567") == "track-1234567"
    assert track_name("X9") == "track-X9"


def test_without_labels_keeps_the_measurements_and_drops_ids_and_keys(detections):
    rows = without_labels(detections.take(np.arange(5)))
    assert rows.object_id == [UNLABELLED] * 5 and not rows.shard_key.any()
    assert is_unlabelled(rows.object_id).all()
    assert not is_unlabelled(detections.object_id[:5]).any()
    np.testing.assert_array_equal(rows.z, detections.z[:5])
    assert rows.frame_id == detections.frame_id[:5]


def test_elevation_masks_from_a_sites_file_else_the_built_in_sensor_else_the_horizon():
    stations = network_stations("tira,columbus", {})
    own = {"tira": Sensor(stations["tira"], SensorType.RADAR, (0.02, 1e-4, 1e-4), 25.0)}
    masks = elevation_masks({**stations, "nowhere": stations["tira"]}, own)
    assert masks["tira"] == pytest.approx(math.radians(25.0))
    assert masks["columbus"] == pytest.approx(math.radians(SENSORS["columbus"].min_elevation_deg))
    assert masks["nowhere"] == 0.0


def test_every_detection_has_a_fate_and_confirmed_tracks_are_one_object_each(detections):
    assoc = _associator()
    out = assoc.process(without_labels(detections))
    m = len(detections)
    assert sum(out.fates.values()) == m == out.events[TrackEvent.DETECTIONS]
    refused = out.fates[DetectionFate.REFUSED]
    assert len(out.associated) == m - refused
    assert all(o.startswith("track-") for o in out.associated.object_id)
    # the associated rows are the detections, relabelled: their truth by (t, station, z)
    truth = {(t, f, tuple(z)): o for t, f, z, o in zip(
        detections.t.tolist(), detections.frame_id, detections.z.tolist(),
        detections.object_id, strict=True)}
    owners: dict[str, set[str]] = {}
    for t, f, z, track in zip(out.associated.t.tolist(), out.associated.frame_id,
                              out.associated.z.tolist(), out.associated.object_id, strict=True):
        owners.setdefault(track, set()).add(truth[(t, f, tuple(z))])
    assert assoc.tracks(TrackStatus.CONFIRMED) == 4
    published = set(out.estimates.object_id)
    assert len(published) == 4 and all(len(owners[t]) == 1 for t in published)
    assert len({next(iter(owners[t])) for t in published}) == 4  # one track per object
    # an estimate per detection fused into a confirmed track, at its epoch, in the GCRF
    assert 0 < len(out.estimates) <= out.fates[DetectionFate.TRACK]
    assert set(out.estimates.t.tolist()) <= set(detections.t.tolist())
    r = np.linalg.norm(out.estimates.x[:, :3], axis=1)
    assert (r > 6500.0).all() and (r < 8000.0).all()


def test_a_tentative_track_publishes_nothing(detections):
    assoc = _associator()
    one = np.flatnonzero(np.asarray(detections.object_id) == detections.object_id[0])
    first = detections.take(one[:11])  # 7 detections to the IOD, 4 more: not yet 6 of 8
    out = assoc.process(without_labels(first))
    assert out.events[TrackEvent.TRACK_INITIATED] >= 1
    assert assoc.tracks(TrackStatus.CONFIRMED) == 0 and len(out.estimates) == 0
    assert out.fates[DetectionFate.TRACK] > 0  # fused into tentative tracks all the same


def test_the_tracks_do_not_depend_on_how_the_rows_are_cut_into_calls(detections):
    rows = without_labels(detections)
    whole = _associator().process(rows)
    assoc = _associator()
    parts = []
    edges = np.r_[0, np.flatnonzero(np.diff(rows.t) > 0)[::37] + 1, len(rows)]
    station = np.asarray(rows.frame_id, dtype=object)
    for a, b in itertools.pairwise(edges):
        # a call's rows station by station (a scan's in their order): the scans are cut
        # and ordered by epoch, then station
        mine = np.arange(a, b)
        parts.append(assoc.process(rows.take(mine[np.argsort(station[mine], kind="stable")])))
    assert [o for p in parts for o in p.estimates.object_id] == whole.estimates.object_id
    np.testing.assert_array_equal(np.concatenate([p.estimates.x for p in parts]),
                                  whole.estimates.x)


def test_a_station_not_of_the_network_is_a_key_error(detections):
    rows = without_labels(detections.take(np.arange(1)))
    rows.frame_id = ["columbus"]
    with pytest.raises(KeyError):
        _associator().process(rows)

"""TrackBank: the batched catalog filter equals one per-object `Tracker` per
object, object by object, on a day-long radar survey of a synthetic LEO catalog."""

import dataclasses
import itertools
import math
from pathlib import Path

import numpy as np
import pytest

from ssa_fusion.core.base.types import Cause, Kind, Measurement
from ssa_fusion.core.catalog.track_bank import TrackBank, station_bit
from ssa_fusion.core.earth.stations import NETWORKS, SENSORS
from ssa_fusion.core.filter.options import FilterOptions
from ssa_fusion.core.gaps.estimator import EstimatorConfig, make_tracker
from ssa_fusion.formats import element_sets as catalog
from ssa_fusion.sim import survey

SAMPLE = Path(__file__).resolve().parents[2] / "config" / "catalogs" / "sample.tle"
RADARS = [SENSORS[s] for s in NETWORKS["radar_network"]]
NETWORK = {s.station.name: s.station for s in RADARS}
Q, SPAN, BOUND = 1e-12, 300.0, 2.0


@pytest.fixture(scope="module")
def survey_6h():
    base = catalog.read_catalog(SAMPLE)[0]
    cat = survey.synthetic_catalog(base, 8, seed=5)
    return survey.observe_catalog(cat, RADARS, base.epoch_unix, 6 * 3600.0, seed=1)


CASES = {  # motion model, q km^2/s^3, IOD samples, reinit_after, tolerance
    "kepler": ("kepler", Q, 3, 0, 1e-9),
    # Kepler loses passes to J2 (gate misses): tracks dropped and initialised again
    "kepler_reinit": ("kepler", Q, 3, 10, 1e-9),
    # the sky scenarios' filter; fixed-step (batched) vs adaptive (per-object) DOP853
    "j2_reinit": ("j2", 1e-13, 7, 10, 1e-7),
}


def _bank(case: str = "kepler") -> TrackBank:
    model, q, samples, reinit, _ = CASES[case]
    options = FilterOptions().with_(motion_model=model, q=q, sigma_bound=BOUND,
                                    iod_samples=samples, iod_max_span_s=SPAN,
                                    reinit_after=reinit)
    return TrackBank(options, NETWORK, capacity=2)


def _per_object(obs, k: int, case: str) -> dict[float, tuple[np.ndarray, np.ndarray]]:
    """Object k's measurements through its own `Tracker`: estimate by epoch."""
    model, q, samples, reinit, _ = CASES[case]
    options = FilterOptions().with_(motion_model=model, q=q, iod_samples=samples,
                                    iod_max_span_s=SPAN, sigma_bound=BOUND,
                                    reinit_after=reinit)
    tr = make_tracker(EstimatorConfig(station=",".join(NETWORK), filter=options))
    out = {}
    for i in np.flatnonzero(obs.obj == k):
        s = obs.sensors[obs.sensor[i]]
        o = tr.process(Measurement(float(obs.t[i]), obs.z[i], s.R, Kind.RANGE_AZ_EL,
                                   frame_id=s.station.name))
        if o.estimate is not None:
            out[float(obs.t[i])] = (o.estimate.x, o.estimate.P)
    return out


def _rel(a, b) -> float:
    return float(np.abs(a - b).max() / max(np.abs(b).max(), 1e-300))


@pytest.mark.parametrize("case", list(CASES))
def test_bank_equals_the_per_object_tracker_object_by_object(survey_6h, case):
    obs = survey_6h
    bank = _bank(case)
    ids = [obs.object_ids[k] for k in obs.obj]
    frames = [obs.sensors[j].station.name for j in obs.sensor]
    R = np.stack([obs.sensors[j].R for j in obs.sensor])
    got: dict[str, dict[float, tuple]] = {}
    # in batches of uneven size, as a node would receive them
    cuts = np.unique(np.r_[0, np.cumsum(np.random.default_rng(0).integers(1, 400, 200)),
                           len(obs)].clip(0, len(obs)))
    for a, b in itertools.pairwise(cuts):
        res = bank.process(obs.t[a:b], ids[a:b], frames[a:b], obs.z[a:b], R[a:b])
        for j, i in enumerate(res.fused.tolist()):
            got.setdefault(ids[a + i], {})[float(obs.t[a + i])] = (res.x[j], res.P[j])
    assert len(bank) == 8
    worst, fused = 0.0, 0
    for k, oid in enumerate(obs.object_ids):
        want = _per_object(obs, k, case)
        assert set(got.get(oid, {})) == set(want), oid
        for t, (x, P) in want.items():
            gx, gP = got[oid][t]
            worst = max(worst, _rel(gx, x), _rel(gP, P))
        fused += len(want)
    assert fused > 500
    assert worst < CASES[case][-1], worst


def test_stale_duplicate_and_unknown_station_are_refused_per_measurement():
    bank = _bank()
    R = np.diag([1e-4, 1e-8, 1e-8])
    z = np.array([1500.0, 1.0, 0.5])
    res = bank.process([0.0, 0.0], ["a", "b"], ["nowhere", "millstone"], [z, z], [R, R])
    assert res.cause == [Cause.REJECTED_FRAME, Cause.IOD_PENDING]
    bank.tracking[bank.rows["b"]] = True
    bank.x[bank.rows["b"]] = [7000.0, 0.0, 0.0, 0.0, 7.5, 0.0]
    bank.P[bank.rows["b"]] = np.eye(6)
    bank.t[bank.rows["b"]] = 100.0
    bank.stations_at_t[bank.rows["b"]] = station_bit(np.array([bank.ekf.index["millstone"]]))[0]
    res = bank.process([50.0, 100.0], ["b", "b"], ["millstone", "millstone"], [z, z], [R, R])
    assert res.cause == [Cause.REJECTED_STALE, Cause.REJECTED_DUPLICATE]
    assert res.fused.size == 0 and bank.t[bank.rows["b"]] == 100.0
    assert math.isfinite(bank.x[bank.rows["b"]].sum())


def test_a_flood_of_new_object_ids_stops_at_max_objects():
    """Objects beyond `max_objects` are refused per measurement (`rejected_bank_full`), the
    ones it holds go on; memory stays at that many rows."""
    bank = TrackBank(_bank().config, NETWORK, capacity=2, max_objects=3)
    R = np.diag([1e-4, 1e-8, 1e-8])
    z = np.array([1500.0, 1.0, 0.5])
    ids = [f"o{k}" for k in range(10)] + ["o1"]
    res = bank.process(np.arange(11.0), ids, ["millstone"] * 11, [z] * 11, [R] * 11)
    assert res.cause == [Cause.IOD_PENDING] * 3 + [Cause.REJECTED_BANK_FULL] * 7 \
        + [Cause.IOD_PENDING]
    assert len(bank) == 3 and bank.object_ids == ["o0", "o1", "o2"]
    assert bank.t.size <= 4


def test_a_full_bank_evicts_only_an_object_silent_for_evict_after():
    """With `evict_after_s` the object measured longest ago gives its row to a new one if
    it has been silent that long; one measured since (or in the same batch) is kept, and a
    new object is refused while nobody is that silent. The evicted object's pending IOD
    goes with it; the new object starts afresh."""
    bank = TrackBank(_bank().config, NETWORK, capacity=2, max_objects=2, evict_after_s=100.0)
    R = np.diag([1e-4, 1e-8, 1e-8])
    z = np.array([1500.0, 1.0, 0.5])
    res = bank.process([0.0, 10.0], ["a", "b"], ["millstone"] * 2, [z] * 2, [R] * 2)
    assert res.cause == [Cause.IOD_PENDING] * 2
    # at 50 s nobody has been silent for 100 s: refused
    res = bank.process([50.0], ["c"], ["millstone"], [z], [R])
    assert res.cause == [Cause.REJECTED_BANK_FULL] and bank.evicted == 0
    # at 105 s: "a" (last at 0 s) is evicted for "c", "b" (10 s) stays; "b" measured in the
    # same batch at 112 s is not a candidate for "d" at 112 s
    res = bank.process([105.0, 112.0, 112.0], ["c", "b", "d"], ["millstone"] * 3, [z] * 3,
                       [R] * 3)
    assert res.cause == [Cause.IOD_PENDING, Cause.IOD_PENDING, Cause.REJECTED_BANK_FULL]
    assert bank.evicted == 1 and sorted(bank.object_ids) == ["b", "c"] and len(bank) == 2
    assert bank.rows["c"] == 0 and "a" not in bank.rows
    assert len(bank._initiators[bank.rows["c"]].batch) == 1  # a's measurement went with it
    # never, by default
    never = TrackBank(_bank().config, NETWORK, capacity=2, max_objects=1)
    never.process([0.0], ["a"], ["millstone"], [z], [R])
    assert never.process([1e9], ["b"], ["millstone"], [z], [R]).cause == [
        Cause.REJECTED_BANK_FULL]


def test_the_bank_keeps_copies_and_refuses_a_non_finite_epoch():
    """Measurements waiting in an IOD batch do not change when the caller reuses its
    arrays; a NaN epoch is refused with a cause, not reported as fused."""
    bank = _bank()
    R = np.diag([1e-4, 1e-8, 1e-8])
    z = np.array([[1500.0, 1.0, 0.5]])
    res = bank.process([10.0], ["a"], ["millstone"], z, [R])
    assert res.cause == [Cause.IOD_PENDING]
    z[0, 0] = -1.0
    assert bank._initiators[bank.rows["a"]].batch[0].z[0] == 1500.0
    bank.tracking[bank.rows["a"]] = True
    bank.x[bank.rows["a"]] = [7000.0, 0.0, 0.0, 0.0, 7.5, 0.0]
    bank.P[bank.rows["a"]] = np.eye(6)
    bank.t[bank.rows["a"]] = 10.0
    res = bank.process([float("nan")], ["a"], ["millstone"], [[1500.0, 1.0, 0.5]], [R])
    assert res.cause == [Cause.REJECTED_NONFINITE] and res.fused.size == 0


@pytest.fixture(scope="module")
def twin_sites_3h():
    """Millstone and a twin radar 3 km east of it: every pass is seen by both at once."""
    mill = SENSORS["millstone"]
    twin = dataclasses.replace(mill, station=dataclasses.replace(
        mill.station, name="millstone_east", lon_rad=mill.station.lon_rad + 3.0 / 4880.0))
    base = catalog.read_catalog(SAMPLE)[0]
    cat = survey.synthetic_catalog(base, 6, seed=7)
    return survey.observe_catalog(cat, [mill, twin], base.epoch_unix, 3 * 3600.0, seed=2)


def test_two_stations_at_one_epoch_are_both_fused_and_equal_the_tracker(twin_sites_3h):
    """Networks see an object from two sites at once: the second site's measurement at the
    epoch of the first is fused (a zero-length prediction), in the bank as in the per-object
    tracker, and only the same site's measurement again is a duplicate."""
    obs = twin_sites_3h
    sensors = {s.station.name: s.station for s in obs.sensors}
    bank = TrackBank(_bank().config, sensors, capacity=2)
    ids = [obs.object_ids[k] for k in obs.obj]
    frames = [obs.sensors[j].station.name for j in obs.sensor]
    R = np.stack([obs.sensors[j].R for j in obs.sensor])
    key = obs.obj * 1e12 + obs.t
    _, pairs = np.unique(key, return_counts=True)
    assert (pairs == 2).sum() > 100  # the geometry gives simultaneous measurements
    res = bank.process(obs.t, ids, frames, obs.z, R)
    assert Cause.REJECTED_DUPLICATE not in res.cause
    fused = np.zeros(len(obs), bool)
    fused[res.fused] = True
    assert fused.sum() > 0.8 * len(obs)
    # the second of a same-epoch pair was fused, and shrank the covariance further
    shrunk = 0
    for j in range(1, res.fused.size):
        a, b = res.fused[j - 1], res.fused[j]
        if ids[a] == ids[b] and obs.t[a] == obs.t[b] and frames[a] != frames[b]:
            assert np.trace(res.P[j][:3, :3]) < np.trace(res.P[j - 1][:3, :3])
            shrunk += 1
    assert shrunk > 50
    # the per-object tracker (its own EKF, no batching) fuses the same pairs to the same state
    tracker_options = dataclasses.replace(bank.config)
    for k in range(2):
        tr = make_tracker(EstimatorConfig(station=",".join(sensors), filter=tracker_options,
                                          sites=(sensors["millstone_east"],)))
        for i in np.flatnonzero(obs.obj == k):
            o = tr.process(Measurement(float(obs.t[i]), obs.z[i], R[i], Kind.RANGE_AZ_EL,
                                       frame_id=frames[i]))
            assert fused[i] == (o.estimate is not None), (i, o.rejected)
            if o.estimate is not None:
                j = int(np.flatnonzero(res.fused == i)[0])
                assert _rel(o.estimate.x, res.x[j]) < 1e-9
    # the same site again at the bank's epoch: a duplicate; the tracker says the same
    last = int(res.fused[-1])
    again = bank.process([obs.t[last]], [ids[last]], [frames[last]], [obs.z[last]], [R[last]])
    assert again.cause == [Cause.REJECTED_DUPLICATE]

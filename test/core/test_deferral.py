"""Decisions deferred over passes (`core.catalog.association.deferral`, `Associator` with
``defer_passes``): the ambiguous pairs of a scan against analytic costs, the pair's cost against
its definition, and two objects of a train whose tracks the scan-wise assignment swaps in their
second pass and the deferred decision puts back (truth labels as the reference): at the next
pass, after a half-day gap with a common along-track error (the groups' registration takes it
out), and through a catalog node's rows (the moved detections given out again)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from ssa_fusion.core.base.rows import MeasurementRows
from ssa_fusion.core.catalog.association import (
    UNASSIGNED,
    AssociationConfig,
    Associator,
    TrackEvent,
    TrackStatus,
    pair_cost,
    predict_scan,
)
from ssa_fusion.core.catalog.association.deferral import Fork, ambiguous_pairs, shadows_in
from ssa_fusion.core.catalog.track_bank import TrackBank
from ssa_fusion.core.catalog.unlabelled import UNLABELLED, RowAssociator, track_name
from ssa_fusion.core.earth.stations import SENSORS
from ssa_fusion.core.filter.options import SKY_FILTER
from ssa_fusion.evaluation.association import detection_labels
from ssa_fusion.sim import survey

RADAR = SENSORS["columbus"]
T0 = 1_735_732_800.0  # 2025-01-01T12:00:00Z
MASK = math.radians(RADAR.min_elevation_deg)
NETWORK = {RADAR.station.name: RADAR.station}
GATE = AssociationConfig().gate


# ------------------------------------------------------------------------------------------
# Ambiguous pairs and the pair's cost
# ------------------------------------------------------------------------------------------
def test_ambiguous_pairs_are_those_whose_swap_costs_less_than_the_margin():
    # tracks 0..3 on detections 0..3; swapping 0 and 1 costs 2 more, 2 and 3 costs 20 more
    cost = np.full((4, 4), 50.0)
    np.fill_diagonal(cost, 1.0)
    cost[0, 1] = cost[1, 0] = 2.0  # 2 + 2 - 1 - 1 = 2
    cost[2, 3] = cost[3, 2] = 11.0  # 11 + 11 - 1 - 1 = 20
    feasible = cost < 40.0
    track = np.arange(4)
    eligible = np.ones(4, dtype=bool)
    assert ambiguous_pairs(track, cost, feasible, 9.2, eligible) == [(0, 1)]
    assert ambiguous_pairs(track, cost, feasible, 25.0, eligible) == [(0, 1), (2, 3)]
    # a swapped pair outside the gate is no hypothesis; an ineligible track pairs with none
    assert ambiguous_pairs(track, cost, feasible & (cost != 2.0), 25.0, eligible) == [(2, 3)]
    assert ambiguous_pairs(track, cost, feasible, 25.0,
                           np.array([True, False, True, True])) == [(2, 3)]
    # a track without a detection in the scan pairs with none: track 1 on detection 0,
    # tracks 3 and 2 on detections 2 and 3 (their swap costs 20 less: a pair)
    assert ambiguous_pairs(np.array([1, UNASSIGNED, 3, 2]), cost, feasible, 25.0,
                           eligible) == [(3, 2)]


def test_ambiguous_pairs_take_each_track_once_least_extra_cost_first():
    # three tracks, every swap ambiguous: (1, 2) costs least, so 0 stays alone
    cost = np.array([[0.0, 3.0, 4.0], [3.0, 0.0, 1.0], [4.0, 1.0, 0.0]])
    got = ambiguous_pairs(np.arange(3), cost, np.ones((3, 3), bool), 9.0, np.ones(3, bool))
    assert got == [(1, 2)]


def test_pair_cost_is_the_clipped_distance_plus_log_det_and_a_miss_the_gate():
    bank = TrackBank(SKY_FILTER, NETWORK)
    cat = survey.satellite_train(RADAR.station, T0 + 600.0, 2, seed=1)
    obs = survey.observe_catalog(cat, [RADAR], T0, 1200.0, seed=1)
    for o in range(2):  # start both tracks from their own detections
        k = np.flatnonzero(obs.obj == o)[:10]
        bank.process(obs.t[k], [f"o{o}"] * k.size, [RADAR.station.name] * k.size, obs.z[k],
                     np.broadcast_to(RADAR.R, (k.size, 3, 3)))
    rows = [bank.rows["o0"], bank.rows["o1"]]
    scan = next(s for s in obs.scans(seed=0) if s.t > bank.t.max() and s.truth.size == 2)
    R = np.broadcast_to(RADAR.R, (2, 3, 3))
    pred = predict_scan(bank.ekf, bank.x[rows], bank.P[rows], bank.t[rows], scan.t, 0)
    S = pred.HPHt[0] + RADAR.R
    dets = [int(np.flatnonzero(scan.truth == o)[0]) for o in range(2)]
    expect = 0.0
    for i, j in enumerate(dets):
        y = scan.z[j] - pred.zp[0, i]
        y[1:] = (y[1:] + math.pi) % (2 * math.pi) - math.pi
        d2 = float(y @ np.linalg.solve(S[i], y))
        expect += min(d2, GATE) + math.log(np.linalg.det(S[i]))
    got, seen = pair_cost(bank, rows, 0, np.full(2, scan.t), scan.z, R, GATE, dets)
    assert seen and got == pytest.approx(expect, rel=1e-9)
    # the tracks' own best assignment is the true one here
    assert pair_cost(bank, rows, 0, np.full(2, scan.t), scan.z, R, GATE)[0] == pytest.approx(
        expect, rel=1e-9)
    # no detection: each track costs the gate plus ln det S
    miss, _ = pair_cost(bank, rows, 0, np.full(2, scan.t), scan.z, R, GATE, [-1, -1])
    assert miss == pytest.approx(sum(GATE + math.log(np.linalg.det(s)) for s in S), rel=1e-9)


def test_shadows_in_lends_the_tracks_h1_states_and_gives_theirs_back():
    bank, shadow = TrackBank(SKY_FILTER, NETWORK), TrackBank(SKY_FILTER, NETWORK)
    rng = np.random.default_rng(0)
    for b, names in ((bank, ("a", "b", "c")), (shadow, ("b~1", "a~1"))):
        for n in names:
            r = b.row(n)
            b.x[r], b.P[r], b.t[r] = rng.normal(size=6), np.eye(6) * rng.uniform(1, 2), r
            b.tracking[r], b.gate_misses[r] = True, 2
    before = {f: getattr(bank, f).copy() for f in ("x", "P", "t", "tracking", "gate_misses")}
    fork = Fork(bank.rows["a"], bank.rows["b"], ("b~1", "a~1"), 0.0)
    with shadows_in(fork, [(bank, fork.a, fork.b)], [shadow]):
        np.testing.assert_array_equal(bank.x[fork.a], shadow.x[shadow.rows["b~1"]])
        np.testing.assert_array_equal(bank.P[fork.b], shadow.P[shadow.rows["a~1"]])
        np.testing.assert_array_equal(bank.x[bank.rows["c"]], before["x"][bank.rows["c"]])
    for f, v in before.items():
        np.testing.assert_array_equal(getattr(bank, f), v)


# ------------------------------------------------------------------------------------------
# Two objects of a train, swapped in their second pass
# ------------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def pair_scans():
    """Two objects 2 km apart in one orbit over the radar for 5 h: three passes."""
    cat = survey.satellite_train(RADAR.station, T0 + 600.0, 2, spacing_km=(2.0, 2.0), seed=1)
    return survey.observe_catalog(cat, [RADAR], T0, 5 * 3600.0, seed=1).scans(seed=1)


def _passes(scans, gap: float = 600.0):
    t = np.array([s.t for s in scans])
    return np.split(np.arange(len(scans)), np.flatnonzero(np.diff(t) > gap) + 1)


def _feed(assoc, scans):
    return [assoc.process_scan(RADAR.station.name, s.t, s.z,
                               np.broadcast_to(RADAR.R, (s.z.shape[0], 3, 3)), MASK)
            for s in scans]


def _bend(assoc: Associator, name: str, t_to: float, along_km: float) -> None:
    """Change a track's speed (both filters) so that at `t_to` it is `along_km` ahead.

    An error of mean motion, as a one-pass orbit has: the along-track error grows with
    time, and the filter's covariance relates it to the velocity.
    """
    banks = [assoc.bank] + ([assoc.predictor] if assoc.predictor is not None else [])
    _bend_banks(banks, name, t_to, along_km)


def _bend_banks(banks: list[TrackBank], name: str, t_to: float, along_km: float) -> None:
    """`_bend` on the track `name` of each of `banks`."""
    for bank in banks:
        r = bank.rows[name]
        x, P, t = bank.x[r], bank.P[r], bank.t[r]
        u = x[3:] / np.linalg.norm(x[3:])
        eps = 1e-5  # km/s
        trial = np.stack([x, x + np.r_[0.0, 0.0, 0.0, eps * u]])
        out = bank.ekf.predict(trial, np.stack([P, P]), np.full(2, t_to - t), np.full(2, t))
        v = out.x[0, 3:] / np.linalg.norm(out.x[0, 3:])
        per_eps = float((out.x[1, :3] - out.x[0, :3]) @ v) / eps
        bank.x[r, 3:] = x[3:] + along_km / per_eps * u


def _run(pair_scans, config: AssociationConfig, later: int = 2, common_km: float = 0.0,
         assoc: Associator | None = None):
    """Track pass 1, give each track a mean-motion error that inverts their predicted order
    at pass 2 (each 0.6 of the spacing towards the other), track passes 2 and `later`.

    `common_km`: before pass `later`, every copy of both tracks (the tracks' and the
    deferred decision's shadows, both filters) is bent that far ahead at its start, the
    common along-track error a long gap leaves. Returns the associator, per pass the
    object of each confirmed track's detections as emitted, and the same after the
    relabels.
    """
    scans = pair_scans
    passes = _passes(scans)
    assert len(passes) > later >= 2
    passes = [passes[0], passes[1], passes[later]]
    assoc = Associator(SKY_FILTER, NETWORK, config) if assoc is None else assoc
    outs = _feed(assoc, [scans[i] for i in passes[0]])
    names = assoc.track_ids(TrackStatus.CONFIRMED)
    assert len(names) == 2
    t2 = scans[passes[1][0]].t
    a, b = names
    r = [assoc.bank.rows[a], assoc.bank.rows[b]]
    bank = assoc.bank
    x = bank.ekf.predict(bank.x[r], bank.P[r], t2 - bank.t[r], bank.t[r]).x
    sep = float((x[1, :3] - x[0, :3]) @ (x[0, 3:] / np.linalg.norm(x[0, 3:])))  # b ahead
    assert 1.0 < abs(sep) < 4.0  # the two objects, 2 km apart, predicted about so
    _bend(assoc, a, t2, 0.6 * sep)
    _bend(assoc, b, t2, -0.6 * sep)
    outs += _feed(assoc, [scans[i] for i in passes[1]])
    if common_km:
        banks = [assoc.bank] + ([assoc.predictor] if assoc.predictor is not None else [])
        shadows = [] if assoc.deferral is None else assoc.deferral.banks()
        forks = [] if assoc.deferral is None else assoc.deferral.forks
        t3 = scans[passes[2][0]].t
        for name in names:
            _bend_banks(banks, name, t3, common_km)
        for fork in forks:
            for name in fork.shadow:
                _bend_banks(shadows, name, t3, common_km)
    outs += _feed(assoc, [scans[i] for i in passes[2]])
    used = [scans[i] for i in np.concatenate(passes)]
    labels = [list(o.ids) for o in outs]
    emitted = _objects(used, labels, names, passes)
    for rel in assoc.relabels:
        labels[rel.scan][rel.detection] = rel.track
    return assoc, emitted, _objects(used, labels, names, passes)


def _objects(scans, labels, names, passes):
    """Per pass (the first three), per track name, the set of objects of its detections."""
    out = []
    start = 0
    for p in passes[:3]:
        seen: dict[str, set[int]] = {n: set() for n in names}
        for s, lab in zip(scans[start:start + p.size], labels[start:start + p.size],
                          strict=True):
            for i, o in zip(lab, s.truth.tolist(), strict=True):
                if i in seen:
                    seen[i].add(o)
        out.append(seen)
        start += p.size
    return out


LOOSE = 2.0 * math.log(1e6)
"""A margin that admits the constructed swap's pair, whatever its first scan's costs."""


def test_scan_wise_assignment_swaps_the_pair_for_good(pair_scans):
    assoc, emitted, _ = _run(pair_scans, AssociationConfig(defer_passes=0))
    first = {n: emitted[0][n] for n in emitted[0]}
    assert all(len(v) == 1 for v in first.values())
    # the premise: in passes 2 and 3 each track holds the other's object
    for later in emitted[1:]:
        assert all(later[n] and later[n] != first[n] for n in first)
    assert assoc.relabels == [] and assoc.deferral is None


def test_deferred_decision_puts_the_swapped_pair_back(pair_scans):
    assoc, emitted, decided = _run(pair_scans, AssociationConfig(defer_margin=LOOSE))
    assert assoc.counts[TrackEvent.DEFER_OPENED] >= 1
    assert assoc.counts[TrackEvent.DEFER_SWAPPED] == 1
    first = decided[0]
    assert all(len(v) == 1 for v in first.values())
    # as emitted, pass 2 went swapped; after the decision every pass is the first's object
    assert any(emitted[1][n] != first[n] for n in first)
    for later in decided[1:]:
        assert all(later[n] == first[n] for n in first)
    assert emitted[2] == decided[2]  # pass 3 was assigned after the decision: no relabel
    assert {r.scan for r in assoc.relabels} <= set(range(len(pair_scans)))


def test_a_pair_not_seen_again_soon_enough_keeps_the_scan_wise_assignment(pair_scans):
    # the third pass comes 1.5 h after the second: with a wait of 1 min the fork is dropped
    assoc, emitted, decided = _run(pair_scans, AssociationConfig(defer_margin=LOOSE,
                                                                 defer_max_wait_s=60.0))
    assert assoc.counts[TrackEvent.DEFER_OPENED] >= 1
    assert assoc.counts[TrackEvent.DEFER_DROPPED] == assoc.counts[TrackEvent.DEFER_OPENED]
    assert assoc.counts[TrackEvent.DEFER_SWAPPED] == 0 and assoc.relabels == []
    assert decided == emitted and any(emitted[2][n] != emitted[0][n] for n in emitted[0])


@pytest.mark.parametrize("bad", [{"defer_passes": -1}, {"defer_margin": -1.0},
                                 {"defer_max_wait_s": 0.0}])
def test_config_refuses_nonsense_deferral_settings(bad):
    with pytest.raises(ValueError, match=next(iter(bad))):
        AssociationConfig(**bad)


# ------------------------------------------------------------------------------------------
# A pair swapped in its last pass before a long gap
# ------------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def gap_scans():
    """The pair of `pair_scans` over the radar for 24 h: its passes and the half-day gap."""
    cat = survey.satellite_train(RADAR.station, T0 + 600.0, 2, spacing_km=(2.0, 2.0), seed=1)
    return survey.observe_catalog(cat, [RADAR], T0, 24 * 3600.0, seed=1).scans(seed=1)


def _after_gap(scans, hours: float = 12.0) -> int:
    """Index of the first pass that starts `hours` or more after the end of pass 1."""
    passes = _passes(scans)
    end = scans[passes[1][-1]].t
    return next(k for k, p in enumerate(passes) if scans[p[0]].t - end >= hours * 3600.0)


COMMON_KM = 3.0
"""A common along-track error of both tracks after the gap: many times the long-arc
predictor's position sigma there, well inside the tracks' filter's."""


def test_a_pair_swapped_before_a_long_gap_is_put_back_on_the_registered_scan(gap_scans):
    later = _after_gap(gap_scans)
    gap = gap_scans[_passes(gap_scans)[later][0]].t - gap_scans[_passes(gap_scans)[1][-1]].t
    assert 12 * 3600.0 < gap < AssociationConfig().defer_max_wait_s
    assoc, emitted, decided = _run(gap_scans, AssociationConfig(defer_margin=LOOSE),
                                   later=later, common_km=COMMON_KM)
    assert assoc.counts[TrackEvent.DEFER_SWAPPED] == 1
    first = decided[0]
    assert all(len(v) == 1 for v in first.values())
    assert any(emitted[1][n] != first[n] for n in first)  # pass 2 went swapped
    for after in decided[1:]:  # the decision put it back, and the pass after the gap
        assert all(after[n] == first[n] for n in first)


def test_without_the_registration_the_common_error_hides_the_swap(gap_scans):
    # the pair's long-arc predictions both miss by the common error: no hypothesis has both
    # tracks in its gates until the tracks' filter, fused as assigned, follows H0's objects
    assoc, emitted, decided = _run(gap_scans, AssociationConfig(defer_margin=LOOSE,
                                                                register_groups=False),
                                   later=_after_gap(gap_scans), common_km=COMMON_KM)
    assert assoc.counts[TrackEvent.DEFER_OPENED] >= 1
    assert assoc.counts[TrackEvent.DEFER_SWAPPED] == 0 and assoc.relabels == []
    assert decided == emitted and any(emitted[2][n] != emitted[0][n] for n in emitted[0])


# ------------------------------------------------------------------------------------------
# Through a catalog node's rows: the moved detections given out again
# ------------------------------------------------------------------------------------------
def _rows(scans, truth: bool = False) -> MeasurementRows:
    """The detections of `scans` as rows: unlabelled, or labelled by their true object."""
    t = np.concatenate([np.full(s.z.shape[0], s.t) for s in scans])
    ids = [str(o) if truth else UNLABELLED for s in scans for o in s.truth.tolist()]
    return MeasurementRows(t, ids, [RADAR.station.name] * t.size,
                           np.concatenate([s.z for s in scans]),
                           np.broadcast_to(RADAR.R, (t.size, 3, 3)).copy())


def test_row_associator_gives_out_the_moved_detections_again(pair_scans):
    rows = RowAssociator(SKY_FILTER, NETWORK, {RADAR.station.name: MASK},
                         AssociationConfig(defer_margin=LOOSE))
    passes = _passes(pair_scans)
    given: list[MeasurementRows] = []  # what a node publishes, in order
    moved: list[MeasurementRows] = []
    for k, p in enumerate(passes[:3]):
        if k == 1:  # the swap of `_run`, on the associator under the rows
            names = rows.associator.track_ids(TrackStatus.CONFIRMED)
            assert len(names) == 2
            t2 = pair_scans[p[0]].t
            bank = rows.associator.bank
            r = [bank.rows[n] for n in names]
            x = bank.ekf.predict(bank.x[r], bank.P[r], t2 - bank.t[r], bank.t[r]).x
            sep = float((x[1, :3] - x[0, :3]) @ (x[0, 3:] / np.linalg.norm(x[0, 3:])))
            _bend(rows.associator, names[0], t2, 0.6 * sep)
            _bend(rows.associator, names[1], t2, -0.6 * sep)
        for s in p.tolist():  # a call per scan, as a node's batches may come
            out = rows.process(_rows([pair_scans[s]]))
            given += [out.associated, out.relabelled]
            moved.append(out.relabelled)
    assert rows.associator.counts[TrackEvent.DEFER_SWAPPED] == 1
    n_moved = sum(len(m) for m in moved)
    assert n_moved == len(rows.associator.relabels) > 0
    assert not rows._held  # no open fork: no scan held
    truth = _rows([pair_scans[i] for i in np.concatenate(passes[:3])], truth=True)
    tracks = {track_name(n) for n in rows.associator.track_ids(TrackStatus.CONFIRMED)}
    label = np.array(detection_labels(truth, MeasurementRows.concat(given)), dtype=object)
    emitted = np.array(detection_labels(truth, MeasurementRows.concat(given[::2])),
                       dtype=object)
    obj = np.array(truth.object_id, dtype=object)
    # the last publication of each detection: every track holds one object
    assert all(len(set(obj[label == n])) == 1 for n in tracks)
    # as first given out, a track held both objects (its deferred pass swapped)
    assert any(len(set(obj[emitted == n])) == 2 for n in tracks)
    # a moved row is a detection of the truth, under a confirmed track's name
    assert {o for m in moved for o in m.object_id} <= tracks

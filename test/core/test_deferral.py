"""Decisions deferred over passes (`core.deferral`, `Associator` with ``defer_passes``):
the ambiguous pairs of a scan against analytic costs, the pair's cost against its
definition, and two objects of a train whose tracks the scan-wise assignment swaps in their
second pass and the deferred decision puts back (truth labels as the reference)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from ssa_fusion.core.association import (
    UNASSIGNED,
    AssociationConfig,
    Associator,
    TrackEvent,
    TrackStatus,
    pair_cost,
    predict_scan,
)
from ssa_fusion.core.deferral import ambiguous_pairs
from ssa_fusion.core.filter_options import SKY_FILTER
from ssa_fusion.core.stations import SENSORS
from ssa_fusion.core.track_bank import TrackBank
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


def _run(pair_scans, config: AssociationConfig):
    """Track pass 1, give each track a mean-motion error that inverts their predicted order
    at pass 2 (each 0.6 of the spacing towards the other), track passes 2 and 3.

    Returns the associator, per pass the object of each confirmed track's detections as
    emitted, and the same after the relabels.
    """
    scans = pair_scans
    passes = _passes(scans)
    assert len(passes) >= 3
    assoc = Associator(SKY_FILTER, NETWORK, config)
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
    outs += _feed(assoc, [scans[i] for i in np.concatenate(passes[1:3])])
    used = [scans[i] for i in np.concatenate(passes[:3])]
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

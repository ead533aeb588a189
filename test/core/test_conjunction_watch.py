"""Watching a live catalog (`core.conjunction.watch`): re-screening what changed.

Against the screening of the whole catalog at once: the first re-screening (every object
new) finds exactly its approaches; a later estimate of one object replaces exactly that
object's approaches; older or non-finite estimates change nothing.
"""

from __future__ import annotations

import numpy as np
import pytest
from planted_conjunctions import T0, planted

from ssa_fusion.core.conjunction.ephemeris import StateEphemeris
from ssa_fusion.core.conjunction.screening import ScreeningConfig, screen
from ssa_fusion.core.conjunction.watch import ConjunctionWatch, WatchConfig

SPAN = 6 * 3600.0


def _pairs(ids: list[str], a, b) -> list[tuple[str, str]]:
    return sorted(tuple(sorted((ids[i], ids[j]))) for i, j in zip(a, b, strict=True))


def test_the_first_rescreening_is_the_screening_of_the_whole_catalog():
    eph = planted(seed=7, n_background=40, n_pairs=15, span_s=SPAN)
    n = len(eph.object_ids)
    p = np.broadcast_to(np.diag([1e-2] * 3 + [1e-8] * 3), (n, 6, 6))
    cfg = WatchConfig(screening=ScreeningConfig(distance_km=10.0), horizon_s=SPAN)
    watch = ConjunctionWatch(cfg)
    assert watch.update(list(eph.object_ids), eph.t0, eph.x0, p) == n
    first = watch.rescreen(T0)
    full = screen(eph, T0, T0 + SPAN, cfg.screening)
    assert len(full) >= 8
    assert sorted(first.screened) == sorted(eph.object_ids) and watch.pending == 0
    ids = list(first.approaches.object_ids)
    assert _pairs(ids, first.approaches.primary, first.approaches.secondary) == _pairs(
        list(eph.object_ids), full.primary, full.secondary)
    assert sorted(first.approaches.tca) == pytest.approx(sorted(full.tca), abs=1e-6)
    assert np.isfinite(first.log10_pc).all() and first.approaches.p1 is not None

    # a later estimate of one object: only its approaches, from its new state
    k = int(full.primary[0])
    oid = eph.object_ids[k]
    t1 = T0 + 60.0
    x1 = eph.exact([k], [t1])[0] + np.r_[0.0, 0.0, 0.5, 0, 0, 0]  # 500 m off
    assert watch.update([oid], [t1], [x1], [p[0]]) == 1
    assert watch.update([oid], [T0], [eph.x0[k]], [p[0]]) == 0  # older: ignored
    assert watch.update(["nan"], [t1], [np.full(6, np.nan)], [p[0]]) == 0
    again = watch.rescreen(t1)
    assert again.screened == [oid]
    got = again.approaches
    assert got.primary_ids == [oid] * len(got) and len(got) >= 1
    # the moved object's approaches are those of its new trajectory
    epochs = np.full(n, T0)
    epochs[k] = t1
    states = eph.x0.copy()
    states[k] = x1
    fresh = screen(StateEphemeris(list(eph.object_ids), states, epochs, model="j2",
                                  max_step_s=cfg.max_step_s), t1,
                   t1 + SPAN, cfg.screening, primaries=[k])
    assert sorted(got.tca) == pytest.approx(sorted(fresh.tca), abs=1e-6)
    # the watch flies from nodes on its fixed grid, this screening from t1: 150 s DOP853
    # steps taken from other epochs agree to ~2e-9 relative (0.1 mm at most)
    assert sorted(got.miss_km) == pytest.approx(sorted(fresh.miss_km), abs=1e-7)


def test_an_estimate_that_re_enters_is_not_flown():
    eph = planted(seed=7, n_background=3, n_pairs=0, span_s=SPAN)
    watch = ConjunctionWatch()
    p = np.diag([1e-2] * 3 + [1e-8] * 3)
    slow = eph.x0[:2].copy()
    slow[0, 3:] *= 0.3  # its perigee deep inside the Earth
    slow[1, 3:] *= 0.997  # its perigee ~80 km lower: still above 100 km
    low = watch.too_low(slow)
    assert low[0] < -3000.0 and np.isnan(low[1])
    assert watch.update(["a", "b"], [T0, T0], slow, [p, p]) == 1 and watch.objects == 1


def test_nothing_changed_screens_nothing():
    watch = ConjunctionWatch()
    up = watch.rescreen(T0)
    assert up.screened == [] and len(up.approaches) == 0


def test_the_order_estimates_arrive_in_changes_nothing():
    # two filter shards' batches interleave as DDS delivers them: the watch must not care
    eph = planted(seed=7, n_background=40, n_pairs=15, span_s=SPAN)
    n = len(eph.object_ids)
    p = np.broadcast_to(np.diag([1e-2] * 3 + [1e-8] * 3), (n, 6, 6))
    cfg = WatchConfig(screening=ScreeningConfig(distance_km=10.0), horizon_s=SPAN)
    updates = []
    for order in (np.arange(n), np.random.default_rng(3).permutation(n)):
        watch = ConjunctionWatch(cfg)
        for part in np.array_split(order, 4):  # four batches
            watch.update([eph.object_ids[k] for k in part], eph.t0[part], eph.x0[part], p[part])
        updates.append(watch.rescreen(T0))
    a, b = (u.approaches for u in updates)
    assert len(a) >= 8 and sorted(updates[0].screened) == sorted(updates[1].screened)
    assert a.primary_ids == b.primary_ids and a.secondary_ids == b.secondary_ids
    np.testing.assert_array_equal(a.tca, b.tca)
    np.testing.assert_array_equal(a.miss_km, b.miss_km)
    np.testing.assert_array_equal(updates[0].log10_pc, updates[1].log10_pc)

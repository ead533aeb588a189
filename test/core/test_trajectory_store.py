"""Trajectories kept between re-screenings (`core.conjunction.trajectory_store`).

Against `StateEphemeris` (the same estimates flown afresh): the store's nodes, carried on
piece by piece as windows slide, are the same numbers; an estimate that changes is flown
again from itself; a watch whose window slid over unchanged objects finds what a fresh
screening of the newest estimates finds.
"""

from __future__ import annotations

import numpy as np
import pytest
from planted_conjunctions import T0, planted

from ssa_fusion.core.base.types import MotionModel
from ssa_fusion.core.conjunction.ephemeris import StateEphemeris
from ssa_fusion.core.conjunction.screening import ScreeningConfig, screen
from ssa_fusion.core.conjunction.trajectory_store import TrajectoryStore
from ssa_fusion.core.conjunction.watch import ConjunctionWatch, WatchConfig

STEP = 300.0
SPAN = 6 * 3600.0


def _store_and_fresh() -> tuple[TrajectoryStore, StateEphemeris, int]:
    eph = planted(seed=3, n_background=12, n_pairs=2, span_s=SPAN)
    store = TrajectoryStore(MotionModel.J2, STEP)
    n = len(eph.object_ids)
    t0 = eph.t0 + np.linspace(-900.0, 400.0, n)  # epochs off the grid, either side
    x0 = eph.exact(np.arange(n), t0)
    store.set_estimates(np.arange(n), x0, t0)
    fresh = StateEphemeris(list(eph.object_ids), x0, t0, model="j2")
    return store, fresh, int(np.ceil(T0 / STEP))


def test_nodes_carried_on_piece_by_piece_are_those_flown_at_once():
    store, fresh, k = _store_and_fresh()
    rows = np.arange(len(fresh.object_ids))
    first = store.states(rows, k, k + 10)
    store.keep_from(k + 4)  # the window slid: older nodes forgotten
    later = store.states(rows[::2], k + 4, k + 30)  # half the rows carried on
    rest = store.states(rows, k + 20, k + 40)  # the other half jumps ahead
    whole = fresh.sample(STEP * np.arange(k, k + 41))
    np.testing.assert_array_equal(first, whole[:, :11])
    np.testing.assert_array_equal(later, whole[::2, 4:31])
    np.testing.assert_array_equal(rest, whole[:, 20:41])
    # exact states start from the nearest node: the trajectory's, to integration error
    t = STEP * (k + 20) + np.linspace(-140.0, 140.0, rows.size)
    np.testing.assert_allclose(store.exact(rows, t), fresh.exact(rows, t), atol=1e-9)


def test_a_new_estimate_is_flown_from_itself():
    store, fresh, k = _store_and_fresh()
    rows = np.arange(len(fresh.object_ids))
    store.states(rows, k, k + 20)
    moved = fresh.x0[3] + np.r_[0.0, 0.0, 1.0, 0.0, 0.0, 0.0]  # 1 km off, an hour later
    store.set_estimates([3], [moved], [fresh.t0[3] + 3600.0])
    again = store.states(rows, k + 12, k + 24)
    alone = StateEphemeris(["3"], [moved], [fresh.t0[3] + 3600.0], model="j2")
    np.testing.assert_array_equal(again[3], alone.sample(STEP * np.arange(k + 12, k + 25))[0])
    np.testing.assert_array_equal(again[:3], fresh.sample(STEP * np.arange(k, k + 25))[:3, 12:])
    with pytest.raises(ValueError, match="consecutive nodes"):
        store.view(rows).sample([STEP * k, STEP * (k + 2)])


def test_a_window_slid_over_unchanged_objects_finds_what_a_fresh_screening_finds():
    eph = planted(seed=7, n_background=40, n_pairs=15, span_s=2 * SPAN)
    n = len(eph.object_ids)
    p = np.broadcast_to(np.diag([1e-2] * 3 + [1e-8] * 3), (n, 6, 6))
    cfg = WatchConfig(screening=ScreeningConfig(distance_km=10.0), horizon_s=SPAN)
    watch = ConjunctionWatch(cfg)
    watch.update(list(eph.object_ids), eph.t0, eph.x0, p)
    watch.rescreen(T0)
    t2 = T0 + 4 * 3600.0 + 77.0  # four hours on: the others carried on, not flown again
    ahead = screen(eph, t2 + 600.0, t2 + SPAN, cfg.screening)
    moved = sorted({int(k) for k in ahead.primary[:3]} | {0})
    x2 = eph.exact(moved, [t2] * len(moved)) + np.r_[0.0, 0.3, 0.0, 0.0, 0.0, 0.0]
    watch.update([eph.object_ids[k] for k in moved], [t2] * len(moved), x2, p[:len(moved)])
    got = watch.rescreen(t2).approaches
    states, epochs = eph.x0.copy(), eph.t0.copy()
    states[moved], epochs[moved] = x2, t2
    fresh = screen(StateEphemeris(list(eph.object_ids), states, epochs, model="j2",
                                  max_step_s=cfg.max_step_s, covariance=p),
                   t2, t2 + SPAN, cfg.screening, primaries=moved)
    assert len(fresh) >= 1
    key = sorted(zip(got.primary_ids, got.secondary_ids, strict=True))
    assert key == sorted(zip(fresh.primary_ids, fresh.secondary_ids, strict=True))
    order_g, order_f = np.argsort(got.tca), np.argsort(fresh.tca)
    np.testing.assert_allclose(got.tca[order_g], fresh.tca[order_f], atol=1e-6)
    np.testing.assert_allclose(got.miss_km[order_g], fresh.miss_km[order_f], atol=1e-9)
    assert got.p1 is not None and fresh.p1 is not None
    # the covariances' matrices take longer steps (covariance_step_s): 1e-7 relative
    np.testing.assert_allclose(got.p1[order_g], fresh.p1[order_f], rtol=1e-5, atol=1e-12)

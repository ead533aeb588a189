"""Tests for ssa_fusion.core.filter.history (the log of fused steps and rollback) and the filter's
snapshot/restore it goes through, on their own.

The references are the test's own copies of the filter's x, P taken before every step (not
`ExtendedKalmanFilter.snapshot`), a brute-force count for the position lookup and a
brute-force slice for the trimming; the filter is a constant-velocity EKF fused with noisy
positions, so every step changes x and P.
"""

from __future__ import annotations

import numpy as np
import pytest

from ssa_fusion.core.base.types import Kind, Measurement, Source
from ssa_fusion.core.filter.ekf import ExtendedKalmanFilter, process_noise
from ssa_fusion.core.filter.history import HISTORY_REAL, FusedHistory, FusedStep, Snapshot

H = np.hstack([np.eye(3), np.zeros((3, 3))])


def _cv(x: np.ndarray, dt: float) -> tuple[np.ndarray, np.ndarray]:
    F = np.eye(6)
    F[:3, 3:] = dt * np.eye(3)
    return F @ x, F


def _ekf() -> ExtendedKalmanFilter:
    return ExtendedKalmanFilter([7000.0, 0, 0, 0, 7.5, 0], np.diag([1.0] * 3 + [1e-2] * 3))


def _measurement(t: float, rng: np.random.Generator, source: int = Source.SENSOR) -> Measurement:
    z = np.array([7000.0, 7.5 * t, 0.0]) + rng.standard_normal(3)
    return Measurement(t, z, np.eye(3), kind=Kind.POSITION, source=source,
                       horizon=30.0 if source == Source.FORECAST else 0.0)


def _fuse(ekf: ExtendedKalmanFilter, t0: float, m: Measurement) -> None:
    dt = m.t - t0
    if dt:
        ekf.predict(lambda x: _cv(x, dt), process_noise(dt, 1e-8))
    assert ekf.update(m.z, lambda x: (H @ x, H), m.R).accepted


def _run(sources: list[int], seed: int = 0):
    """Fuse one step per source, 30 s apart, into a fresh filter and a history.

    Returns the filter, the history, the test's own copies of (x, P) before each step, and
    those after the last step.
    """
    rng = np.random.default_rng(seed)
    ekf, hist = _ekf(), FusedHistory()
    t, t_real, before = 0.0, -np.inf, []
    for i, source in enumerate(sources):
        m = _measurement(30.0 * (i + 1), rng, source)
        before.append((np.array(ekf.x), np.array(ekf.P)))
        snap = Snapshot(t, *ekf.snapshot())
        _fuse(ekf, t, m)
        hist.record(FusedStep(m, snap, t_real))
        t = m.t
        if source != Source.FORECAST:
            t_real = m.t
    return ekf, hist, before, (np.array(ekf.x), np.array(ekf.P))


# ------------------------------------------------------------------------------ the filter
def test_snapshot_and_restore_are_copies():
    ekf = _ekf()
    x, P = ekf.snapshot()
    x_ref, P_ref = np.array(ekf.x), np.array(ekf.P)
    assert x is not ekf.x and P is not ekf.P
    _fuse(ekf, 0.0, _measurement(30.0, np.random.default_rng(1)))
    assert not np.array_equal(ekf.x, x_ref)
    np.testing.assert_array_equal(x, x_ref)  # the snapshot did not follow the filter
    np.testing.assert_array_equal(P, P_ref)
    ekf.restore(x, P)
    np.testing.assert_array_equal(ekf.x, x_ref)
    np.testing.assert_array_equal(ekf.P, P_ref)
    x[0] += 1.0
    P[0, 0] += 1.0  # the filter does not alias the snapshot it was restored from
    np.testing.assert_array_equal(ekf.x, x_ref)
    np.testing.assert_array_equal(ekf.P, P_ref)


# ------------------------------------------------------------------------------ rollback
MIXED = [Source.SENSOR, Source.FORECAST, Source.FORECAST, Source.SENSOR, Source.FORECAST,
         Source.SENSOR]


@pytest.mark.parametrize("k", range(len(MIXED)))
def test_rollback_restores_exactly_the_state_before_the_step(k):
    ekf, hist, before, _ = _run(MIXED)
    steps = list(hist.steps)
    tail = hist.rollback(k, ekf)
    np.testing.assert_array_equal(ekf.x, before[k][0])
    np.testing.assert_array_equal(ekf.P, before[k][1])
    assert [id(e) for e in tail] == [id(e) for e in steps[k:]]
    assert [id(e) for e in hist.steps] == [id(e) for e in steps[:k]] and len(hist) == k
    assert tail[0].before.t == (30.0 * k)  # the epoch the caller goes back to
    real = [30.0 * (i + 1) for i in range(k) if MIXED[i] != Source.FORECAST]
    assert tail[0].t_real == (real[-1] if real else -np.inf)


def test_fusing_the_undone_steps_again_gives_the_same_state():
    ekf, hist, _, after = _run(MIXED, seed=3)
    tail = hist.rollback(2, ekf)
    t = tail[0].before.t
    for e in tail:
        _fuse(ekf, t, e.m)
        t = e.m.t
    np.testing.assert_array_equal(ekf.x, after[0])
    np.testing.assert_array_equal(ekf.P, after[1])


# ------------------------------------------------------------------------------ the log
def test_position_is_the_count_of_earlier_steps():
    _, hist, _, _ = _run(MIXED)
    epochs = [e.m.t for e in hist.steps]
    for t in np.arange(0.0, 30.0 * (len(MIXED) + 2), 7.5):
        assert hist.position(float(t)) == sum(s < t for s in epochs)
        k = hist.position(float(t))
        at = hist.at(k)
        assert (at is None) == (k == len(hist))
        assert at is None or at.m.t >= t


def test_trimming_keeps_the_steps_since_history_real_reals_back():
    rng = np.random.default_rng(5)
    sources = [Source.FORECAST if rng.random() < 0.4 else Source.SENSOR for _ in range(60)]
    _, hist, _, _ = _run(sources)
    real_epochs = [30.0 * (i + 1) for i, s in enumerate(sources) if s != Source.FORECAST]
    first = real_epochs[-HISTORY_REAL]
    kept = [30.0 * (i + 1) for i in range(len(sources)) if 30.0 * (i + 1) >= first]
    assert [e.m.t for e in hist.steps] == kept
    assert sum(e.m.source != Source.FORECAST for e in hist.steps) == HISTORY_REAL


def test_forecasts_alone_do_not_trim():
    _, hist, _, _ = _run([Source.SENSOR] + [Source.FORECAST] * (3 * HISTORY_REAL))
    assert len(hist) == 1 + 3 * HISTORY_REAL

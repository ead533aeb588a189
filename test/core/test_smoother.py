"""Tests for ssa_fusion.core.filter.smoother: RTS smoothing of a filter's recorded estimates.

References: FilterPy's ``rts_smoother`` on a linear problem (equal to 1e-10); on an orbit (the
real-sky ISS over Columbus, SGP4 truth), the smoothed estimates against the truth beside
the filtered ones; the live filter's own priors against those rebuilt from its estimates.
"""

from __future__ import annotations

import numpy as np
import pytest
from filterpy.kalman import rts_smoother

from ssa_fusion.core.base.types import Measurement, Source, StateEstimate
from ssa_fusion.core.filter import smoother
from ssa_fusion.core.filter.ekf import ExtendedKalmanFilter, process_noise
from ssa_fusion.core.filter.tracker import Tracker
from ssa_fusion.core.gaps import estimator as config
from ssa_fusion.sim import sky

DT = 1.0
F = np.array([[1.0, 0.0, DT, 0.0], [0.0, 1.0, 0.0, DT], [0.0, 0.0, 1.0, 0.0],
              [0.0, 0.0, 0.0, 1.0]])
H = np.hstack([np.eye(2), np.zeros((2, 2))])
Q = process_noise(DT, 0.02, dim=2)
R = np.diag([0.5, 0.3])


def _linear_run(k: int = 40) -> tuple[list[smoother.FilterStep], np.ndarray]:
    rng = np.random.default_rng(11)
    x_true = np.array([0.0, 1.0, 0.5, -0.3])
    kf = ExtendedKalmanFilter(np.zeros(4), np.diag([5.0, 5.0, 1.0, 1.0]))
    steps, truth = [], []
    for i in range(k):
        x_true = F @ x_true + np.linalg.cholesky(Q + 1e-15 * np.eye(4)) @ rng.standard_normal(4)
        if i:
            kf.predict(lambda x: (F @ x, F), Q)
        z = H @ x_true + np.sqrt(np.diag(R)) * rng.standard_normal(2)
        prior = (kf.x.copy(), kf.P.copy())
        kf.update(z, lambda x: (H @ x, H), R)
        steps.append(smoother.FilterStep(float(i), *prior, kf.x.copy(), kf.P.copy(),
                                         F.copy() if i else np.eye(4)))
        truth.append(x_true.copy())
    return steps, np.array(truth)


def test_rts_equals_filterpy_on_a_linear_problem() -> None:
    steps, truth = _linear_run()
    ours = smoother.rts(steps)
    Xs = np.array([s.x_post for s in steps])
    Ps = np.array([s.P_post for s in steps])
    x, P, K, _ = rts_smoother(Xs, Ps, [F] * len(steps), [Q] * len(steps))
    np.testing.assert_allclose(ours.x, x, rtol=0, atol=1e-10)
    np.testing.assert_allclose(ours.P, P, rtol=0, atol=1e-10)
    np.testing.assert_allclose(ours.C[:-1], K[:-1], rtol=0, atol=1e-10)
    # and it helps: smoothed errors below filtered ones over the interior
    ef = np.linalg.norm(Xs[:-1, :2] - truth[:-1, :2], axis=1)
    es = np.linalg.norm(ours.x[:-1, :2] - truth[:-1, :2], axis=1)
    assert es.mean() < 0.8 * ef.mean()
    np.testing.assert_array_equal(ours.x[-1], Xs[-1])


def test_steps_rebuilt_from_estimates_are_the_filters() -> None:
    steps, _ = _linear_run()
    est = [StateEstimate(s.t, s.x_post, s.P_post) for s in steps]
    rebuilt = smoother.steps_from_estimates(est, lambda x, dt, t0: (F @ x, F),
                                            lambda x, dt: Q)
    for a, b in zip(rebuilt[1:], steps[1:], strict=True):
        np.testing.assert_allclose(a.x_prior, b.x_prior, rtol=0, atol=1e-14)
        np.testing.assert_allclose(a.P_prior, b.P_prior, rtol=0, atol=1e-14)
    np.testing.assert_allclose(smoother.rts(rebuilt).x[1:], smoother.rts(steps).x[1:],
                               atol=1e-12)


@pytest.fixture(scope="module")
def sky_run() -> tuple[sky.SkyScenario, list[Measurement]]:
    s = sky.SKY_SCENARIOS["iss_radar_columbus"].with_(duration_s=0.55 * 86400.0)
    return s, sky.simulate_sky(s, seed=3).real


def test_orbit_smoothed_below_filtered(sky_run: tuple[sky.SkyScenario, list[Measurement]]
                                       ) -> None:
    s, real = sky_run
    tracker = config.make_tracker(s.estimator())
    rec = smoother.TrackerRecorder(tracker)
    live = {}
    for m in real:
        if rec.process(m).estimate is not None and tracker.ekf is not None:
            live[m.t] = (tracker.ekf.x_prior.copy(), tracker.ekf.P_prior.copy())
    (steps,) = rec.steps()
    assert len(steps) > 90  # three passes after the IOD
    for st in steps[1:]:  # the recorder's priors are the live filter's own
        np.testing.assert_allclose(st.x_prior, live[st.t][0], rtol=0, atol=1e-12)
        np.testing.assert_allclose(st.P_prior, live[st.t][1], rtol=1e-12, atol=0)
    (sm,) = rec.smooth()
    truth = sky.truth(s, sm.t)
    filtered = np.array([st.x_post for st in steps])
    ef = np.linalg.norm(filtered[:-1, :3] - truth[:-1, :3], axis=1)
    es = np.linalg.norm(sm.x[:-1, :3] - truth[:-1, :3], axis=1)
    assert np.median(es) < 0.5 * np.median(ef)
    assert np.mean(es < ef) > 0.8
    np.testing.assert_array_equal(sm.x[-1], filtered[-1])
    e = sm.x[:, :3] - truth[:, :3]
    nees = np.einsum("ki,kij,kj->k", e, np.linalg.inv(sm.P[:, :3, :3]), e)
    assert np.median(nees) < 7.8  # chi2(3) 95 %


def recorded(sky_run: tuple[sky.SkyScenario, list[Measurement]], n: int
             ) -> tuple[Tracker, smoother.TrackerRecorder, list[Measurement]]:
    """The scenario's tracker, its recorder after the first `n` real measurements, and them."""
    s, real = sky_run
    tracker = config.make_tracker(s.estimator())
    rec = smoother.TrackerRecorder(tracker)
    for m in real[:n]:
        rec.process(m)
    return tracker, rec, real


def test_recorder_follows_a_rollback(sky_run: tuple[sky.SkyScenario, list[Measurement]]
                                     ) -> None:
    """A late forecast goes in front of fused real measurements: the chain is re-fused."""
    tracker, rec, real = recorded(sky_run, 12)
    base = real[9]
    z = 0.5 * (base.z + real[10].z)  # halfway between two measurements 10 s apart
    late = Measurement(base.t + 5.0, z, base.R, base.kind, Source.FORECAST,
                       frame_id=base.frame_id, horizon=5.0)
    out = rec.process(late)
    assert out.estimate is not None and len(out.fused_again) == 2
    chain = rec.segments[-1]
    assert [e.t for e in chain[-4:]] == [base.t, late.t, real[10].t, real[11].t]
    np.testing.assert_array_equal(chain[-1].x, tracker.estimate().x)
    steps = rec.steps()[-1]
    assert [st.t for st in steps] == [e.t for e in chain]


def test_recorder_splits_at_a_new_filter(sky_run: tuple[sky.SkyScenario, list[Measurement]]
                                         ) -> None:
    tracker, rec, real = recorded(sky_run, 15)
    tracker.reset()  # a clock jump: the filter starts again with a new IOD
    for m in real[15:23]:  # the rest of the first pass: 7 for the IOD, then one update
        rec.process(m)
    segs = rec.steps()
    assert len(segs) == 2
    assert segs[0][-1].t == real[14].t and segs[1][0].t == real[21].t
    assert [st.t for st in segs[1]] == [real[21].t, real[22].t]
    np.testing.assert_array_equal(segs[1][0].F, np.eye(6))
    assert all(len(sm.t) == len(st) for sm, st in zip(rec.smooth(), segs, strict=True))

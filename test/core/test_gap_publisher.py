"""`core.gaps.publisher.GapPublisher`: what a filter publishes, live and offline alike."""

import math

import numpy as np
import pytest
from references import scipy_orbit

from ssa_fusion.core.base.constants import MU_EARTH
from ssa_fusion.core.base.types import Kind, Measurement, Source, UpdateSource
from ssa_fusion.core.filter.options import FilterOptions
from ssa_fusion.core.gaps.estimator import EstimatorConfig, make_tracker
from ssa_fusion.core.gaps.publisher import GapFill, GapPublisher

R_KM = 7000.0
T0 = 1.7e9  # Unix s
CADENCE = 30.0


def position(t: float) -> np.ndarray:
    """A circular equatorial orbit of radius `R_KM`: position at Unix time `t` (km)."""
    w = math.sqrt(MU_EARTH / R_KM**3)
    a = w * (t - T0)
    return np.array([R_KM * math.cos(a), R_KM * math.sin(a), 0.0])


def meas(t: float, source: int = Source.SENSOR) -> Measurement:
    return Measurement(t=t, z=position(t), R=np.eye(3) * 1e-4, kind=Kind.POSITION,
                       source=source, object_id="sat", frame_id="gcrf",
                       horizon=0.0 if source == Source.SENSOR else CADENCE)


def publisher(period_s: float = 300.0, fill: GapFill = GapFill.NONE) -> GapPublisher:
    c = EstimatorConfig(kind=Kind.POSITION)
    return GapPublisher.of(make_tracker(c), period_s, fill, c)


TRACK = [T0 + i * CADENCE for i in range(10)]
AFTER = TRACK[-1] + 1000.0  # the measurement that ends a gap of ~1000 s


def published(pub: GapPublisher, clock: list[float]) -> list:
    """What `pub` publishes: the track, the clock ticks `clock` through the gap, then AFTER."""
    out = []
    for t in TRACK:
        out += pub.measurement(meas(t)).estimates
    for now in clock:
        out += pub.advance(now).estimates
    out += pub.measurement(meas(AFTER)).estimates
    return out


def test_predictions_on_the_grid_through_the_gap_before_the_measurement_ending_it():
    out = published(publisher(), [])
    sources = [e.update_source for e in out]
    predictions = [e for e in out if e.update_source == UpdateSource.NONE]
    expected = [k * 300.0 for k in range(math.floor(TRACK[-1] / 300) + 1,
                                         math.ceil(AFTER / 300))]
    assert [e.t for e in predictions] == expected
    assert sources[-1] == UpdateSource.SENSOR and out[-1].t == AFTER
    assert all(e.object_id == "sat" for e in out)
    # the covariance grows through the gap; the state follows the orbit
    traces = [np.trace(e.P[:3, :3]) for e in predictions]
    assert traces == sorted(traces)
    assert all(np.linalg.norm(e.x[:3] - position(e.t)) < 1.0 for e in predictions)


@pytest.mark.parametrize("clock", [
    [AFTER - 1.0],                                      # one late tick
    list(np.arange(TRACK[-1], AFTER, 7.0)),             # many ticks
    [TRACK[-1] + 400.0, TRACK[-1] + 401.0, AFTER - 5],  # some, unevenly
])
def test_what_is_published_does_not_depend_on_when_the_clock_ticks(clock):
    """The live node ticks on a wall timer, the offline replay on the bag's /clock: the same
    input gives the same estimates however the clock advanced."""
    reference = published(publisher(), [])
    ticked = published(publisher(), clock)
    assert [(e.t, e.update_source) for e in ticked] == [(e.t, e.update_source)
                                                        for e in reference]
    for a, b in zip(reference, ticked, strict=True):
        assert np.array_equal(a.x, b.x) and np.array_equal(a.P, b.P)


def test_nothing_is_predicted_without_a_period_or_before_initialisation():
    assert not [e for e in published(publisher(period_s=0.0), [AFTER - 1.0])
                if e.update_source == UpdateSource.NONE]
    pub = publisher()
    assert not pub.advance(T0 + 1e6).estimates  # no state yet


def test_a_clock_far_ahead_skips_the_earliest_predictions():
    pub = publisher(period_s=1.0)
    for t in TRACK:
        pub.measurement(meas(t))
    out = pub.advance(TRACK[-1] + 5000.0, limit=10)  # 5000 due, the clock's own epoch too
    assert out.skipped == 5000 - 100 and len(out.estimates) == 10


def test_reset_forgets_the_track_and_a_new_period_takes_effect():
    pub = publisher()
    for t in TRACK:
        pub.measurement(meas(t))
    pub.set_period(100.0)
    times = [e.t for e in pub.advance(TRACK[-1] + 350.0).estimates]
    assert times and all(t % 100.0 == 0 for t in times)
    pub.reset()
    assert not pub.tracker.initialised and not pub.advance(AFTER).estimates


def test_a_residual_publisher_coasts_until_it_has_learnt_from_pass_ends():
    """With `GapFill.RESIDUAL` and no pass end learnt yet, the gap is the EKF's predictions
    (the forecaster has nothing to say); the EKF's own chain is the same either way."""
    plain = published(publisher(), [])
    residual = published(publisher(fill=GapFill.RESIDUAL), [])
    assert [(e.t, e.update_source) for e in residual] == [(e.t, e.update_source)
                                                         for e in plain]


def test_a_batch_fit_publisher_fills_the_gap_with_the_fit_of_the_last_passes():
    """`GapFill.BATCH_FIT`: three passes of 10 m positions of a J2-J4 orbit (scipy), a filter
    on a two-body model; from `pass_break_s` after the last pass on, the gap's predictions
    are the J2 batch fit of those passes (update source FORECAST, within 30 m of scipy's
    orbit over the next two hours) while the two-body EKF's own predictions drift by
    kilometres; before it, the EKF's predictions."""
    x0 = np.array([6778.0, 0.0, 0.0, 0.0, 4.8, 5.9])
    t = T0 + np.concatenate([k * 2400.0 + 60.0 * np.arange(10) for k in range(3)])
    grid = 60.0 * np.arange(math.floor(t[-1] / 60.0) + 1, math.floor((t[-1] + 7200) / 60) + 1)
    truth = scipy_orbit(x0, np.concatenate([t, grid]), j3_j4=True)
    c = EstimatorConfig(kind=Kind.POSITION, lift="none",
                        filter=FilterOptions().with_(p0_sigma=(1.0,) * 3 + (1e-2,) * 3,
                                                     q=1e-9))
    pubs = {f: GapPublisher.of(make_tracker(c), 60.0, f, c)
            for f in (GapFill.NONE, GapFill.BATCH_FIT)}
    out = {}
    for f, pub in pubs.items():
        rng = np.random.default_rng(5)
        for ti, xi in zip(t, truth[: t.size], strict=True):
            pub.measurement(Measurement(float(ti), xi[:3] + 0.01 * rng.standard_normal(3),
                                        1e-4 * np.eye(3), kind=Kind.POSITION, frame_id="gcrf"))
        out[f] = pub.advance(float(grid[-1]), limit=1000).estimates
    fits = out[GapFill.BATCH_FIT]
    assert [e.t for e in fits] == [e.t for e in out[GapFill.NONE]] == list(grid)
    late = grid - t[-1] >= 600.0
    assert all((e.update_source == UpdateSource.FORECAST) == lt for e, lt in zip(fits, late,
                                                                              strict=True))
    x_fit = np.array([e.x for e in fits])
    x_ekf = np.array([e.x for e in out[GapFill.NONE]])
    err_fit = np.linalg.norm(x_fit[late, :3] - truth[t.size:][late, :3], axis=1)
    err_ekf = np.linalg.norm(x_ekf[late, :3] - truth[t.size:][late, :3], axis=1)
    assert err_fit.max() < 0.03 and err_ekf.max() > 1.0
    np.testing.assert_array_equal(x_fit[~late], x_ekf[~late])


def test_the_gap_fit_of_angles_only_has_its_own_process_noise():
    """A window of RA/Dec alone gets `GAP_FIT_SNC_ANGLES` (chosen on leo_optical's tuning
    runs), one with any range `GAP_FIT_SNC` (chosen on the ranged scenarios' tuning runs)."""
    from ssa_fusion.core.gaps import batch_gap

    def m(kind: Kind) -> Measurement:
        return Measurement(T0, np.zeros(3), np.eye(3), kind=kind, frame_id="maui")

    angles = [m(Kind.RA_DEC)] * 3
    assert batch_gap.gap_fit_options(angles).snc_psd == (batch_gap.GAP_FIT_SNC_ANGLES,) * 3
    assert batch_gap.gap_fit_options([*angles, m(Kind.RANGE_AZ_EL)]).snc_psd == \
        (batch_gap.GAP_FIT_SNC,) * 3
    assert batch_gap.GAP_FIT_ANGLES.snc_psd != batch_gap.GAP_FIT.snc_psd
    # ranges: the drag factor solved for with the state; angles: the state alone
    assert batch_gap.GAP_FIT.solve_for == ("drag_scale",) and batch_gap.GAP_FIT.force.drag
    assert batch_gap.GAP_FIT_ANGLES.solve_for == () and not batch_gap.GAP_FIT_ANGLES.force.drag
    assert batch_gap.GAP_FIT_ANGLES.consider == ()
    assert batch_gap.GAP_FIT.consider == ("accel_r", "accel_t", "accel_n")
    assert batch_gap.GAP_FIT.param_sigma[1:] == (batch_gap.GAP_FIT_ACCEL_SIGMA,) * 3


def test_a_batch_init_publisher_starts_each_pass_from_the_fit():
    """`GapFill.BATCH_INIT`: the gap is the batch fit's, as with `BATCH_FIT`, and at the first
    measurement of the next pass the EKF updates the fit's prediction there (state and
    covariance, `BatchGapForecaster.prior`) instead of its own two-body coasting, which has
    drifted by kilometres: the estimate is that Kalman update, and nearer the truth."""
    x0 = np.array([6778.0, 0.0, 0.0, 0.0, 4.8, 5.9])
    t = T0 + np.concatenate([k * 2400.0 + 60.0 * np.arange(10) for k in range(3)])
    t_next = float(t[-1] + 7200.0)  # the first measurement of the next pass
    truth = scipy_orbit(x0, np.append(t, t_next), j3_j4=True)
    c = EstimatorConfig(kind=Kind.POSITION, lift="none",
                        filter=FilterOptions().with_(p0_sigma=(1.0,) * 3 + (1e-2,) * 3,
                                                     q=1e-9))
    R = 1e-4 * np.eye(3)
    got = {}
    for f in (GapFill.BATCH_FIT, GapFill.BATCH_INIT):
        pub = GapPublisher.of(make_tracker(c), 60.0, f, c)
        rng = np.random.default_rng(5)
        z = truth[:, :3] + 0.01 * rng.standard_normal((t.size + 1, 3))
        for ti, zi in zip(t, z[:-1], strict=True):
            pub.measurement(Measurement(float(ti), zi, R, kind=Kind.POSITION, frame_id="gcrf"))
        prior = pub.forecaster.prior(t_next)  # the fit of the three passes, predicted
        last = pub.measurement(Measurement(t_next, z[-1], R, kind=Kind.POSITION,
                                           frame_id="gcrf")).estimates[-1]
        got[f] = (prior, last, z[-1])
    (x, P), init, z = got[GapFill.BATCH_INIT]
    K = P[:, :3] @ np.linalg.inv(P[:3, :3] + R)
    np.testing.assert_allclose(init.x, x + K @ (z - x[:3]), rtol=0, atol=1e-9)
    # round-off of the filter's (Joseph) update against this form, relative to the prior's
    np.testing.assert_allclose(init.P, P - K @ P[:3], rtol=0, atol=1e-11 * np.abs(P).max())
    coasted = got[GapFill.BATCH_FIT][1]
    err = {f: np.linalg.norm(e.x[3:] - truth[-1, 3:]) for f, e in
           ((GapFill.BATCH_FIT, coasted), (GapFill.BATCH_INIT, init))}
    assert err[GapFill.BATCH_INIT] < 0.1 * err[GapFill.BATCH_FIT], err  # velocity, km/s


def test_a_batch_init_publisher_keeps_its_own_state_until_the_fit_spans_its_passes():
    """Before the window holds `GAP_FIT_PASSES` passes (right after the initial orbit
    determination) `GapFill.BATCH_INIT` does not restart the EKF: the next pass's first
    estimate is the same as `BATCH_FIT`'s, whose EKF never restarts."""
    x0 = np.array([6778.0, 0.0, 0.0, 0.0, 4.8, 5.9])
    t = T0 + 60.0 * np.arange(10)  # one pass
    truth = scipy_orbit(x0, np.append(t, t[-1] + 7200.0), j3_j4=True)
    c = EstimatorConfig(kind=Kind.POSITION, lift="none",
                        filter=FilterOptions().with_(p0_sigma=(1.0,) * 3 + (1e-2,) * 3,
                                                     q=1e-9))
    last = {}
    for f in (GapFill.BATCH_FIT, GapFill.BATCH_INIT):
        pub = GapPublisher.of(make_tracker(c), 60.0, f, c)
        ms = [Measurement(float(ti), xi[:3], 1e-4 * np.eye(3), kind=Kind.POSITION,
                          frame_id="gcrf") for ti, xi in zip([*t, t[-1] + 7200.0], truth,
                                                              strict=True)]
        for m in ms[:-1]:
            pub.measurement(m)
        assert pub.forecaster.prior(ms[-1].t) is not None  # a fit it had
        last[f] = pub.measurement(ms[-1]).estimates[-1]
    np.testing.assert_array_equal(last[GapFill.BATCH_INIT].x, last[GapFill.BATCH_FIT].x)

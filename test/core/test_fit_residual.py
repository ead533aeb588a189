"""`core.gaps.fit_residual.FitResidualForecaster`: the gap fit corrected by what it leaves out.

The truth is scipy's (`references.scipy_orbit`: two-body + J2-J4, optionally a constant
along-track acceleration that the fit's model, J2-J4 + drag, lacks), at 800 km where the
fit's drag factor is unobserved (the air there is ~1e-3 of the ISS's), seen in passes of
10 m positions every 4 h for 2.5 days, then a gap of 12 h.
"""

import math

import numpy as np
import pytest
from references import scipy_orbit

from ssa_fusion.core.base.constants import MU_EARTH
from ssa_fusion.core.base.types import Kind, Measurement
from ssa_fusion.core.gaps.batch_gap import BatchGapForecaster
from ssa_fusion.core.gaps.estimator import EstimatorConfig, make_tracker, measurement_model
from ssa_fusion.core.gaps.fit_residual import FitResidualForecaster
from ssa_fusion.core.gaps.publisher import GapFill, GapPublisher
from ssa_fusion.core.gaps.step_aside import Choice, StepAside

T0 = 1.7e9 - (1.7e9 % 600.0)  # Unix s, on the forecast grid
PERIOD = 600.0  # s, the forecast grid
PASS_EVERY = 4 * 3600.0
PASSES = 16  # 2.5 days
LAST_GAP = 12 * 3600.0
SIGMA = 0.01  # km


def orbit() -> np.ndarray:
    """A circular orbit at 800 km altitude, inclined 51.6 deg (GCRF km, km/s)."""
    r = 6378.137 + 800.0
    v, i = math.sqrt(MU_EARTH / r), math.radians(51.6)
    return np.array([r, 0.0, 0.0, 0.0, v * math.cos(i), v * math.sin(i)])


def run(along_track: float, seed: int = 3, span_h: float = 0.0) -> dict[str, tuple]:
    """Drive a plain gap fit and the corrected one over the passes; return per arm
    (epochs of the last gap, forecast states, covariances, true states, forecasters).

    `span_h`: the fits' window, the passes of that many hours (at least three;
    `batch_gap.BatchGapForecaster.span_h`); 0: the last three passes (12 h here)."""
    t_meas = np.concatenate([T0 + k * PASS_EVERY + 60.0 * np.arange(10)
                             for k in range(PASSES)])
    gaps = [PERIOD * math.ceil((t_meas[10 * k + 9] + 600.0) / PERIOD)
            for k in range(PASSES - 1)]  # one forecast epoch in each gap: the fit is made
    last = t_meas[-1]
    t_gap = PERIOD * np.arange(math.ceil((last + 600.0) / PERIOD),
                               math.floor((last + LAST_GAP) / PERIOD) + 1)
    t_all = np.unique(np.concatenate([t_meas, gaps, t_gap]))
    truth = scipy_orbit(orbit(), t_all, j3_j4=True, rtn_accel=(0.0, along_track, 0.0))
    at = dict(zip(t_all.tolist(), truth, strict=True))
    model = measurement_model(EstimatorConfig(kind=Kind.POSITION))
    out = {}
    for name, cls in (("fit", BatchGapForecaster), ("fit_residual", FitResidualForecaster)):
        rng = np.random.default_rng(seed)
        f = cls(model, PERIOD, span_h=span_h)
        pending = list(gaps)
        for t in t_meas.tolist():
            while pending and pending[0] < t:
                f.forecast(pending.pop(0))
            x = at[t]
            f.on_measurement(Measurement(t, x[:3] + SIGMA * rng.standard_normal(3),
                                         SIGMA**2 * np.eye(3), kind=Kind.POSITION,
                                         frame_id="gcrf"))
            f.on_estimate(t, x + 0.02 * rng.standard_normal(6) * [1, 1, 1, 1e-3, 1e-3, 1e-3],
                          np.eye(6))
        got = [f.forecast(float(t)) for t in t_gap]
        assert all(g is not None for g in got), name
        out[name] = (t_gap, np.array([g[0] for g in got]), np.array([g[1] for g in got]),
                     np.array([at[float(t)] for t in t_gap]), f)
    return out


def errors(arm: tuple) -> np.ndarray:
    """Position errors (km) of an arm of `run` at its gap epochs."""
    _, x, _, truth, _ = arm
    return np.linalg.norm(x[:, :3] - truth[:, :3], axis=1)


@pytest.fixture(scope="module")
def pushed() -> dict[str, tuple]:
    """A truth with a constant along-track acceleration of 2e-9 km/s^2 (2 um/s^2), fits of
    the last three passes."""
    return run(2e-9)


def test_it_learns_an_acceleration_the_fit_lacks(pushed):
    """After 2.5 days of passes the corrected forecast through a 12 h gap is at least ten
    times closer to the truth than the fit's (median over the gap; the fit drifts by
    kilometres as 3/2 f t^2), and the surrogate fitted (its forecast is not the fit's)."""
    fit, corrected = errors(pushed["fit"]), errors(pushed["fit_residual"])
    assert pushed["fit_residual"][4].residual is not None
    assert np.median(corrected) < 0.1 * np.median(fit), (np.median(corrected),
                                                        np.median(fit))


def test_it_still_helps_a_fit_of_a_days_passes():
    """With the live window (the passes of the last 24 h, `batch_gap.GAP_FIT_SPAN_H`) the
    fit drifts less (0.21 km median over the gap, measured), and the corrected forecast is
    still at least twice as close (0.093 km measured)."""
    arms = run(2e-9, span_h=24.0)
    fit, corrected = errors(arms["fit"]), errors(arms["fit_residual"])
    assert arms["fit"][4].window[0].t < arms["fit"][4].window[-1].t - 20 * 3600.0  # a day
    assert np.median(corrected) < 0.5 * np.median(fit), (np.median(corrected),
                                                        np.median(fit))


def test_its_covariance_is_a_covariance_and_covers_its_error(pushed):
    """Every forecast covariance is symmetric positive definite, and the position NEES of
    the forecast against the truth is inside chi2(3)'s 99.9 % bound (16.3) at every
    gap epoch."""
    _, x, P, truth, _ = pushed["fit_residual"]
    np.testing.assert_allclose(P, np.swapaxes(P, 1, 2), rtol=0, atol=1e-12 * np.abs(P).max())
    assert (np.linalg.eigvalsh(P) > 0).all()
    d = x[:, :3] - truth[:, :3]
    nees = np.einsum("ki,ki->k", d, np.linalg.solve(P[:, :3, :3], d[:, :, None])[:, :, 0])
    assert nees.max() < 16.27, nees.max()


def test_with_nothing_to_learn_it_stays_with_the_fit():
    """A truth the fit's model holds (no extra acceleration): the corrected forecast's
    median error through the 12 h gap is within 20 % + 10 m of the fit's."""
    arms = run(0.0)
    fit, corrected = np.median(errors(arms["fit"])), np.median(errors(arms["fit_residual"]))
    assert corrected <= 1.2 * fit + 0.01, (corrected, fit)


def test_until_the_surrogate_can_fit_the_forecast_is_the_fit_s():
    """With the passes of less than a day (fewer anchors than the surrogate needs), the
    corrected forecaster publishes exactly the fit's forecast."""
    model = measurement_model(EstimatorConfig(kind=Kind.POSITION))
    t_meas = np.concatenate([T0 + k * PASS_EVERY + 60.0 * np.arange(10) for k in range(3)])
    truth = scipy_orbit(orbit(), t_meas, j3_j4=True)
    arms = [BatchGapForecaster(model, PERIOD), FitResidualForecaster(model, PERIOD)]
    t = PERIOD * math.ceil((t_meas[-1] + 3600.0) / PERIOD)
    got = []
    for f in arms:
        for ti, xi in zip(t_meas.tolist(), truth, strict=True):
            f.on_measurement(Measurement(ti, xi[:3], SIGMA**2 * np.eye(3),
                                         kind=Kind.POSITION, frame_id="gcrf"))
            f.on_estimate(ti, xi, np.eye(6))
        got.append(f.forecast(t))
    assert got[0] is not None and got[1] is not None
    assert arms[1].residual is None
    np.testing.assert_array_equal(got[0][0], got[1][0])
    np.testing.assert_array_equal(got[0][1], got[1][1])


def test_the_filter_s_fit_residual_fill_is_this_forecaster_and_restarts_each_pass():
    """``gap_forecast: fit_residual`` publishes this forecaster's gap and, as ``batch_init``,
    starts the EKF of each pass from its prior; ``batch_init`` keeps the plain fit."""
    c = EstimatorConfig(kind=Kind.POSITION)
    pub = GapPublisher.of(make_tracker(c), 60.0, GapFill.FIT_RESIDUAL, c)
    assert isinstance(pub.forecaster, FitResidualForecaster) and pub.restart
    plain = GapPublisher.of(make_tracker(c), 60.0, GapFill.BATCH_INIT, c)
    assert type(plain.forecaster) is BatchGapForecaster and plain.restart
    assert not GapPublisher.of(make_tracker(c), 60.0, GapFill.BATCH_FIT, c).restart


# --------------------------------------------------------------------------------------------
# Stepping aside: the correction is used only where it predicted the last passes better
# --------------------------------------------------------------------------------------------
def test_step_aside_rule_counts_and_picks_the_better_predictor():
    """On positions with a known sigma, a prediction 3 sigma off against one 1 sigma off: the
    smaller misfit wins, over the last two passes (an older win is forgotten), nothing
    validated is the plain fit, and every decision is counted."""
    model = measurement_model(EstimatorConfig(kind=Kind.POSITION))
    x = np.array([7000.0, 0.0, 0.0, 0.0, 7.5, 0.0])
    ms = [Measurement(float(t), x[:3], SIGMA**2 * np.eye(3), kind=Kind.POSITION,
                      frame_id="gcrf") for t in range(5)]
    near = x + np.array([SIGMA, 0, 0, 0, 0, 0])
    far = x + np.array([3 * SIGMA, 0, 0, 0, 0, 0])
    step = StepAside(passes=2)
    assert step.decide() == Choice.UNVALIDATED
    step.validate(ms, model, np.tile(far, (5, 1)), np.tile(near, (5, 1)))
    assert step.misfits[-1] == pytest.approx((45.0, 5.0))  # 5 x 3^2, 5 x 1^2
    assert step.decide() == Choice.CORRECTED
    for _ in range(2):  # two passes where the plain fit predicted better
        step.validate(ms, model, np.tile(near, (5, 1)), np.tile(far, (5, 1)))
    assert step.decide() == Choice.PLAIN
    step.validate(ms, model, np.tile(far, (5, 1)), np.tile(near, (5, 1)))
    assert step.choice() == Choice.PLAIN  # 5 + 45 against 45 + 5: a tie is no win
    step.validate(ms, model, np.tile(far, (5, 1)), np.tile(near, (5, 1)))
    assert step.decide() == Choice.CORRECTED
    assert step.counts == {Choice.UNVALIDATED: 1, Choice.CORRECTED: 2, Choice.PLAIN: 1}
    step.validate(ms, model, np.full((5, 6), np.nan), np.tile(near, (5, 1)))
    assert len(step.misfits) == 2  # a prediction that failed scores nothing


def test_a_correction_that_learnt_the_truth_is_used(pushed):
    """The along-track push of `pushed`: the correction predicted the last passes better,
    so the last gap's forecast is the corrected one (and counted so)."""
    f = pushed["fit_residual"][4]
    assert f.step.last == Choice.CORRECTED and f.residual is f.learned is not None
    assert f.choices[Choice.CORRECTED] >= 1


class _Harmful(FitResidualForecaster):
    """A forecaster whose learned correction is 20 km off along x (a correction gone wrong)."""

    def _learn(self) -> None:
        super()._learn()
        for r in (self.learned, self.residual):
            if r is not None and not getattr(r, "harmed", False):
                predict = r.predict

                def off(t, predict=predict):
                    xs, Ps = predict(t)
                    return xs + np.array([20.0, 0, 0, 0, 0, 0]), Ps

                r.predict = off
                r.harmed = True
        if self.residual is not None:  # the table was corrected with the unharmed one
            grid = np.array(sorted(self.table))
            xs, Ps = self.residual.predict(grid)
            self.table = {float(g): (xs[i], Ps[i]) for i, g in enumerate(grid)}


def test_a_correction_that_hurts_steps_aside_to_the_fit(monkeypatch):
    """A correction 20 km off: validated on the passes it predicts, it loses to the plain fit
    and steps aside, so the last gap's forecast is exactly the plain fit's (never worse than
    it), and the choices say so."""
    import test_fit_residual as me

    monkeypatch.setattr(me, "FitResidualForecaster", _Harmful)
    arms = run(2e-9)
    f = arms["fit_residual"][4]
    assert isinstance(f, _Harmful) and f.learned is not None
    assert f.step.last == Choice.PLAIN and f.residual is None
    assert f.choices[Choice.PLAIN] >= 1
    np.testing.assert_array_equal(arms["fit_residual"][1], arms["fit"][1])


def test_the_covariance_published_is_the_fit_s_times_the_calibrated_factor(pushed):
    """The gap fit publishes its fit's covariance times the factor its last passes measured
    (`calibration`; never below 1)."""
    t_gap, x, P, _, f = pushed["fit"]
    k = f.scale.factor(t_gap - f.fitted_t)
    assert len(f.scale.estimates) >= 3 and np.all(k >= 1.0)
    xs, Ps = f.fit.predict(t_gap)
    np.testing.assert_allclose(x, xs, rtol=0, atol=1e-9)
    np.testing.assert_allclose(P, Ps * k[:, None, None], rtol=1e-12, atol=0)


def test_each_pass_scores_the_last_fits_at_their_own_horizons(pushed):
    """The calibration scores the last `batch_gap.GAP_FIT_SCORED_FITS` fits on each pass: the
    last pass's estimates are at the horizons from each fit's epoch to the pass's mean epoch,
    so they differ by the spans between the fits' epochs (the two fits kept in ``older``)."""
    f = pushed["fit"][4]
    assert f.scored_fits == 3 and len(f.older) == 2
    (t_b, _), (t_c, _) = f.older
    h = [a for a, _ in f.scale.estimates][-3:]
    assert h[0] > h[1] > h[2] > 0.0
    assert h[1] - h[2] == pytest.approx(t_c - t_b, abs=1e-6)
    assert len(f.scale.estimates) == f.scale.passes == 18  # six passes' worth

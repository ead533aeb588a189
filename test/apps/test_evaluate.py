"""`evaluate` on synthetic bag data (no ROS): every arm is scored over the whole gap."""

import numpy as np
import pytest
from gap_bags import around_a_gap

from ssa_fusion.apps import evaluate
from ssa_fusion.core.base import metrics, types
from ssa_fusion.core.filter.ekf import process_noise
from ssa_fusion.core.motion import kepler
from ssa_fusion.evaluation.arms import ArmName
from ssa_fusion.params import settings
from ssa_fusion.sim import scenarios

TRACK, GAP, COVERED, AFTER = 40, 40, 10, 5  # epochs; estimates cover the gap's first 10
OFFSET = np.array([1.0, -0.5, 0.2, 1e-3, -2e-3, 5e-4])  # the estimates' error, km, km/s


def synthetic() -> evaluate.BagData:
    """Two-body truth, noise-free positions, estimates that stop a quarter into the gap."""
    data, epochs = around_a_gap(TRACK, GAP, AFTER)
    for i, ti, xi, in_gap in epochs:
        if i < TRACK + COVERED:
            source = types.UpdateSource.FORECAST if in_gap else types.UpdateSource.SENSOR
            data.estimates.append(types.StateEstimate(ti, xi + OFFSET, 1e-2 * np.eye(6),
                                                      update_source=source))
    return data


def test_dmd_ekf_is_scored_over_the_whole_gap_with_the_filters_prediction():
    data = synthetic()
    ev = evaluate.evaluate(data).gap
    last = data.estimates[-1]  # the last estimate, at the gap's 10th epoch
    x_true = np.array([e.x for e in data.truth[TRACK:TRACK + GAP]])
    expected = np.array([e.x for e in data.estimates[TRACK:]] + [
        kepler.propagate(last.x, t - last.t)[0] for t in ev.t[COVERED:]])
    full = metrics.epsilon(expected, x_true)
    subset = metrics.epsilon(expected[:COVERED], x_true[:COVERED])
    assert full > 1.5 * subset  # the propagated half is the harder one
    assert ev.scores[ArmName.DMD_EKF].epsilon == pytest.approx(full, rel=1e-9)
    # the covariance is the filter's prediction's too, chained epoch by epoch through the
    # gap as the filter node publishes it: P <- F P F' + Q(dt) at every cadence step
    q = scenarios.get("iss_j2_pos").q
    x, P, t_prev = last.x, last.P, last.t
    for t in ev.t[COVERED:]:
        x, F = kepler.propagate(x, t - t_prev)
        P = F @ P @ F.T + process_noise(t - t_prev, q, dim=3)
        t_prev = t
    np.testing.assert_allclose(ev.arms[ArmName.DMD_EKF].P[-1], P, rtol=1e-9)
    # chaining differs from one jump over the whole gap: the test tells them apart
    F = kepler.propagate(last.x, ev.t[-1] - last.t)[1]
    one_jump = F @ last.P @ F.T + process_noise(ev.t[-1] - last.t, q, dim=3)
    assert not np.allclose(P, one_jump, rtol=1e-3)
    assert ev.coverage == COVERED / GAP
    assert ev.predicted == GAP - COVERED
    assert f"{GAP - COVERED} scored from" in evaluate.table(evaluate.evaluate(data))


def test_settings_come_from_the_bag_else_the_kinds_default(tmp_path):
    data = synthetic()
    assert evaluate.evaluate(data).settings.origin.startswith(
        "position, from the data (")  # the set-up the data call for (filter_setup)
    assert "the paper's position filter (scenario iss_j2_pos)" in \
        evaluate.evaluate(data).settings.origin
    est = scenarios.get("iss_j2_pos").estimator()
    recorded = settings.config_message("filter", est.with_(filter=est.filter.with_(q=3e-9)))
    data.config.append(recorded)
    ev = evaluate.evaluate(data)
    assert ev.settings.origin.startswith("recorded")
    assert ev.settings.estimator.filter.noise.q == 3e-9
    params = tmp_path / "p.yaml"
    params.write_text("/**:\n  ros__parameters:\n    kind: position\n"
                      "filter:\n  ros__parameters:\n    q: 0.002\n    gate: 0.0\n")
    ev = evaluate.evaluate(data, params_file=params)
    assert ev.settings.origin == f"params file {params}"
    assert ev.settings.estimator.filter.noise.q == pytest.approx(2e-9)  # m^2/s^3 -> km^2/s^3
    assert ev.settings.estimator.filter.noise.gate is None


def test_sample_bag_coast_matches_an_independent_kepler_propagation():
    """On the recorded default scenario: `coast` is the last pre-gap estimate propagated by
    the Keplerian model (checked against scipy's integration of two-body motion, within
    10 % of ε), and `placeholder` (Monte Carlo from the same estimate) is close to it."""
    from pathlib import Path

    from scipy.integrate import solve_ivp

    sample = Path(__file__).resolve().parents[2] / "bags" / "sample_iss_j2_rae"
    data = evaluate.load(sample)
    ev = evaluate.evaluate(data).gap
    live = {e.t: e for e in data.estimates if e.update_source == types.UpdateSource.SENSOR}
    start = live[max(t for t in live if t < ev.t[0])]
    mu = 398600.4418

    def f(_t, y):
        return np.concatenate([y[3:], -mu * y[:3] / np.linalg.norm(y[:3]) ** 3])

    sol = solve_ivp(f, (start.t, ev.t[-1]), start.x, t_eval=ev.t, rtol=1e-12, atol=1e-12,
                    method="DOP853")
    independent = metrics.epsilon(sol.y.T, ev.truth)
    coast = ev.scores[ArmName.COAST].epsilon
    assert coast == pytest.approx(independent, rel=0.1)
    assert ev.scores[ArmName.PLACEHOLDER].epsilon == pytest.approx(coast, rel=0.5)
    assert set(ev.scores) == set(ArmName)  # all five arms, j2_coast included

"""`evaluation.residuals`: pre-fit residuals, NIS coverage, passes and σ on small hand cases."""

import math

import numpy as np
import pytest
from scipy.stats import chi2

from ssa_fusion.core.base.types import Kind, Measurement, StateEstimate, UpdateSource
from ssa_fusion.core.filter.ekf import process_noise
from ssa_fusion.core.motion import kepler
from ssa_fusion.evaluation import residuals as rs
from ssa_fusion.sim import scenarios

X0 = np.array([7000.0, 0.0, 0.0, 0.0, 7.5, 0.0])


def test_the_pre_fit_residual_is_the_measurement_minus_the_prediction_of_the_last_estimate():
    """Position measurements and a Kepler filter (iss_j2_pos's): the residual at t = 10 s is
    z minus the estimate of t = 0 propagated 10 s, S = F P F' + Q(10 s) + R. The first
    estimate has no prior, the IOD estimate (NIS 0) no innovation, a measurement the filter
    did not fuse no residual."""
    c = scenarios.get("iss_j2_pos").estimator()
    P0 = np.diag([1e-2, 1e-2, 1e-2, 1e-6, 1e-6, 1e-6])
    e0 = StateEstimate(0.0, X0, P0, update_source=UpdateSource.SENSOR)  # the IOD
    x1, F = kepler.propagate(X0, 10.0)
    z = x1[:3] + np.array([0.03, -0.04, 0.0])
    Rm = 0.01 * np.eye(3)
    e1 = StateEstimate(10.0, x1, P0, update_source=UpdateSource.SENSOR, nis=4.2)
    pred = StateEstimate(15.0, x1, P0)  # a prediction: not a prior of anything
    ms = [Measurement(0.0, X0[:3], Rm), Measurement(10.0, z, Rm),
          Measurement(20.0, z, Rm)]  # t = 20: not fused
    got = rs.residuals(c, [pred, e1, e0], ms)
    assert len(got) == 1
    r = got[0]
    S = (F @ P0 @ F.T + process_noise(10.0, c.filter.noise.q))[:3, :3] + Rm
    np.testing.assert_allclose(r.y, [0.03, -0.04, 0.0], atol=1e-9)
    np.testing.assert_allclose(r.sigma, np.sqrt(np.diag(S)), rtol=1e-9)
    np.testing.assert_allclose(r.sigma_r, [0.1, 0.1, 0.1])
    assert r.nis == pytest.approx(r.y @ np.linalg.solve(S, r.y), rel=1e-9)
    assert r.nis_filter == 4.2 and r.station == "gcrf" and r.kind == Kind.POSITION


def res(t, normalised, station="a", nis=1.0):
    n = np.asarray(normalised, float)
    return rs.Residual(t, station, Kind.RANGE_AZ_EL, 2.0 * n, np.full(n.size, 2.0),
                      np.ones(n.size), nis, nis)


def radar(t, el, station="a"):
    return Measurement(t, np.array([1000.0, 0.0, el]), np.eye(3), kind=Kind.RANGE_AZ_EL,
                       frame_id=station)


def test_passes_by_hand():
    """Station a: a pass at 0-20 s (elevations 0.1, 0.5, 0.3 rad; all fused; residuals
    (1, -1, 2) σ and (0, 1, 1) σ: RMS √(8/6)) and one at 1000-1010 s (one fused, no
    residual); station b: a pass at 5-15 s (none fused). Cut at 600 s; the network's one gap
    is 20-1000 s."""
    ms = [radar(0, 0.1), radar(10, 0.5), radar(20, 0.3), radar(1000, 0.2), radar(1010, 0.2),
          radar(5, 0.4, "b"), radar(15, 0.4, "b")]
    made = [res(10.0, [1, -1, 2]), res(20.0, [0, 1, 1])]
    rows = rs.pass_rows(ms, [0.0, 10.0, 20.0, 1000.0], made)
    assert [(p.station, p.t_start, p.t_end, p.fused, p.not_fused, p.residuals) for p in rows] \
        == [("a", 0, 20, 3, 0, 2), ("b", 5, 15, 0, 2, 0), ("a", 1000, 1010, 1, 1, 0)]
    assert rows[0].max_elevation_deg == pytest.approx(math.degrees(0.5))
    assert rows[0].rms_normalised == pytest.approx(math.sqrt(8 / 6))
    assert math.isnan(rows[1].rms_normalised) and math.isnan(rows[2].rms_normalised)
    assert rs.gaps(ms) == [(20.0, 1000.0)]
    optical = Measurement(0.0, np.zeros(2), np.eye(2), kind=Kind.RA_DEC, frame_id="o")
    assert math.isnan(rs.pass_rows([optical], [], [])[0].max_elevation_deg)  # none measured


def test_nis_inside_the_two_sided_95_percent_band_of_each_dimension():
    """3 dof: band [0.216, 9.348]: 0.1 and 10 out, 1 and 5 in; 2 dof: [0.0506, 7.378]:
    0.06 in, 8 out. 3 of 6 inside."""
    values = [rs.Nis(float(t), "a", 3, v) for t, v in enumerate((0.1, 1.0, 10.0, 5.0))]
    values += [rs.Nis(10.0 + i, "o", 2, v) for i, v in enumerate((0.06, 8.0))]
    s = rs.nis_summary(values)
    assert s.n == 6 and s.inside == 3 and s.fraction == 0.5
    for dof in (2, 3):
        lo, hi = s.band[dof]
        assert chi2.cdf(lo, dof) == pytest.approx(0.025) and chi2.cdf(hi, dof) == pytest.approx(
            0.975)
    assert math.isnan(rs.nis_summary([]).fraction)


def test_published_nis_of_the_fused_real_measurements_only():
    """The IOD estimate (NIS 0), a prediction, a forecast update and an unfused measurement
    give none; the dimension is the measurement's."""
    es = [StateEstimate(0.0, X0, update_source=UpdateSource.SENSOR),
          StateEstimate(10.0, X0, update_source=UpdateSource.SENSOR, nis=2.5),
          StateEstimate(15.0, X0), StateEstimate(20.0, X0, update_source=UpdateSource.FORECAST,
                                                 nis=1.0)]
    ms = [Measurement(t, np.zeros(2), np.eye(2), kind=Kind.RA_DEC, frame_id="o")
          for t in (0.0, 10.0, 20.0, 30.0)]
    assert rs.published_nis(es, ms) == [rs.Nis(10.0, "o", 2, 2.5)]


def test_position_sigma_is_the_root_of_the_trace():
    es = [StateEstimate(5.0, X0, np.diag([1.0, 4.0, 4.0, 9.0, 9.0, 9.0])),
          StateEstimate(1.0, X0, np.diag([0.25, 0.0, 0.0, 1.0, 1.0, 1.0]))]
    t, s = rs.position_sigma(es)
    np.testing.assert_allclose(t, [1.0, 5.0])
    np.testing.assert_allclose(s, [0.5, 3.0])

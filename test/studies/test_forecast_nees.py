"""Tests for ssa_fusion.studies.catalog_gaps.forecast_nees: the position NEES of forecasts
against the SGP4 truth, by fit, on forecasts made from the truth with known errors."""

import numpy as np

from ssa_fusion.core.catalog.gap_bank import GapForecast
from ssa_fusion.core.motion.element_sets import catalog_states
from ssa_fusion.formats import element_sets as catalog_io
from ssa_fusion.studies.catalog_gaps import SAMPLE, forecast_nees


def test_nees_of_known_errors_split_by_fit():
    entry = catalog_io.read_catalog(SAMPLE)[0]
    t0 = float(entry.satrec.jdsatepoch - 2440587.5 + entry.satrec.jdsatepochF) * 86400.0
    t = t0 + 600.0 * np.arange(1, 5)
    truth = catalog_states([entry], t).x[0]
    P = np.diag([0.01] * 3 + [1e-6] * 3)  # 100 m sigma
    # position errors of 0.1, 0.2, 0.3 and 0.5 km along x: NEES 1, 4, 9, 25
    errs = [0.1, 0.2, 0.3, 0.5]
    fc = [GapForecast(entry.object_id, float(ti), xt + np.r_[e, 0, 0, 0, 0, 0], P,
                      physics=i < 2)
          for i, (ti, xt, e) in enumerate(zip(t, truth, errs, strict=True))]
    got = forecast_nees([entry], fc)
    assert got["all"]["forecasts"] == 4
    assert got["all"]["in_bound"] == 0.5  # 9 and 25 > chi2(3) 95 % = 7.81
    assert got["physics"]["in_bound"] == 1.0
    np.testing.assert_allclose(got["all"]["nees_median"], 6.5, rtol=1e-6)
    np.testing.assert_allclose(got["physics"]["nees_median"], 2.5, rtol=1e-6)
    np.testing.assert_allclose(got["learned"]["error_km_median"], 0.4, rtol=1e-6)
    assert got["learned"]["in_bound"] == 0.0
    np.testing.assert_allclose(got["bound"], 7.814727903251179)

"""`studies.sky_study.fit_ratios`: how many times smaller fit_residual's gap errors are."""

import math

from ssa_fusion.studies.sky_study import fit_ratios


def run(fit: float, corrected: float, fit_long: float, corrected_long: float) -> dict:
    return {"published": {"batch_fit": {"err_median_km": fit, "long_err_median_km": fit_long},
                          "fit_residual": {"err_median_km": corrected,
                                           "long_err_median_km": corrected_long}}}


def test_median_of_run_ratios_and_ratio_of_medians_skip_runs_without_long_gaps():
    runs = [run(0.2, 0.1, 0.4, 0.1), run(0.3, 0.1, math.nan, math.nan),
            run(0.1, 0.1, 0.3, 0.2)]
    r = fit_ratios(runs)
    assert r["all gap epochs: median of run ratios"] == 2.0  # ratios 2, 3, 1
    assert r["all gap epochs: ratio of medians"] == 2.0  # 0.2 / 0.1
    assert r["gaps > 12 h: median of run ratios"] == 2.75  # ratios 4, 1.5
    assert math.isclose(r["gaps > 12 h: ratio of medians"], 0.35 / 0.15)
    none = fit_ratios([run(0.2, 0.1, math.nan, math.nan)])
    assert none["gaps > 12 h: median of run ratios"] is None
    assert none["gaps > 12 h: ratio of medians"] is None

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


def _published(err: float, long: float, cpu: float, nees: float = 2.0,
               cover: float = 0.95, choices: dict | None = None) -> dict:
    return {"err_median_km": err, "long_err_median_km": long, "cpu_s": cpu,
            "nees_median": nees, "nees_in_95": cover, "choices": choices or {}}


def test_targets_49_ratios_cost_nees_and_choices_by_hand():
    """`sky_study.targets_49` on three hand-made runs: each measure computed here from its
    definition (medians over runs; ratios of medians; the worst run)."""
    from ssa_fusion.core.gaps.publisher import GapFill
    from ssa_fusion.studies.sky_study import targets_49

    def one(cheap, corr, full, cpu_cheap, cpu_corr, cpu_full, choices):
        return {"published": {"batch_init": _published(cheap[0], cheap[1], cpu_cheap, 3.0),
                              "fit_residual": _published(corr[0], corr[1], cpu_corr,
                                                         choices=choices),
                              "full_fit": _published(full[0], full[1], cpu_full)}}

    runs = [one((4.0, 8.0), (2.0, 4.0), (0.1, 0.2), 1.0, 1.2, 5.0, {"corrected": 3, "plain": 1}),
            one((2.0, 6.0), (2.2, 3.0), (0.1, 0.1), 2.0, 2.0, 8.0, {"corrected": 0, "plain": 4}),
            one((3.0, 4.0), (3.0, 8.0), (0.2, 0.4), 1.5, 3.0, 9.0, {"corrected": 1, "plain": 2})]
    t = targets_49(runs, GapFill.BATCH_INIT)
    assert t["cheap_over_corrected_long"] == 2.0  # run ratios 2, 2, 0.5
    assert math.isclose(t["corrected_over_cheap_all"], 2.2 / 3.0)
    assert math.isclose(t["corrected_over_cheap_long"], 4.0 / 6.0)
    assert math.isclose(t["corrected_over_cheap_worst_run"], 1.1)  # 2.2 / 2.0
    assert math.isclose(t["cpu_corrected_over_cheap"], 2.0 / 1.5)
    assert math.isclose(t["corrected_over_full_long"], 4.0 / 0.2)
    assert math.isclose(t["cheap_over_full_long"], 6.0 / 0.2)
    assert math.isclose(t["cpu_full_over_cheap"], 8.0 / 1.5)
    assert t["nees_median"] == 3.0 and t["nees_in_95"] == 0.95 and t["live"] == "batch_init"
    assert t["choices"] == {"corrected": 4, "plain": 7}

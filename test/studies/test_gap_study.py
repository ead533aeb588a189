"""The gap study's cases: the sky study's geometry (orbit turned, sites drawn) per seed."""

import pytest

from ssa_fusion.sim import sky
from ssa_fusion.studies import gap_study, sky_study


class _SimulatedError(Exception):
    """Raised by the stand-in simulator once it has the scenario (nothing is simulated)."""


@pytest.mark.parametrize("name", ["iss_radar_columbus", "iss_network"])
def test_each_seed_runs_the_sky_studys_case_turned_and_with_its_sites(monkeypatch, name):
    seen: list[sky.SkyScenario] = []

    def simulate(s, seed):
        seen.append(s)
        raise _SimulatedError

    monkeypatch.setattr(sky, "simulate_sky", simulate)
    for seed in (101, 102):
        with pytest.raises(_SimulatedError):
            gap_study.run_case(gap_study.Case(name, 8.0, seed, variants=()))
    assert seen == [sky_study.case_scenario(name, 8.0, s) for s in (101, 102)]
    base = sky.SKY_SCENARIOS[name]
    assert seen[0] != seen[1]  # the seeds turn the orbit: no two cases share their passes
    assert all(s.t0 == base.t0 + 8 * 3600.0 for s in seen)
    assert all(s != base.with_(t0=base.t0 + 8 * 3600.0) for s in seen)

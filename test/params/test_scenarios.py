"""`params.scenarios` is the simulator's scenarios written out: the names sensor_sim's
``scenario`` takes and the defaults it computes from them are `sim`'s."""

import pytest

from ssa_fusion.params import scenarios as written
from ssa_fusion.params.defaults import SENSOR_SIM
from ssa_fusion.params.tables.sensor_sim import PARAMETERS
from ssa_fusion.sim import scenarios, sky


def test_the_names_are_the_orbit_scenarios_then_the_real_sky_ones_in_order():
    orbits = [n for n, s in scenarios.SCENARIOS.items() if s.is_orbit]
    assert list(written.PAPER_SCENARIOS) == orbits
    assert list(written.SKY_SCENARIOS) == list(sky.SKY_SCENARIOS)
    assert (*orbits, *sky.SKY_SCENARIOS) == written.NAMES
    assert written.DEFAULT_LIVE == scenarios.DEFAULT_LIVE.name == SENSOR_SIM.scenario


@pytest.mark.parametrize("name", list(written.PAPER_SCENARIOS))
def test_a_paper_scenario_s_timing_is_sim_s(name):
    s, t = scenarios.get(name), written.PAPER_SCENARIOS[name]
    assert (t.cadence_s, t.track_s, t.gap_s, t.after_s) == (s.cadence_s, s.track_s, s.gap_s,
                                                            s.after_s)


@pytest.mark.parametrize("name", list(written.SKY_SCENARIOS))
def test_a_real_sky_scenario_s_truth_cadence_is_sim_s(name):
    assert written.SKY_SCENARIOS[name] == sky.SKY_SCENARIOS[name].truth_cadence_s


@pytest.mark.parametrize("name", written.NAMES)
def test_the_computed_defaults_are_the_scenario_s(name):
    """What the node computes at start for `scenario` = name (real sky: the default live
    scenario's gap, its own truth cadence)."""
    values = {"scenario": name}
    computed = {p.name: p.default.compute(values) for p in PARAMETERS
                if not isinstance(p.default, (str, int, float, bool, tuple))}
    paper = scenarios.DEFAULT_LIVE if name in sky.SKY_SCENARIOS else scenarios.get(name)
    cadence = (sky.SKY_SCENARIOS[name].truth_cadence_s if name in sky.SKY_SCENARIOS
               else paper.cadence_s)
    assert computed == {"object_id": name, "cadence": cadence, "gap_start": paper.track_s,
                        "gap_length": paper.gap_s, "after_gap": paper.after_s}


def test_the_scenario_check_refuses_a_scenario_that_is_not_an_orbit():
    assert PARAMETERS["scenario"].reason("iss_j2_rae") is None
    assert "must be one of" in PARAMETERS["scenario"].reason("pendulum")


def test_the_truths_written_out_are_the_world_s():
    """``truth`` takes exactly `sim.world.TruthModel`'s values (the parameters may not import
    the simulated world)."""
    from ssa_fusion.sim.world import TruthModel

    assert tuple(str(t) for t in TruthModel) == written.TRUTHS
    assert PARAMETERS["truth"].reason("high_fidelity") is None
    assert "must be one of" in PARAMETERS["truth"].reason("sgp8")

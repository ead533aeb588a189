"""`params.settings`: the one translation between ROS parameters (SI) and EstimatorConfig;
config/default.yaml read offline is the default scenario's estimator (bad params files:
test_params_file.py)."""

import json
from pathlib import Path

import pytest

from ssa_fusion.core.gaps import estimator as config
from ssa_fusion.params import checks, settings
from ssa_fusion.params.params_file import load_params_file
from ssa_fusion.sim import scenarios

CONFIG = Path(__file__).resolve().parents[2] / "config" / "default.yaml"


def same(a, b) -> bool:
    """Equal settings up to the last bits of a unit conversion (12 significant digits)."""
    def rounded(c):
        return json.loads(json.dumps(config.to_dict(c)),
                          parse_float=lambda v: float(f"{float(v):.12g}"))

    return rounded(a) == rounded(b)


def test_params_round_trip_in_si_units():
    c = scenarios.DEFAULT_LIVE.estimator()
    f, s = settings.filter_params(c), settings.surrogate_params(c)
    assert f["p0_sigma"][0] == pytest.approx(1000.0) and f["q"] == pytest.approx(0.1)  # m, m^2/s^3
    assert s["retrain_period"] == 0.0  # never = 0 as a parameter
    assert same(settings.estimator_from(f, s), c)


def test_default_yaml_is_the_default_live_scenario():
    """config/default.yaml, read as a ROS params file, is the default scenario's estimator
    (what `ssa-fusion live` runs)."""
    assert same(load_params_file(CONFIG), scenarios.DEFAULT_LIVE.estimator())


def test_recorded_settings_merge_both_nodes_last_message():
    c = scenarios.DEFAULT_LIVE.estimator()
    changed = c.with_(filter=c.filter.with_(q=7e-8))
    msgs = [settings.config_message("filter", c), settings.config_message("surrogate", c),
            settings.config_message("filter", changed)]  # a `ros2 param set` during the run
    assert settings.recorded_estimator(msgs) == changed
    assert settings.recorded_estimator([]) is None
    with pytest.raises(ValueError, match="malformed /ssa/config"):
        settings.recorded_estimator(["{not json"])


def test_a_filter_of_ra_dec_alone_gets_no_eci_lift():
    """`ros2 run ssa_fusion filter -p kind:=ra_dec` (no surrogate parameters): the surrogate's
    default lift (eci, for range/az/el) must not apply to angles-only measurements."""
    from ssa_fusion.core.base.types import Kind
    from ssa_fusion.core.gaps.estimator import Lift

    c = settings.estimator_from({"kind": "ra_dec", "station": "socorro"}, {})
    assert c.kind == Kind.RA_DEC and c.lift == Lift.NONE
    assert settings.estimator_from({"kind": "range_az_el"}, {}).lift == Lift.ECI


def test_station_and_sites_parameters(tmp_path):
    """The filter's and surrogate's `station` may name a site of their `sites` file; the
    rule over both names what is wrong, and so does the check of `sites`."""
    example = str(CONFIG.parent / "sites" / "example.yaml")
    c = settings.estimator_from({"station": "nordlys", "sites": example}, {})
    assert c.station == "nordlys" and [s.name for s in c.sites] == ["nordlys", "kestrel",
                                                                    "pampa-obs"]
    assert settings.estimator_problem("filter", {**settings.filter_params(c),
                                                 "sites": ""}) is not None
    assert checks.sites_problem({"station": "nordlys,tira,", "sites": example}) is None
    said = checks.sites_problem({"station": "nordlys", "sites": ""})
    assert said is not None and "station 'nordlys' unknown" in said
    bad = tmp_path / "bad.yaml"
    bad.write_text("sites:\n  - {id: x, latitude_deg: 91}\n")
    said = checks.SITES(str(bad))
    assert said is not None and "site 'x': longitude_deg: missing" in said
    assert checks.SITES("") is None
    assert checks.STATION_IDS("nordlys") is None and checks.STATION_IDS(",") is not None

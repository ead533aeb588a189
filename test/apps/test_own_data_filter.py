"""Your own data chooses its filter: a telescope-only TDM is estimated without naming a
scenario; the choice is said, and `--filter` overrides it; no estimate is never a success.

The TDM is of the simulated sky's two optical sites (leo_optical's maui and socorro, 72 h,
a sun-synchronous object): written into a bag, exported as a CCSDS TDM, imported back, as a
user's own telescope data would come. Before, `replay` took it to the paper's position
filter and published 0 estimates with exit 0 and no hint.
"""

from __future__ import annotations

import numpy as np
import pytest

from ssa_fusion.apps import ccsds, cli, evaluate
from ssa_fusion.apps.filter_setup import DataMix, FilterSetup, chosen_estimator, data_setup
from ssa_fusion.core.base.types import Kind, Measurement, Source, UpdateSource
from ssa_fusion.sim import sky

HOURS = 72.0


@pytest.fixture(scope="module")
def telescope_tdm(tmp_path_factory):
    """(the TDM file, the simulated sky): 300 RA/Dec of two telescopes over 72 h."""
    d = tmp_path_factory.mktemp("telescopes")
    s = sky.SKY_SCENARIOS["leo_optical"]
    sim = sky.simulate_sky(s.with_window(s.t0, HOURS * 3600.0), seed=1, object_id="SAT-4242")
    ccsds.write_measurement_bag(d / "sim", sim.real)
    assert cli.main(["export", "tdm", str(d / "sim"), "--out", str(d / "telescopes.tdm")]) == 0
    return d / "telescopes.tdm", sim


def test_a_telescope_only_tdm_is_estimated_without_naming_a_scenario(telescope_tdm, tmp_path,
                                                                     capsys):
    """import tdm -> the replay it suggests -> estimates on the object's orbit.

    Bound: the smoothed positions at the fused epochs are within 0.2 km of the simulated
    truth in the median (angles of 1-2 arcsec at ranges of 1000-3000 km are 10-30 m across
    the line of sight): measured 0.021, 0.012, 0.033 km over seeds 1-3 (the largest, 38-110
    km, at a first pass's initial orbit).
    """
    tdm, sim = telescope_tdm
    capsys.readouterr()
    bag = tmp_path / "imported"
    assert cli.main(["import", "tdm", str(tdm), "--bag", str(bag)]) == 0
    out = capsys.readouterr().out
    n = len(sim.real)
    assert f"{n} ra/dec measurements of SAT-4242 from maui, socorro" in out, out
    suggested = out.splitlines()[-1]
    assert suggested.startswith(f"next: `ssa-fusion replay {bag} --offline --smooth` (about "), \
        suggested
    assert "at --rate 1)" in suggested  # beside the ROS replay's own time

    replayed = tmp_path / "replayed"
    assert cli.main(["replay", str(bag), "--offline", "--smooth", "--out", str(replayed)]) == 0
    out = capsys.readouterr().out
    assert (f"replay: estimator settings: optical, from the data ({n} ra/dec from maui, "
            "socorro; --filter radar|optical|network|position or --params-file choose "
            "another): the real-sky filter for the stations of its measurements (maui, "
            "socorro)") in out, out
    data = evaluate.load(replayed)
    fused = [e for e in data.estimates if e.update_source == UpdateSource.SENSOR]
    assert len(fused) > 0.7 * n, (len(fused), n)
    t = np.array([e.t for e in data.smoothed])
    err = np.linalg.norm(np.array([e.x[:3] for e in data.smoothed])
                         - sky.truth(sim.scenario, t)[:, :3], axis=1)
    assert np.median(err) < 0.2, np.median(err)


def test_the_choice_is_overridden_and_a_wrong_one_refused_with_the_fix(telescope_tdm, tmp_path,
                                                                       capsys):
    tdm, _ = telescope_tdm
    bag = tmp_path / "imported"
    assert cli.main(["import", "tdm", str(tdm), "--bag", str(bag)]) == 0
    capsys.readouterr()
    # --filter network takes them too (both kinds; here the telescopes only)
    assert cli.main(["replay", str(bag), "--offline", "--filter", "network",
                     "--out", str(tmp_path / "network")]) == 0
    assert "replay: estimator settings: --filter network: the real-sky filter" in \
        capsys.readouterr().out
    # a set-up that takes none of the data: one line, the set-up that does
    assert cli.main(["replay", str(bag), "--offline", "--filter", "radar",
                     "--out", str(tmp_path / "radar")]) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: --filter radar takes range/az/el; the bag has ") and \
        err.endswith(" ra/dec from maui, socorro: choose --filter optical\n"), err
    # settings that take none of them: no estimate is exit 1, with the reason and the fix
    assert cli.main(["replay", str(bag), "--offline", "--scenario", "iss_j2_pos",
                     "--out", str(tmp_path / "position")]) == 1
    err = capsys.readouterr().err
    assert err.startswith("error: no estimate: ") and \
        "of another kind than the settings' position (the bag has " in err and \
        err.endswith("replay with --filter optical\n"), err


def _m(station: str, kind: Kind) -> Measurement:
    return Measurement(t=0.0, z=np.zeros(3 if kind != Kind.RA_DEC else 2),
                       R=np.eye(3 if kind != Kind.RA_DEC else 2), kind=kind, frame_id=station,
                       source=Source.SENSOR)


@pytest.mark.parametrize(("data", "setup", "station"), [
    ([("maui", Kind.RA_DEC)], FilterSetup.OPTICAL, "maui"),
    ([("millstone", Kind.RANGE_AZ_EL), ("tira", Kind.RANGE_AZ_EL)], FilterSetup.RADAR,
     "millstone,tira,"),
    ([("millstone", Kind.RANGE_AZ_EL), ("maui", Kind.RA_DEC)], FilterSetup.NETWORK,
     "maui,millstone,"),
    ([("gcrf", Kind.POSITION)], FilterSetup.POSITION, None),
    ([("columbus", Kind.RANGE_AZ_EL)], FilterSetup.RADAR, "columbus"),
])
def test_the_set_up_follows_the_kinds_and_stations(data, setup, station):
    mix = DataMix.of([_m(s, k) for s, k in data])
    assert data_setup(mix) == setup
    c, why = chosen_estimator(mix, None)
    assert why.startswith(f"{setup}, from the data ("), why
    if station is not None:
        assert c.station == station
    assert c.kind == data[0][1] or setup == FilterSetup.NETWORK


def test_unknown_stations_are_left_out_and_said():
    mix = DataMix.of([_m("maui", Kind.RA_DEC), _m("my-scope", Kind.RA_DEC)])
    c, why = chosen_estimator(mix, None)
    assert c.station == "maui"
    assert why.endswith("station(s) my-scope left out: neither built in nor in --sites"), why
    with pytest.raises(ValueError, match="my-scope are neither built in nor in a sites file"):
        chosen_estimator(DataMix.of([_m("my-scope", Kind.RA_DEC)]), None)

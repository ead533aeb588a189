"""`ssa-fusion reproduce --quick`: the JSON's shape, determinism under a seed, and the arms'
ordering for the scenarios where the paper found the DMD-EKF close to hypothetical."""

import json

import pytest

from ssa_fusion.apps import cli
from ssa_fusion.evaluation.arms import ArmName

ARMS = ("placeholder", "coast", "dmd_ekf", "hypothetical_ekf")
SETTINGS = ("cadence_s", "training_window_s", "gap_s", "delays", "rank", "p0_sigma", "q",
            "R_sigma")


@pytest.fixture(scope="module")
def quick(tmp_path_factory):
    """One quick run of the two ordering scenarios plus a noisy one (and the studies)."""
    out = tmp_path_factory.mktemp("reproduce")
    names = ["iss_j2_pos", "iss_j2_rae", "iss_j2_pos_noisy", "vdp"]
    assert cli.main(["reproduce", "--quick", "--seed", "3", "--out", str(out),
                     "--seeds", "1", "--scenario", *names]) == 0
    return out, json.loads((out / "results.json").read_text())


def test_json_shape_and_files(quick):
    out, res = quick
    assert res["seed"] == 3 and res["quick"] is True
    assert set(res["scenarios"]) == {"iss_j2_pos", "iss_j2_rae", "iss_j2_pos_noisy", "vdp"}
    for name, r in res["scenarios"].items():
        for arm in ARMS:
            assert r["arms"][arm]["epsilon"] > 0.0, (name, arm)
        for key in SETTINGS:
            assert key in r["settings"], (name, key)
        assert r["arms"]["dmd_ekf"]["forecast_fraction"] >= 0.9, name  # forecasts were fused
        assert (out / f"{name}_error.png").stat().st_size > 1000
    noisy = res["scenarios"]["iss_j2_pos_noisy"]
    assert noisy["arms"]["dmd_ekf"]["nees_mean"] > 0.0
    lo, hi = noisy["nees"]["band95"]
    assert 0.0 < lo < 6.0 < hi
    assert (out / "iss_j2_pos_noisy_sigma.png").exists()
    sweep = res["vdp_sweep"]
    assert len(sweep["mu_p"]) == len(sweep["dmd_ekf"]) >= 3
    cons = res["consistency"]
    assert len(cons["one_shot"]["empirical_var"]) == len(cons["horizon_s"])
    assert (out / "results.md").read_text().startswith("# Reproduction")


@pytest.mark.parametrize("name", ["iss_j2_pos", "iss_j2_rae", "iss_j2_pos_noisy"])
def test_placeholder_and_coast_start_from_the_same_estimate(quick, name):
    """Same motion model, same start (the estimate at the last real measurement before the
    gap): the Monte Carlo mean and the EKF's prediction stay within a factor 2 (the mean of
    200 particles drawn from a 10 km covariance, iss_j2_pos_noisy, is 1.55x off)."""
    arms = quick[1]["scenarios"][name]["arms"]
    assert 1 / 2 < arms["placeholder"]["epsilon"] / arms["coast"]["epsilon"] < 2


def test_j2_coast_only_for_orbits(quick):
    res = quick[1]["scenarios"]
    assert all(res[n]["arms"]["j2_coast"]["epsilon"] > 0 for n in ("iss_j2_pos", "iss_j2_rae"))
    assert "j2_coast" not in res["vdp"]["arms"]
    # noise-free positions of a J2 orbit: the J2 filter is nearly exact
    assert res["iss_j2_pos"]["arms"]["j2_coast"]["epsilon"] < 1e-8


def test_quick_keeps_the_ordering(quick):
    """Noise-free positions (iss_j2_pos): the surrogate bridges the gap far better than
    coasting on the Keplerian model, as well as the filter that saw the gap."""
    eps = {a: quick[1]["scenarios"]["iss_j2_pos"]["arms"][a]["epsilon"] for a in ARMS}
    assert eps["coast"] / eps["dmd_ekf"] >= 10
    assert eps["dmd_ekf"] / eps["hypothetical_ekf"] < 1.5


def test_distributions_over_evaluation_seeds_never_used_for_tuning(quick):
    from ssa_fusion.studies import distributions

    assert not set(distributions.EVALUATION_SEEDS) & set(distributions.TUNING_SEEDS)
    assert len(distributions.EVALUATION_SEEDS) >= 20 and len(distributions.START_OFFSETS_H) >= 3
    dist = quick[1]["distributions"]
    assert set(dist) == set(quick[1]["scenarios"])
    for name, d in dist.items():
        assert d["seeds"] == [101] and d["runs"] == 1, name
        assert len(d["epsilon"]["dmd_ekf"]) == 1
        r = d["ratios"]["dmd_over_coast"]
        assert r["q25"] <= r["median"] <= r["q75"] <= r["worst"]
        eps = d["epsilon"]
        wins = sum(a < b for a, b in zip(eps["dmd_ekf"], eps["coast"], strict=True)) / 1
        assert d["dmd_beats_coast"] == wins
    assert "dmd_over_j2_coast" in dist["iss_j2_rae"]["ratios"]
    assert "dmd_over_j2_coast" not in dist["vdp"]["ratios"]
    assert "## Distributions over the evaluation seeds" in (quick[0] / "results.md").read_text()


def test_same_seed_same_numbers(quick, tmp_path):
    assert cli.main(["reproduce", "--quick", "--seed", "3", "--out", str(tmp_path),
                     "--scenario", "iss_j2_pos", "--no-plots", "--no-studies",
                     "--seeds", "1", "--workers", "1"]) == 0
    again = json.loads((tmp_path / "results.json").read_text())["scenarios"]["iss_j2_pos"]
    first = quick[1]["scenarios"]["iss_j2_pos"]
    assert again["arms"] == first["arms"]
    assert again["settings"] == first["settings"]
    # one worker or two: the same distribution
    dist = json.loads((tmp_path / "results.json").read_text())["distributions"]["iss_j2_pos"]
    assert dist == quick[1]["distributions"]["iss_j2_pos"]


def test_unknown_scenario_is_an_error(tmp_path, capsys):
    assert cli.main(["reproduce", "--quick", "--out", str(tmp_path),
                     "--scenario", "nope"]) == 2
    assert "unknown scenario" in capsys.readouterr().err


def test_dmd_arm_predicts_where_no_forecast_arrives(monkeypatch):
    """A surrogate that never forecasts: every gap epoch still has an estimate, the filter's
    prediction, which is then the coasting EKF's state."""
    import numpy as np

    from ssa_fusion.sim import scenarios
    from ssa_fusion.sim.simulate import simulate
    from ssa_fusion.studies import experiments
    from ssa_fusion.studies.reproduce import quick_variant

    s = quick_variant(scenarios.SCENARIOS["iss_j2_pos"])
    sim = simulate(s, seed=1)
    config = experiments.scenario_surrogate(s).config

    class Silent:
        def __init__(self) -> None:
            self.config = config

        def add(self, m):
            return []

        def due(self, t):
            return []

    monkeypatch.setattr(experiments, "scenario_surrogate", lambda s: Silent())
    ev, run = experiments.evaluate_sim(s, sim, seed=1)
    assert run.forecasts == []
    dmd, coast = ev.arms[ArmName.DMD_EKF], ev.arms[ArmName.COAST]
    assert len(dmd.t) == int(sim.in_gap.sum())
    np.testing.assert_allclose(dmd.x, coast.x, rtol=1e-8)
    assert np.all(np.diff(np.trace(dmd.P, axis1=1, axis2=2)) > 0)  # growing uncertainty
    assert ev.coverage == 0.0 and ev.predicted == len(dmd.t)  # and the results say so


def test_update_doc_replaces_only_the_generated_block(tmp_path):
    from ssa_fusion.studies import reproduce

    doc = tmp_path / "R.md"
    doc.write_text(f"# Results\nintro\n{reproduce.GENERATED_BEGIN}\nold\n"
                   f"{reproduce.GENERATED_END}\nreading\n")
    reproduce.update_doc(doc, "# Reproduction\n\n| new | table |\n")
    assert doc.read_text() == (f"# Results\nintro\n{reproduce.GENERATED_BEGIN}\n| new | table |\n"
                               f"{reproduce.GENERATED_END}\nreading\n")
    doc.write_text("no markers")
    with pytest.raises(ValueError, match="generated by ssa-fusion reproduce"):
        reproduce.update_doc(doc, "x\ny")

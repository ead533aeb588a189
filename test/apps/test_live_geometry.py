"""`ssa-fusion live --seed`: a real-sky run's orbit and start vary with the seed, as the
benchmarks' cases do, unless ``--same-geometry``; ``--truth`` picks the object's truth."""

import argparse

from ssa_fusion.apps import live
from ssa_fusion.graphs import node_parameters
from ssa_fusion.sim import scenarios, sky


def _args(*argv: str) -> argparse.Namespace:
    p = argparse.ArgumentParser()
    live.add_arguments(p)
    return p.parse_args(list(argv))


def test_seed_varies_start_and_orbit_unless_same_geometry(tmp_path):
    base = sky.SKY_SCENARIOS["iss_radar_columbus"]
    s, g = live._case(base, _args("--seed", "7", "--truth", "high_fidelity"))
    assert g == 7 and s.truth == sky.TruthModel.HIGH_FIDELITY
    assert s.t0 == base.t0 + sky.case_start_offset_s(7) and s.x0 == base.x0
    params = node_parameters(s, 1000.0, 7, tmp_path, g)["sensor_sim"]
    assert params["geometry_seed"] == 7 and params["truth"] == "high_fidelity"
    assert params["start"] != node_parameters(base, 1000.0, 7, tmp_path)["sensor_sim"]["start"]
    same, g = live._case(base, _args("--seed", "7", "--same-geometry"))
    assert g == -1 and same.t0 == base.t0 and same.truth == sky.TruthModel.SGP4
    started, g = live._case(base, _args("--seed", "7", "--start", "2025-03-01T00:00:00Z"))
    assert g == 7 and started.t0 == base.t0  # an explicit start is kept (set later)
    paper, g = live._case(scenarios.DEFAULT_LIVE, _args("--seed", "7"))
    assert g == -1 and paper is scenarios.DEFAULT_LIVE

"""TrackBank.warm_up loads every compiled kernel `process` runs, with the argument types it
runs them with: a batch after it (IODs started, tracks updated) compiles or loads nothing
more. In a fresh interpreter (a kernel another test ran would already be loaded here)."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]

SCRIPT = r"""
import json, sys
from dataclasses import asdict
from numba.core.dispatcher import Dispatcher
from ssa_fusion.core.catalog import bank_kernels, batch_ekf
from ssa_fusion.core.motion import kepler
from ssa_fusion.core.motion import propagation
from ssa_fusion.formats import element_sets as catalog
from ssa_fusion.core.earth.stations import NETWORKS, SENSORS
from ssa_fusion.core.catalog.track_bank import TrackBank
from ssa_fusion.params import settings
from ssa_fusion.params.defaults import CATALOG_FILTER
from ssa_fusion.sim import survey

def signatures():
    return {f"{m.__name__}.{k}": len(v.signatures)
            for m in (bank_kernels, batch_ekf, kepler, propagation)
            for k, v in vars(m).items() if isinstance(v, Dispatcher)}

radars = [SENSORS[s] for s in NETWORKS["radar_network"]]
network = {s.station.name: s.station for s in radars}
options = settings.filter_options({**asdict(CATALOG_FILTER), "station": ",".join(network),
                                   "motion_model": sys.argv[2]})
base = catalog.read_catalog(sys.argv[1])[0]
obs = survey.observe_catalog(survey.synthetic_catalog(base, 4, seed=5), radars,
                             base.epoch_unix, 3 * 3600.0, seed=1)
ids = [obs.object_ids[k] for k in obs.obj]
names = [radars[j].station.name for j in obs.sensor]
R = [radars[j].R for j in obs.sensor]
bank = TrackBank(options, network)
before = signatures()
bank.warm_up()
warm = signatures()
res = bank.process(obs.t, ids, names, obs.z, R)
print(json.dumps({"before": before, "warm": warm, "after": signatures(),
                  "fused": int(res.fused.size), "tracks": int(bank.tracking.sum())}))
"""


@pytest.mark.parametrize("model", ["j2", "kepler"])
def test_warm_up_loads_what_process_runs(model):
    sample = ROOT / "config" / "catalogs" / "sample.tle"
    out = subprocess.run([sys.executable, "-c", SCRIPT, str(sample), model], cwd=ROOT,
                         capture_output=True, text=True, check=True, timeout=600)
    got = json.loads(out.stdout.strip().splitlines()[-1])
    assert got["tracks"] >= 2 and got["fused"] > 20  # IODs solved, tracks updated
    assert sum(got["before"].values()) == 0  # a fresh interpreter: nothing loaded yet
    loaded = {k for k, n in got["warm"].items() if n}
    assert loaded, "warm_up loaded no kernel"
    assert got["after"] == got["warm"], "process loaded kernels warm_up had not"

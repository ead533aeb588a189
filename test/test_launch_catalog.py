"""The catalog launch file (launch_scripts/catalog.launch.py) over the stand-ins of
test_launch.py: its arguments, and the nodes it starts are `ssa-fusion live --catalog`'s
(`graphs.catalog_graph`), K filter and K surrogate shards, with the two shutdown
handlers."""

from __future__ import annotations

import re
import sys
from itertools import pairwise
from pathlib import Path

import pytest
from test_launch import declared, kind, load_launch_file, run_graph, shutdowns

from ssa_fusion.graphs import catalog_graph
from ssa_fusion.nodes.kit.shards import shard_range
from ssa_fusion.sim import sky

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture
def launch(monkeypatch):
    return load_launch_file(monkeypatch, ROOT / "launch_scripts" / "catalog.launch.py")


def test_declares_its_arguments_and_installs_the_sample_catalog(launch):
    args = declared(launch.generate_launch_description())
    assert tuple(args) == tuple(launch.ARGUMENTS)
    assert all(a.kwargs["description"] for a in args.values())
    sample = Path(args["catalog"].kwargs["default_value"])
    assert sample == Path(sys.prefix) / "share" / "ssa_fusion" / "config" / "catalogs" / \
        "sample.tle"
    assert sample.read_text() == (ROOT / "config" / "catalogs" / "sample.tle").read_text()


def test_starts_k_filter_and_k_surrogate_shards_as_live_catalog_does(launch):
    nodes, handlers = run_graph(launch, shards="3", synthetic="50", duration="2",
                                time_scale="200", bag="/tmp/cat_bag", seed="7",
                                start="2025-03-01T00:00:00Z")
    s = sky.SKY_SCENARIOS["iss_network"]
    want = catalog_graph(s, Path(declared(launch.generate_launch_description())["catalog"]
                                 .kwargs["default_value"]), 0, 50, 7200.0, 200.0, 7, 3, True,
                         {}, Path("/tmp/cat_bag"), "2025-03-01T00:00:00Z")
    assert list(nodes) == [n.name for n in want]  # sensor_sim last
    assert [n for n in nodes if n.startswith("catalog_filter")] == \
        [f"catalog_filter_{k}" for k in range(3)]
    assert [n for n in nodes if n.startswith("catalog_surrogate")] == \
        [f"catalog_surrogate_{k}" for k in range(3)]
    for spec in want:
        node = nodes[spec.name]
        assert node.kwargs["executable"] == spec.executable
        assert node.kwargs["parameters"] == [spec.params]
        assert (Path(sys.prefix) / "lib" / "ssa_fusion" / spec.executable).is_file()
    # each shard of each kind owns one key range: together they cover every key once
    ranges = [shard_range(nodes[f"catalog_filter_{k}"].kwargs["parameters"][0]["shard"], 3)
              for k in range(3)]
    assert ranges[0][0] == 0 and all(a[1] + 1 == b[0] for a, b in pairwise(ranges))
    sensor = nodes["sensor_sim"].kwargs["parameters"][0]
    assert sensor["duration"] == 7200.0 and sensor["time_scale"] == 200.0
    assert sensor["start"] == "2025-03-01T00:00:00Z"
    assert sensor["wait_for"] == ["/ssa/measurement_batch=4", "/ssa/estimate_batch=4"]
    targets = {next(n for n, a in nodes.items() if a is h.kwargs["target_action"])
               for h in handlers}
    assert targets == {"sensor_sim", "recorder"}
    assert all(len(shutdowns(h.kwargs["on_exit"])) == 1 for h in handlers)
    assert [kind(h) for h in handlers] == ["OnProcessExit", "OnProcessExit"]


def test_a_sites_file_gives_the_radars_that_observe_the_catalog(launch):
    """sites:= (as `live --catalog --sites`): its radars, not the scenario's, for the
    simulator and every filter shard (which then need the file to know them)."""
    sites = str(Path(__file__).resolve().parents[1] / "config" / "sites" / "example.yaml")
    nodes, _ = run_graph(launch, shards="2", sites=sites)
    for name in ("sensor_sim", "catalog_filter_0", "catalog_filter_1"):
        assert nodes[name].kwargs["parameters"][0]["sites"] == sites, name
    assert nodes["catalog_filter_0"].kwargs["parameters"][0]["station"] == "nordlys,kestrel"


def test_without_surrogates_only_the_filter_shards_run(launch):
    nodes, _ = run_graph(launch, shards="2", surrogate="false")
    assert not [n for n in nodes if n.startswith("catalog_surrogate")]
    assert nodes["sensor_sim"].kwargs["parameters"][0]["wait_for"][1] == "/ssa/estimate_batch=1"


def test_unlabelled_detections_and_their_truth_are_recorded(launch):
    nodes, _ = run_graph(launch, unlabelled="true")
    sensor = nodes["sensor_sim"].kwargs["parameters"][0]
    assert sensor["unlabelled"] is True
    assert {"recorder:/ssa/detection_truth", "recorder:/ssa/measurement_associated=1"} <= \
        set(sensor["wait_for_readers"])
    nodes, _ = run_graph(launch)
    assert nodes["sensor_sim"].kwargs["parameters"][0]["unlabelled"] is False


@pytest.mark.parametrize(("given", "message"), [
    ({"scenario": "iss_j2_rae"}, "scenario 'iss_j2_rae' is not a real-sky scenario"),
    ({"shards": "0"}, "shards:='0' must be >= 1"),
    ({"shards": "two"}, "shards:='two' is not an integer"),
    ({"duration": "-1"}, "duration:='-1' must be >= 0.0"),
    ({"surrogate": "maybe"}, "surrogate:='maybe': true or false"),
    ({"start": "2040-01-01"}, "is outside the range ssa_fusion represents"),
    ({"sites": "/nope/sites.yaml"}, "/nope/sites.yaml"),
    ({"unlabelled": "yes"}, "unlabelled:='yes': true or false"),
    ({"unlabelled": "true", "shards": "2"}, "unlabelled detections need one filter shard"),
])
def test_bad_arguments_are_named(launch, given, message):
    with pytest.raises(ValueError, match=re.escape(message)):
        run_graph(launch, **given)

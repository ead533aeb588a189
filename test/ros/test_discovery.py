"""Discovery settings of a graph: loopback by default (range, no peers, a loopback-only
Fast DDS profile with dynamic history memory that rmw_fastrtps applies), other hosts only
when asked, and the command a remote shard's host runs."""

from __future__ import annotations

import argparse
import os
import shlex
import subprocess
import sys
import textwrap
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest

from ssa_fusion import graphs
from ssa_fusion.apps import live_catalog
from ssa_fusion.apps.args import discovery_range, static_peers
from ssa_fusion.ros.discovery import (
    LOOPBACK,
    PEERS_VAR,
    PROFILE_NAME,
    PROFILE_VAR,
    QOS_FROM_XML_VAR,
    RANGE_VAR,
    Discovery,
    DiscoveryRange,
)

SAMPLE = Path(__file__).resolve().parents[2] / "config" / "catalogs" / "sample.tle"
SUBNET = Discovery(DiscoveryRange.SUBNET)


def test_the_default_stays_on_this_host_whatever_the_shell_exports(tmp_path):
    env = {RANGE_VAR: "SUBNET", PEERS_VAR: "10.0.0.9"}
    LOOPBACK.apply(env)
    LOOPBACK.bind(env, tmp_path)
    assert env[RANGE_VAR] == "LOCALHOST" and PEERS_VAR not in env
    profile = Path(env[PROFILE_VAR])
    assert profile == tmp_path / PROFILE_NAME
    text = profile.read_text()
    assert '<interface name="lo"/>' in text and "<useBuiltinTransports>false" in text
    assert not LOOPBACK.reaches_other_hosts
    assert env[QOS_FROM_XML_VAR] == "1"  # else rmw_fastrtps overrides the history memory


def test_every_writer_and_reader_defaults_to_dynamic_history_memory(tmp_path):
    """The profile's default writer and reader: DYNAMIC history memory, and rmw_fastrtps's
    own defaults otherwise (synchronous publication, no data sharing)."""
    env: dict[str, str] = {}
    LOOPBACK.bind(env, tmp_path)
    ns = {"dds": "http://www.eprosima.com"}
    profiles = ET.parse(env[PROFILE_VAR]).getroot().find("dds:profiles", ns)
    assert profiles is not None
    for tag in ("data_writer", "data_reader"):
        found = [e for e in profiles.findall(f"dds:{tag}", ns)
                 if e.get("is_default_profile") == "true"]
        assert len(found) == 1, tag
        assert found[0].findtext("dds:historyMemoryPolicy", namespaces=ns) == "DYNAMIC"
        assert found[0].findtext("dds:qos/dds:data_sharing/dds:kind", namespaces=ns) == "OFF"
    writer = profiles.find("dds:data_writer", ns)
    assert writer is not None
    assert writer.findtext("dds:qos/dds:publishMode/dds:kind", namespaces=ns) == "SYNCHRONOUS"


PUB_SUB = textwrap.dedent("""
    import rclpy
    from std_msgs.msg import String
    rclpy.init()
    node = rclpy.create_node("profile_check")
    node.create_publisher(String, "/profile_check", 10)
    node.create_subscription(String, "/profile_check", lambda m: None, 10)
    node.destroy_node()
    rclpy.shutdown()
""")


def _fast_dds_output(env: dict[str, str]) -> str:
    """Run a publisher and a subscription in a process of `env`; return what it printed."""
    done = subprocess.run([sys.executable, "-c", PUB_SUB], env=env, capture_output=True,
                          text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    return done.stdout + done.stderr


def test_fast_dds_parses_the_profile_without_an_error(tmp_path):
    """Fast DDS loads the profile the graph's processes get: no XML parser error, where a
    profile with a history memory policy Fast DDS does not know gets one."""
    env = dict(os.environ)
    LOOPBACK.apply(env)
    LOOPBACK.bind(env, tmp_path)
    assert "XMLPARSER" not in _fast_dds_output(env)
    bad = tmp_path / "bad.xml"
    bad.write_text(Path(env[PROFILE_VAR]).read_text().replace(">DYNAMIC<", ">DYNAMIC_NONE<"))
    assert "XMLPARSER" in _fast_dds_output({**env, PROFILE_VAR: str(bad)})


def test_other_hosts_drop_the_loopback_profile_and_keep_a_users_own(tmp_path):
    env: dict[str, str] = {}
    LOOPBACK.bind(env, tmp_path)
    SUBNET.apply(env)
    SUBNET.bind(env, tmp_path)  # an earlier graph's loopback profile is taken out
    assert env == {RANGE_VAR: "SUBNET"}
    peers = Discovery(static_peers=("10.0.0.2", "b.example"))
    assert peers.reaches_other_hosts
    peers.apply(env)
    assert env[PEERS_VAR] == "10.0.0.2;b.example"
    own = {PROFILE_VAR: "/etc/my_profile.xml"}
    LOOPBACK.bind(own, tmp_path)  # the user's file decides
    assert own == {PROFILE_VAR: "/etc/my_profile.xml"}


def test_options_parse_or_say_why_in_one_line():
    assert discovery_range("subnet") is DiscoveryRange.SUBNET
    assert static_peers("10.0.0.2, fe80::1,host-b") == ("10.0.0.2", "fe80::1", "host-b")
    assert live_catalog.shard_list("3,1,1") == (1, 3)
    for parse, bad in ((discovery_range, "wide"), (static_peers, "a b"),
                       (static_peers, "x;rm -rf"), (live_catalog.shard_list, "x"),
                       (live_catalog.shard_list, "-1"), (live_catalog.shard_list, ",")):
        with pytest.raises(argparse.ArgumentTypeError):
            parse(bad)


def _args(**kw) -> argparse.Namespace:
    base = dict(catalog=SAMPLE, objects=0, synthetic=4, duration=1.0, start="", shards=2,
                scenario="iss_network", surrogate_param=[], remote_shards=(1,),
                discovery_range=DiscoveryRange.LOCALHOST, static_peers=())
    return argparse.Namespace(**{**base, **kw})


def test_remote_shards_need_a_reach_beyond_loopback_and_an_existing_shard():
    assert "--discovery-range SUBNET or --static-peers" in live_catalog.args_problem(_args())
    assert "there are shards 0..1" in live_catalog.args_problem(
        _args(remote_shards=(2,), discovery_range=DiscoveryRange.SUBNET))
    assert live_catalog.args_problem(_args(discovery_range=DiscoveryRange.SUBNET)) is None
    assert live_catalog.args_problem(_args(static_peers=("10.0.0.2",))) is None


def test_a_remote_shard_gets_the_command_of_its_processes_only():
    scenario = graphs.catalog_scenario("iss_network")
    specs = graphs.catalog_graph(scenario, SAMPLE, 0, 4, 3600.0, 100.0, 0, 3, True,
                                 {"min_span": 7200.0}, None)
    lines = live_catalog.remote_commands(specs, (1,), 42, Discovery(
        DiscoveryRange.LOCALHOST, ("10.0.0.2",)))
    assert [k for k, _ in lines] == [1, 1]
    words = [shlex.split(c) for _, c in lines]
    for w, exe in zip(words, ("catalog_filter", "catalog_surrogate"), strict=True):
        # the peers are this host's to name: the other host keeps the range only
        assert w[:6] == ["ROS_DOMAIN_ID=42", "ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST", "ros2",
                         "run", "ssa_fusion", exe]
        assert w[-2:] == ["-r", f"__node:={exe}_1"]
        assert "shard:=1" in w and "shards:=3" in w
    assert "min_span:=7200.0" in words[1]
    local = [s.name for s in specs if not live_catalog.is_remote(s, (1,))]
    assert local == ["recorder", "catalog_filter_0", "catalog_filter_2", "catalog_surrogate_0",
                     "catalog_surrogate_2", "sensor_sim"]

"""A catalog batch writer does not keep what a reader's content filter turns away.

A shard's batches reach the other shard's readers too, whose content filter refuses them.
Fast DDS filters in the writer when its liveliness lease is infinite, and then keeps every
refused sample in a reliable volatile history (`topics.CATALOG_DEPTH` deep): the filter
shards of a 30,000-object run grew by hundreds of MiB. `qos.writer_qos` gives writers a
finite lease, so the readers filter. Real processes over DDS (loopback, a domain of their
own): a publisher of 300 batches of 1,000 rows (about 75 MB) to a reader that takes them
all and one that refuses them all; its resident memory before and after."""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap

import pytest

from ssa_fusion.ros.processes import fresh_domain_id

BATCHES, ROWS = 300, 1000

SCRIPT = textwrap.dedent("""
    import sys, time
    import numpy as np
    import rclpy
    from rclpy.node import Node
    from ssa_fusion.core.base.rows import EstimateRows
    from ssa_fusion.core.base.types import UpdateSource
    from ssa_fusion.nodes.kit.shards import content_filter, shard_range
    from ssa_fusion.ros import messages
    from ssa_fusion.ros.interfaces import EstimateBatch
    from ssa_fusion.ros.qos import CATALOG_QOS, CATALOG_WRITER_QOS

    role, qos_name, batches, rows_n = sys.argv[1], sys.argv[2], int(sys.argv[3]), int(sys.argv[4])
    topic = "/test/estimate_batch"

    def rss_mib():
        with open("/proc/self/status") as f:
            return next(int(l.split()[1]) for l in f if l.startswith("VmRSS:")) / 1024

    rclpy.init()
    node = Node(role)
    if role == "pub":
        qos = CATALOG_WRITER_QOS if qos_name == "writer" else CATALOG_QOS
        pub = node.create_publisher(EstimateBatch, topic, qos)
        end = time.monotonic() + 60
        while pub.get_subscription_count() < 2 and time.monotonic() < end:
            rclpy.spin_once(node, timeout_sec=0.1)
        ids = [str(70000 + 2 * i) for i in range(rows_n)]
        keys = messages.shard_keys(ids)
        before = rss_mib()
        for k in range(batches):  # shard 0's batches
            rows = EstimateRows(np.full(rows_n, 1.7e9 + k), ids, np.ones((rows_n, 6)),
                                np.tile(np.eye(6), (rows_n, 1, 1)), np.zeros(rows_n),
                                UpdateSource.SENSOR, keys)
            pub.publish(messages.estimate_batch_to_msg(rows, shard_range(0, 2)))
            rclpy.spin_once(node, timeout_sec=0.001)
        end = time.monotonic() + 5  # heartbeats and acknowledgements
        while time.monotonic() < end:
            rclpy.spin_once(node, timeout_sec=0.1)
        print(f"grew {rss_mib() - before:.1f}", flush=True)
    else:
        got = {0: 0, 1: 0}
        for shard in (0, 1):
            cft = content_filter(shard, 2, batches=True)
            node.create_subscription(EstimateBatch, topic,
                                     lambda m, s=shard: got.__setitem__(s, got[s] + 1),
                                     CATALOG_QOS, content_filter_options=cft)
        end = time.monotonic() + 120
        while got[0] < batches and time.monotonic() < end:
            rclpy.spin_once(node, timeout_sec=0.1)
        for _ in range(20):
            rclpy.spin_once(node, timeout_sec=0.1)
        print(f"got {got[0]} {got[1]}", flush=True)
""")


def run_pair(qos_name: str) -> tuple[float, str]:
    env = {**os.environ, "ROS_DOMAIN_ID": str(fresh_domain_id()),
           "ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST"}
    args = [str(BATCHES), str(ROWS)]
    sub = subprocess.Popen([sys.executable, "-c", SCRIPT, "sub", qos_name, *args], env=env,
                           stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        pub = subprocess.run([sys.executable, "-c", SCRIPT, "pub", qos_name, *args], env=env,
                             capture_output=True, text=True, timeout=180)
        out, err = sub.communicate(timeout=180)
    finally:
        if sub.poll() is None:
            sub.kill()
            sub.wait()
    assert pub.returncode == 0 and sub.returncode == 0, (pub.stderr, err)
    return float(pub.stdout.split()[-1]), out.strip()


@pytest.mark.parametrize("qos_name", ["writer", "reader"])
def test_a_batch_no_reader_takes_leaves_the_writers_history(qos_name):
    grew, got = run_pair(qos_name)
    assert got == f"got {BATCHES} 0"  # the filtering reader took none, the other all
    if qos_name == "writer":  # CATALOG_WRITER_QOS: the product's writers
        assert grew < 25.0, grew
    else:  # the same QoS the readers use (infinite lease): why writers have their own
        assert grew > 50.0, grew

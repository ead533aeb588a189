"""Graph test: Measurement and StateEstimate cross process boundaries over DDS unchanged."""

import json
from pathlib import Path

from msg_samples import N_SAMPLES, as_dict, sample_estimate, sample_measurement
from ssa_fusion_msgs.msg import Measurement

HERE = Path(__file__).parent


def test_every_field_arrives_identical(ros_graph):
    echo = ros_graph.start_python(HERE / "echo_messages.py", name="echo")
    ros_graph.wait_for_subscriber("/test/measurement")
    ros_graph.wait_for_subscriber("/test/estimate")
    pub = ros_graph.start_python(HERE / "pub_messages.py", name="publisher")

    assert ros_graph.wait_exit(echo, timeout=30) == 0, ros_graph.report()
    lines = [json.loads(line) for line in echo.stdout().splitlines()]
    got_m = [d for d in lines if d.pop("type") == "measurement"]
    got_e = [d for d in lines if "state" in d]
    assert len(got_m) == N_SAMPLES and len(got_e) == N_SAMPLES

    want_m = [json.loads(json.dumps(as_dict(sample_measurement(i)))) for i in range(N_SAMPLES)]
    want_e = [json.loads(json.dumps(as_dict(sample_estimate(i)))) for i in range(N_SAMPLES)]
    assert got_m == want_m  # exact: floats survive CDR and JSON round trips bit for bit
    assert got_e == want_e
    assert got_m[1]["kind"] == Measurement.RANGE_AZ_EL
    assert got_m[0]["z"][1] == 0.0 and got_e[0]["covariance"][0] == 1e-18
    ros_graph.stop(pub)
    assert pub.returncode == 0, pub.describe()

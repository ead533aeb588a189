"""Test process: receive N Measurement and N StateEstimate messages and print each, every
field, as one JSON line on stdout; exit 0 when all arrived."""

import json

import rclpy
from msg_samples import N_SAMPLES, as_dict
from ssa_fusion_msgs.msg import Measurement, StateEstimate

from ssa_fusion.ros.topics import DATA_QOS


def main() -> None:
    rclpy.init()
    node = rclpy.create_node("sample_echo")
    counts = {"measurement": 0, "estimate": 0}

    def on(kind: str):
        def cb(msg) -> None:
            counts[kind] += 1
            print(json.dumps({"type": kind, **as_dict(msg)}), flush=True)

        return cb

    node.create_subscription(Measurement, "/test/measurement", on("measurement"), DATA_QOS)
    node.create_subscription(StateEstimate, "/test/estimate", on("estimate"), DATA_QOS)
    while min(counts.values()) < N_SAMPLES:
        rclpy.spin_once(node, timeout_sec=0.1)
    node.destroy_node()
    rclpy.try_shutdown()


if __name__ == "__main__":
    main()

"""Test process: receive N Measurement and N StateEstimate messages and print each, every
field, as one JSON line on stdout; exit 0 when all arrived. Once both subscriptions have
matched a publisher (the reader's side of the match: what a writer sends before it is
dropped), it says so on /test/ready (latched), which the publisher waits for."""

import json

import rclpy
from msg_samples import N_SAMPLES, as_dict
from ssa_fusion_msgs.msg import Measurement, StateEstimate
from std_msgs.msg import Empty

from ssa_fusion.ros.qos import CONFIG_QOS, DATA_QOS


def main() -> None:
    rclpy.init()
    node = rclpy.create_node("sample_echo")
    counts = {"measurement": 0, "estimate": 0}

    def on(kind: str):
        def cb(msg) -> None:
            counts[kind] += 1
            print(json.dumps({"type": kind, **as_dict(msg)}), flush=True)

        return cb

    subs = [node.create_subscription(Measurement, "/test/measurement", on("measurement"),
                                     DATA_QOS),
            node.create_subscription(StateEstimate, "/test/estimate", on("estimate"), DATA_QOS)]
    ready = node.create_publisher(Empty, "/test/ready", CONFIG_QOS)
    said = False
    while min(counts.values()) < N_SAMPLES:
        if not said and all(s.get_publisher_count() > 0 for s in subs):
            ready.publish(Empty())
            said = True
        rclpy.spin_once(node, timeout_sec=0.1)
    node.destroy_node()
    rclpy.try_shutdown()


if __name__ == "__main__":
    main()

"""Test process: publish N sample Measurement and StateEstimate messages once a subscriber
matched on both topics, then stay up until terminated."""

import rclpy
from msg_samples import N_SAMPLES, sample_estimate, sample_measurement
from rclpy.executors import ExternalShutdownException
from ssa_fusion_msgs.msg import Measurement, StateEstimate

from ssa_fusion.ros.topics import DATA_QOS


def main() -> None:
    rclpy.init()
    node = rclpy.create_node("sample_publisher")
    pub_m = node.create_publisher(Measurement, "/test/measurement", DATA_QOS)
    pub_e = node.create_publisher(StateEstimate, "/test/estimate", DATA_QOS)
    sent = False

    def tick() -> None:
        nonlocal sent
        if sent or pub_m.get_subscription_count() == 0 or pub_e.get_subscription_count() == 0:
            return
        for i in range(N_SAMPLES):
            pub_m.publish(sample_measurement(i))
            pub_e.publish(sample_estimate(i))
        sent = True
        node.get_logger().info(f"published {N_SAMPLES} of each")

    node.create_timer(0.02, tick)
    try:
        rclpy.spin(node)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        node.destroy_node()
        rclpy.try_shutdown()


if __name__ == "__main__":
    main()

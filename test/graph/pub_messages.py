"""Test process: publish N sample Measurement and StateEstimate messages once the echo said
on /test/ready that its subscriptions matched this publisher (both sides of the match), then
stay up until terminated."""

import rclpy
from msg_samples import N_SAMPLES, sample_estimate, sample_measurement
from rclpy.executors import ExternalShutdownException
from ssa_fusion_msgs.msg import Measurement, StateEstimate
from std_msgs.msg import Empty

from ssa_fusion.ros.qos import CONFIG_QOS, DATA_QOS


def main() -> None:
    rclpy.init()
    node = rclpy.create_node("sample_publisher")
    pub_m = node.create_publisher(Measurement, "/test/measurement", DATA_QOS)
    pub_e = node.create_publisher(StateEstimate, "/test/estimate", DATA_QOS)
    sent = False
    ready: list[Empty] = []
    node.create_subscription(Empty, "/test/ready", ready.append, CONFIG_QOS)

    def tick() -> None:
        nonlocal sent
        if sent or not ready:
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

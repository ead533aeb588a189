"""rclpy/rosbags plumbing: topics and QoS, message conversion, bags, executors,
readiness, playback, node processes."""

"""rclpy/rosbags plumbing of ssa_fusion.

Topics and QoS, message conversion, bags, executors, readiness, playback, node processes.
"""

"""Pure numerical core of ssa_fusion.

Imports numpy, scipy and sgp4 only (never rclpy). Units throughout: km, km/s, rad, s.
"""

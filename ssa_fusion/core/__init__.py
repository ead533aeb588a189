"""Pure numerical core of ssa_fusion.

Imports numpy, scipy, sgp4, numba, pyerfa and astropy-iers-data only (never rclpy, no other
floor of the package). Units throughout: km, km/s, rad, s.
"""

"""The world the simulator runs: scenarios, their truth, the sensors' schedules, surveys.

`sensor_sim` (the simulator node) and the studies use it; it imports only the core.
"""

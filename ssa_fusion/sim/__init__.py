"""The world the simulator runs: scenarios, their truth, the sensors' schedules, surveys.

`scenarios` (the paper's), `sky` (stations with horizons), `survey` (a radar network over a
catalog), `simulate` (truth and measurements) and `schedule` (what the simulator node
publishes, and when). `sensor_sim` (the simulator node) and the studies use it; it imports
only the core and `formats` (no ROS, no `params`).
"""

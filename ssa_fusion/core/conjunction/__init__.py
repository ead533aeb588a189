"""Close approaches: screening pairs, times of closest approach, collision probability.

Imports the rooms below it (`base` to `catalog`). Modules: `encounter` (RTN frames, relative
state, the encounter plane), `pc2d` (Foster's 2D Pc, in logs), `usage` (the short-encounter
bounds of Coppola), `max_pc` (upper bounds when a covariance is missing), `monte_carlo` (the
3D Pc of both states' covariances), `result` (methods, warnings, the typed result) and
`probability` (the entry points: `collision_probability`, `pc2d_batch`).
"""

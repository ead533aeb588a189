"""Through the sensor gaps: what a filter publishes when no measurement comes.

The Hankel-DMD `surrogate` of the paper (`hankel_dmd`), the learned `residual` of a physics
model (in its frame, `residual_frame`, with its designs, `residual_design`), gap
`forecaster`s, the batch fit of the passes before a gap (`batch_gap`) and its learned
correction (`fit_residual`), the `publisher` that decides what goes out in a gap, per-object
`measurement_windows`, and one object's `estimator` settings. Imports the rooms below it
(`base` to `od`).
"""

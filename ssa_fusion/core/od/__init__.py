"""Batch orbit determination: least squares over passes with solve-for parameters.

`gauss_newton` (the damped solver with its stopping rules), `batch_ls` (a window of
measurements fitted with the force model, drag and empirical accelerations solved for
where they pay) and `window_noise` (the process noise of its realistic covariance).
Imports the rooms below it (`base` to `filter`).
"""

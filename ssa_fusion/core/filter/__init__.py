"""Sequential estimation of one object: EKF, UKF, smoother, initiation, the tracker.

The filters (`ekf`, `ukf`), the Rauch-Tung-Striebel `smoother`, track `initiation` from the
first measurements, the filter's `history`, the `tracker` that runs them on a measurement
stream with its `options`, and physically meaningful `process_noise`. Imports the rooms
below it (`base` to `measure`).
"""

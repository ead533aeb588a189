"""Catalogs: thousands of objects at once, labelled or not.

The batched EKF (`batch_ekf`, compiled loops over objects), the banks of tracks and of gap
forecasts (`track_bank`, `gap_bank`), the fusion of a catalog's measurement batches
(`fusion`), and unlabelled detections: the `association` package (gating, assignment,
registration, tracklets, deferred decisions, track management) and `unlabelled` rows.
Imports the rooms below it (`base` to `gaps`).
"""

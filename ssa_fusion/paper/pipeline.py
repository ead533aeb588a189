"""Estimator and surrogate built from a scenario's settings: one place, so the live nodes'
defaults, the live evaluation, the offline replay and the experiments agree."""

from __future__ import annotations

from ssa_fusion.core.surrogate import EciLift, Surrogate, SurrogateConfig
from ssa_fusion.core.tracker import Tracker, TrackerConfig
from ssa_fusion.paper.scenarios import Scenario, measurement_model, placeholder


def make_tracker(s: Scenario, object_id: str = "", **overrides) -> Tracker:
    """The scenario's EKF (placeholder model, measurement model, P0 floor, q, frame)."""
    settings = dict(p0_sigma=s.p0_sigma, q=s.q, frame_id=s.station or "eci",
                    iod_samples=s.iod_samples)
    settings.update(overrides)
    config = TrackerConfig(**settings)
    return Tracker(placeholder(s), measurement_model(s), config, n=s.n, object_id=object_id)


def make_surrogate(s: Scenario, **overrides) -> Surrogate:
    """The scenario's Hankel-DMD surrogate (buffer = tracking window, delays, rank, lifted
    observable, retrain period)."""
    settings = dict(buffer_s=s.buffer_s or s.track_s, delays=s.delays, rank=s.rank,
                    cadence_s=s.cadence_s, max_horizon_s=s.gap_s + s.cadence_s,
                    retrain_period_s=s.retrain_period_s, kind=s.kind, frame_id=s.station or "eci",
                    lift=EciLift(measurement_model(s)) if s.lift == "eci" else None)
    settings.update(overrides)
    return Surrogate(SurrogateConfig(**settings))

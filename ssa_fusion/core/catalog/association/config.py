"""The association's rules: `AssociationConfig`, and the chi-square gate it derives.

Every rule of the association (`association` package docstring) in one frozen dataclass:
the gate, M-of-N confirmation and deletion, tracklets, the long-arc predictor, the groups'
registration and deferred decisions. Units: the core's (km, km/s, rad, s).

Of scipy it imports only ``scipy.special`` (the chi-square quantile, `chi2_quantile`): the
package docstring says why.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from scipy.special import gammaincinv

__all__ = ["MEASUREMENT_DOF", "AssociationConfig", "chi2_quantile"]

MEASUREMENT_DOF = 3
"""Degrees of freedom of a range/az/el innovation (the chi-square gate's)."""


def chi2_quantile(p: float, dof: int) -> float:
    """Return the `p` quantile of a chi-square law of `dof` degrees of freedom.

    ``2 gammaincinv(dof / 2, p)``, the expression ``scipy.stats.chi2.ppf(p, dof)`` evaluates
    (the same float, bit for bit), without importing ``scipy.stats`` (package docstring).
    """
    return float(2 * gammaincinv(dof / 2, p))


@dataclass(frozen=True)
class AssociationConfig:
    """Gate and track-management rules of the association (package docstring, `manager.Associator`).

    Attributes
    ----------
    gate_probability : float
        Probability that a detection of a track falls inside the track's gate: the gate on
        ``d^2`` is the chi-square quantile of this probability with 3 degrees of freedom
        (0.9999: d^2 <= 21.1).
    confirm_hits, confirm_window : int
        M-of-N confirmation: a tentative track is confirmed once ``confirm_hits``
        detections were assigned to it in the last ``confirm_window`` scans in which it was
        expected (predicted above the scanning sensor's mask).
    delete_after_missed_passes : int
        A track is deleted after this many passes in a row in which it was expected and got
        no detection.
    pass_gap_s : float
        Two scans of one track further apart than this, s, belong to different passes.
    max_position_sigma_km : float
        A track whose predicted position standard deviation (the largest axis of its
        position covariance) exceeds this, km, is deleted: it can no longer be told from
        its neighbours.
    tracklet_max_gap_s : float
        A tracklet (unassigned detections not yet an orbit) that got no detection for this
        long, s, is dropped.
    tracklet_speed_sigma_km_s : float
        Standard deviation, km/s, of an object's speed about the circular speed at its
        radius, the prior that pairs a tracklet's first detection with its second (a
        near-circular orbit: 0.3 km/s is an eccentricity of ~0.04 in low orbit).
    tracklet_accel_sigma_km_s2 : float
        Standard deviation, km/s^2, of the acceleration left out of a tracklet's
        prediction (two-body gravity is in it), per axis.
    predictor_q : float or None
        Process-noise spectral density, km^2/s^3, of the association's own *long-arc
        predictor* (package docstring): a second filter of every track, fed the same
        detections, whose predictions rescore the pairs the tracks' filter gates
        (`gate_long_arc`); None: the tracks' filter scores them. Chosen on the crowded
        cases' tuning seeds 1-3 (`bench/bench_association.py`, docs/ASSOCIATION.md): the
        largest of 1e-16, 1e-17, 1e-18 with which every tuning run kept 99.95 % of the
        detections on the right track and no track swapped.
    register_groups : bool
        Before the assignment, shift each group of tracks that
        share detections along track by the common time that best aligns it with the scan
        (`register`; its prior from the tracks' filter's predicted position standard
        deviation).
    group_link_km, group_link_speed_fraction : float
        A group also spans tracks predicted within ``group_link_km`` km of each other whose
        predicted velocities differ by at most this fraction of their speed (one orbit:
        objects launched together), chained: twice the widest spacing (5 km) of the
        crowded cases' trains, so that a whole train, not pieces of it, is registered.
    defer_passes : int
        Decisions deferred over passes (`deferral.PairDeferral`): two confirmed tracks with
        at least one and at most this many passes behind them (an orbit of one pass, for
        1), ambiguous in a scan, keep both hypotheses until the next pass; 0: never.
    defer_margin : float
        The most the swapped assignment of two tracks may cost above the chosen one
        (``d^2 + ln det S`` units: twice a log-likelihood ratio) for them to be ambiguous.
        2 ln 1000 (a swap at least 1/1000 as likely as the chosen assignment): chosen on the
        crowded cases' tuning seeds 1-3 (24 h, `bench/bench_association.py`) as the largest
        of 2 ln 10, 2 ln 100, 2 ln 1000 with which every tuning run kept 99.95 % of the
        detections on the right track and no track swapped.
    defer_max_wait_s : float
        A deferred decision whose pair is not seen again within this long after its pass,
        s, is dropped (the scan-wise assignment stays). Each hypothesis is scored on the
        whole scan as the association makes it (the long-arc predictor and the groups'
        registration, `Associator._scan_cost`), so a decision across the half-day gap of a
        station's passes is as sharp as one at the next pass; 1 day: a low orbit comes
        back into a mid-latitude station's view within a day (not fitted).
    """

    gate_probability: float = 0.9999
    confirm_hits: int = 6
    confirm_window: int = 8
    delete_after_missed_passes: int = 3
    pass_gap_s: float = 600.0
    max_position_sigma_km: float = 100.0
    tracklet_max_gap_s: float = 60.0
    tracklet_speed_sigma_km_s: float = 0.3
    tracklet_accel_sigma_km_s2: float = 1e-4
    predictor_q: float | None = 1e-17
    register_groups: bool = True
    group_link_km: float = 10.0
    group_link_speed_fraction: float = 0.01
    defer_passes: int = 1
    defer_margin: float = 2.0 * math.log(1000.0)
    defer_max_wait_s: float = 86400.0

    def __post_init__(self) -> None:
        """Check the settings (ValueError naming the field)."""
        if not 0.0 < self.gate_probability < 1.0:
            raise ValueError(f"gate_probability must be in (0, 1), got {self.gate_probability}")
        if not 1 <= self.confirm_hits <= self.confirm_window <= 62:
            raise ValueError("need 1 <= confirm_hits <= confirm_window <= 62, got "
                             f"{self.confirm_hits} of {self.confirm_window}")
        if self.delete_after_missed_passes < 1:
            raise ValueError("delete_after_missed_passes must be >= 1, got "
                             f"{self.delete_after_missed_passes}")
        for name in ("pass_gap_s", "max_position_sigma_km", "tracklet_max_gap_s",
                     "tracklet_speed_sigma_km_s", "tracklet_accel_sigma_km_s2",
                     "group_link_km", "group_link_speed_fraction"):
            if not getattr(self, name) > 0.0:
                raise ValueError(f"{name} must be > 0, got {getattr(self, name)}")
        if self.defer_passes < 0:
            raise ValueError(f"defer_passes must be >= 0, got {self.defer_passes}")
        if not self.defer_margin >= 0.0:
            raise ValueError(f"defer_margin must be >= 0, got {self.defer_margin}")
        if not self.defer_max_wait_s > 0.0:
            raise ValueError(f"defer_max_wait_s must be > 0, got {self.defer_max_wait_s}")
        if self.predictor_q is not None and not self.predictor_q >= 0.0:
            raise ValueError(f"predictor_q must be >= 0 or None, got {self.predictor_q}")

    @property
    def gate(self) -> float:
        """Threshold on the squared Mahalanobis distance (chi-square quantile, 3 dof)."""
        return chi2_quantile(self.gate_probability, MEASUREMENT_DOF)


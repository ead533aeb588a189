"""What a collision probability says: its method, its warnings and the typed result.

`PcMethod` names how a Pc was computed (its value is what a CDM's
``COLLISION_PROBABILITY_METHOD`` carries: the SANA names where SANA has one), `PcWarning` what
the caller must know about it (a usage bound the method's assumptions break, a remediated
covariance, a Pc below the float range), `PcResult` one conjunction's answer.
"""

from __future__ import annotations

import enum
import math
from dataclasses import dataclass


class PcMethod(enum.StrEnum):
    """How a collision probability was computed (``COLLISION_PROBABILITY_METHOD``)."""

    FOSTER_2D = "FOSTER-1992"
    """2D Pc: the combined position covariance's Gaussian integrated over the hard-body circle
    in the encounter plane, linear relative motion (Foster & Estes 1992)."""
    FRISBEE_MAX = "FRISBEE-2015-MAX"
    """Upper bound when one object's covariance is missing: the unknown covariance chosen, along
    the miss vector, to maximise the 2D Pc (Frisbee 2015)."""
    ALFANO_MAX = "ALFANO_MAX_PROBABILITY-2003"
    """Upper bound when both covariances are missing: the worst covariance along the miss
    vector (Alfano 2003's maximum probability in its degenerate, aspect-ratio limit)."""
    MONTE_CARLO_3D = "MONTE_CARLO-3D"
    """3D Pc: both objects' states drawn from their 6x6 covariances, propagated (two-body)
    over the encounter, a hit when they pass closer than the hard-body radius."""


class PcWarning(enum.StrEnum):
    """What a Pc's user must know: the method's assumptions that fail, the data's defects."""

    EXTENDED_ENCOUNTER = "extended-encounter"
    """The encounter lasts too long for the short-encounter (2D) assumption: its Coppola
    (2012) bounds span more than `EXTENDED_CUTOFF` of the shorter orbital period."""
    OFFSET_ENCOUNTER = "offset-encounter"
    """The encounter's Coppola bounds reach further than `OFFSET_CUTOFF` of the shorter
    orbital period from TCA: the states and covariances at TCA do not describe it."""
    NPD_PRIMARY = "npd-primary"
    """Object 1's position covariance is not positive semi-definite."""
    NPD_SECONDARY = "npd-secondary"
    """Object 2's position covariance is not positive semi-definite."""
    REMEDIATED_COVARIANCE = "remediated-covariance"
    """The combined covariance in the encounter plane had an eigenvalue below
    ``(CLIP_FRACTION * HBR)**2`` (or negative) and was clipped to it."""
    BELOW_FLOAT_RANGE = "below-float-range"
    """The Pc is below the smallest positive float: ``pc`` is 0, ``log10_pc`` holds it."""
    ZERO_RELATIVE_VELOCITY = "zero-relative-velocity"
    """The objects do not move relative to each other: there is no encounter plane."""
    MISSING_COVARIANCE = "missing-covariance"
    """A covariance is missing: the Pc is a maximum over the unknown one (an upper bound)."""
    MONTE_CARLO_NOISE = "monte-carlo-noise"
    """A Monte Carlo Pc with fewer than 10 hits: its relative standard error is over 30 %."""


EXTENDED_CUTOFF = 0.02
"""Encounter duration / shorter orbital period above which the 2D Pc is flagged
(`PcWarning.EXTENDED_ENCOUNTER`; CARA's default cutoff for its 2D Pc)."""
OFFSET_CUTOFF = 0.01
"""Furthest encounter bound from TCA / shorter orbital period above which the 2D Pc is
flagged (`PcWarning.OFFSET_ENCOUNTER`; CARA's default cutoff)."""
CLIP_FRACTION = 1e-4
"""Eigenvalues of the combined 2D covariance are clipped up to ``(CLIP_FRACTION * HBR)**2``."""


@dataclass(frozen=True)
class PcResult:
    """One conjunction's collision probability and what it rests on.

    Attributes
    ----------
    pc : float
        Probability of collision (0 when below the float range: see `log10_pc`).
    log10_pc : float
        log10 of the Pc, finite down to any Pc the integrand can be evaluated at (-inf for a
        Pc that is exactly 0, e.g. a Monte Carlo without hits).
    method : PcMethod
        How it was computed.
    warnings : frozenset of PcWarning
        What its user must know (empty when none).
    miss_km : float
        Miss distance at the linear TCA (in the encounter plane), km.
    relative_speed_km_s : float
        Relative speed, km/s.
    hbr_km : float
        Combined hard-body radius, km.
    tca_offset_s : float
        Linear TCA minus the states' epoch, s (the states are at TCA when it is ~0).
    sigma_major_km, sigma_minor_km : float
        Standard deviations along the principal axes of the combined covariance in the
        encounter plane, km (after any clipping; NaN for a Monte Carlo Pc).
    duration_s : float
        Encounter duration, s: Coppola (2012) bounds, gamma = 1e-16 (NaN when unknown).
    period_s : float
        The shorter of the two osculating orbital periods, s (inf for a hyperbolic orbit).
    std_error : float
        Standard error of a Monte Carlo Pc (0 for the other methods).
    samples : int
        Monte Carlo samples drawn (0 for the other methods).
    """

    pc: float
    log10_pc: float
    method: PcMethod
    warnings: frozenset[PcWarning]
    miss_km: float
    relative_speed_km_s: float
    hbr_km: float
    tca_offset_s: float
    sigma_major_km: float
    sigma_minor_km: float
    duration_s: float = math.nan
    period_s: float = math.nan
    std_error: float = 0.0
    samples: int = 0

    @property
    def short_encounter_ok(self) -> bool:
        """True when neither usage bound of the short-encounter (2D) assumption is broken."""
        return not self.warnings & {PcWarning.EXTENDED_ENCOUNTER, PcWarning.OFFSET_ENCOUNTER}

    @property
    def is_upper_bound(self) -> bool:
        """True when the Pc is a maximum over a missing covariance, not an estimate."""
        return self.method in (PcMethod.FRISBEE_MAX, PcMethod.ALFANO_MAX)


def pc_from_log10(log10_pc: float) -> tuple[float, bool]:
    """Return (Pc, below float range) of a log10 Pc: 0 and True when 10**log10_pc underflows."""
    if log10_pc == -math.inf:
        return 0.0, False
    pc = 10.0 ** log10_pc if log10_pc > -400 else 0.0
    return min(pc, 1.0), pc == 0.0

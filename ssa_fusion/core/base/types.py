"""Plain data types shared by the core, the nodes and the offline tools.

Everything here is in the core's units: km, km/s, rad, s. Times are seconds on the
simulation clock (the ROS time of the message stamps); `same_epoch` says when two of them
name the same epoch.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass, field

import numpy as np


class Kind(enum.IntEnum):
    """Measurement kind; the values are the constants of ``Measurement.msg``."""

    POSITION = 0
    """GCRF position [x, y, z], km (or observed state channels, see ``PositionModel``)."""
    RANGE_AZ_EL = 1
    """[range km, azimuth rad (north, clockwise, [0, 2pi)), elevation rad]."""
    RA_DEC = 2
    """[right ascension rad in [0, 2pi), declination rad in [-pi/2, pi/2]]: topocentric, in
    the GCRF frame (an optical sensor; two channels, the message's third is 0)."""
    LASER_RANGE = 3
    """[range km]: a two-way laser range, c x the time of flight / 2 (the ILRS's one-way
    range), stamped at its transmit epoch at the station (one channel, the message's second
    and third are 0; `core.measure.laser_range` models it). The filter fuses it with a
    laser network's model (`core.measure.laser_model`); the surrogate does not forecast it
    (normal points minutes apart in passes hours apart: no stream to learn)."""


class Source(enum.IntEnum):
    """Measurement source; the values are the constants of ``Measurement.msg``."""

    SENSOR = 0
    """A real sensor."""
    FORECAST = 1
    """A surrogate forecast."""


class UpdateSource(enum.IntEnum):
    """What last updated a state estimate; the values are those of ``StateEstimate.msg``."""

    NONE = 0
    """No update (prediction only, or truth)."""
    SENSOR = 1
    """A real measurement."""
    FORECAST = 2
    """A surrogate forecast."""


class Cause(enum.StrEnum):
    """Why a measurement was not used, or another counted event.

    The values are the ``/diagnostics`` counter keys; they must not change.
    """

    REJECTED_KIND = "rejected_kind"
    REJECTED_FRAME = "rejected_frame"
    REJECTED_NONFINITE = "rejected_nonfinite"
    REJECTED_NEGATIVE_RANGE = "rejected_negative_range"
    REJECTED_ELEVATION = "rejected_elevation"
    REJECTED_COVARIANCE = "rejected_covariance"
    REJECTED_FUTURE = "rejected_future"
    REJECTED_SOURCE = "rejected_source"
    REJECTED_HORIZON = "rejected_horizon"
    REJECTED_NUMERIC = "rejected_numeric"
    REJECTED_GATE = "rejected_gate"
    REJECTED_STALE = "rejected_stale"
    REJECTED_DUPLICATE = "rejected_duplicate"
    REJECTED_IMPLAUSIBLE = "rejected_implausible"
    REJECTED_CLOCK = "rejected_clock"
    REJECTED_MALFORMED = "rejected_malformed"
    FORECAST_SUPERSEDED = "forecast_superseded"
    IGNORED_BEFORE_IOD = "ignored_before_iod"
    IGNORED_FORECAST_INPUT = "ignored_forecast_input"
    IGNORED_OTHER_OBJECT = "ignored_other_object"
    IOD_PENDING = "iod_pending"
    IOD_FAILED = "iod_failed"
    REINITIALISED = "reinitialised"
    RESET_CLOCK_JUMP = "reset_clock_jump"
    HELD_UNTIL_CLOCK = "held_until_clock"
    HELD_AHEAD_OF_CLOCK = "held_ahead_of_clock"
    REJECTED_ID = "rejected_id"
    REJECTED_BANK_FULL = "rejected_bank_full"
    DROPPED_BEFORE_CLOCK = "dropped_before_clock"
    FORECASTS_ROLLED_BACK = "forecasts_rolled_back"
    FORECAST_INVALID = "forecast_invalid"
    PREDICTIONS_SKIPPED = "predictions_skipped"
    INTERNAL_ERROR = "internal_error"
    UNRECORDABLE_TOPIC = "unrecordable_topic"
    UNRECORDED_BAG_FAILED = "unrecorded_bag_failed"


KIND_NAMES = {Kind.POSITION: "position", Kind.RANGE_AZ_EL: "range_az_el", Kind.RA_DEC: "ra_dec",
              Kind.LASER_RANGE: "laser_range"}
"""The kinds the filter streams, by the name of its ``kind`` parameter (the surrogate: all
but LASER_RANGE)."""


class MotionModel(enum.StrEnum):
    """A motion model: what a filter predicts with, or what a simulated truth follows.

    The values are the names in settings, JSON and ROS parameters; `dynamics` holds the
    right-hand sides of the integrated ones.
    """

    KEPLER = "kepler"
    """Analytic two-body (universal variables, `kepler.propagate`), GCRF km, km/s."""
    TWO_BODY = "two_body"
    """Two-body, integrated with its state transition matrix (`propagation.integrate_stm`)."""
    J2 = "j2"
    """Two-body + J2 about the Earth's pole, integrated with its state transition matrix
    (`propagation.integrate_stm`: compiled fixed-step DOP853, steps of at most 60 s)."""
    DRAG = "drag"
    """Two-body + drag in an exponential atmosphere co-rotating with the Earth, integrated
    with its state transition matrix (`propagation.integrate_stm`, numpy path)."""
    PENDULUM = "pendulum"
    """Damped pendulum [theta rad, theta_dot rad/s] (the paper's toy problem)."""
    VDP = "vdp"
    """Van der Pol oscillator (nondimensional)."""
    CR3BP = "cr3bp"
    """Circular restricted three-body problem, Earth-Moon, rotating frame, nondimensional."""
    HIGH_FIDELITY = "high_fidelity"
    """The high-fidelity force model of one object (`core.motion.force_spec.ForceSpec`:
    geopotential, Sun, Moon, solid tides, solar radiation pressure), integrated with its
    state transition matrix (`core.motion.contexts.augmented_motion`); its ``motion_params``
    say which (`formats.force_choice`)."""


EPOCH_TOLERANCE_S = 1e-6
"""Absolute tolerance of `same_epoch`, s (the relative one is 1e-12)."""


def same_epoch(a: float, b: float) -> bool:
    """Return whether epochs ``a`` and ``b`` (s) are the same up to round-off.

    Round-off of epochs computed as ``t0 + k * cadence`` or ``t - horizon``: 1 µs
    (`EPOCH_TOLERANCE_S`), or 1e-12 relative (~2 ms on Unix times).
    """
    return abs(a - b) <= max(EPOCH_TOLERANCE_S, 1e-12 * abs(b))


@dataclass
class Measurement:
    """One measurement (real or forecast) of an object.

    Attributes
    ----------
    t : float
        Epoch, s (simulation clock).
    z : ndarray (3,) or (2,)
        Position in km (POSITION, GCRF), [range km, az rad, el rad] (RANGE_AZ_EL), or
        [ra rad, dec rad] (RA_DEC, astrometric, GCRF).
    R : ndarray (3, 3) or (2, 2)
        Noise covariance of z in the units of z squared.
    kind, source : int
        A `Kind` and a `Source` (plain ints compare equal).
    frame_id : str
        "gcrf" (`frames.Frame.GCRF`) for POSITION, the station id for RANGE_AZ_EL and
        RA_DEC.
    horizon : float
        s since the last real measurement the forecast came from (0 for SENSOR).
    """

    t: float
    z: np.ndarray
    R: np.ndarray
    kind: int = Kind.POSITION
    source: int = Source.SENSOR
    object_id: str = ""
    frame_id: str = "gcrf"
    horizon: float = 0.0


@dataclass
class StateEstimate:
    """An GCRF state estimate: x (6,) in km, km/s; P (6, 6) in km^2, km^2/s, km^2/s^2."""

    t: float
    x: np.ndarray
    P: np.ndarray = field(default_factory=lambda: np.zeros((6, 6)))
    object_id: str = ""
    update_source: int = UpdateSource.NONE
    nis: float = 0.0

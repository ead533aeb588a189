"""Checks every consumer of measurements applies before using one.

The consumers are the filter's `Tracker`, the `Surrogate`, and through them the nodes and
the offline replay, so that a bad message is refused the same way live and offline, with a
cause (a `/diagnostics` counter name) and a reason a user can act on. Units: km, rad, s.
"""

from __future__ import annotations

import math

import numpy as np

from .types import Cause, Kind, Measurement

HALF_PI = 0.5 * math.pi

Problem = tuple[str, str]
"""(cause, reason); ("", "") when there is none."""

OK: Problem = ("", "")

MAX_CLOCK_LEAD_S = 3600.0
"""Default of how far (s) a measurement's stamp may be ahead of the consumer's clock: far
beyond the lag of a clock message behind a measurement at 10000x (a few hundred sim s),
far below a wall-time stamp in a sim-time graph (months)."""


def measurement_problem(m: Measurement, kind: int | None, frame_id: str = "") -> Problem:
    """Return what is wrong with `m` for a consumer of `kind` from `frame_id`, or `OK`.

    `kind` None and `frame_id` "" accept any. Problems: wrong kind or frame, NaN/inf
    anywhere, an impossible range/az/el, or a covariance that is not symmetric positive
    semi-definite.
    """
    z = np.asarray(m.z, dtype=float)
    R = np.asarray(m.R, dtype=float)
    if kind is not None and m.kind != kind:
        return Cause.REJECTED_KIND, f"kind {m.kind}, expected {kind}"
    if frame_id and m.frame_id != frame_id:
        return Cause.REJECTED_FRAME, f"frame_id {m.frame_id!r}, expected {frame_id!r}"
    if not (math.isfinite(m.t) and np.isfinite(z).all() and np.isfinite(R).all()
            and math.isfinite(m.horizon)):
        return Cause.REJECTED_NONFINITE, f"NaN or inf in stamp, z, covariance or horizon at t={m.t}"
    if m.kind == Kind.RANGE_AZ_EL:
        if z[0] < 0.0:
            return Cause.REJECTED_NEGATIVE_RANGE, f"range {z[0]} km < 0 at t={m.t}"
        if not -HALF_PI <= z[2] <= HALF_PI:
            return (Cause.REJECTED_ELEVATION,
                    f"elevation {z[2]} rad outside [-pi/2, pi/2] at t={m.t}")
    if not is_covariance(R):
        return Cause.REJECTED_COVARIANCE, "covariance is not symmetric positive semi-definite"
    return OK


def razel_possible(z: np.ndarray) -> np.ndarray:
    """Return whether z is a possible range/az/el: range >= 0 and |elevation| <= pi/2.

    z (3, ...) = [range km, azimuth rad, elevation rad]; the result is a bool array (...).
    A forecast that is not possible is withheld, not clipped.
    """
    z = np.asarray(z, dtype=float)
    ok: np.ndarray = (z[0] >= 0.0) & (np.abs(z[2]) <= HALF_PI)
    return ok


def is_covariance(R: np.ndarray) -> bool:
    """Return whether R is symmetric positive semi-definite up to round-off.

    Relative to its scale: asymmetry <= 1e-9 max|R| and eigenvalues >= -1e-12 max|eig| (a
    singular covariance assembled as Q D Q^T has eigenvalues of +-1e-17 |R| where D has a
    zero).
    """
    scale = float(np.abs(R).max(initial=0.0))
    if float(np.abs(R - R.T).max(initial=0.0)) > 1e-9 * scale:
        return False
    eig = np.linalg.eigvalsh(0.5 * (R + R.T))
    return bool(eig[0] >= -1e-12 * np.abs(eig).max())


def ahead_of_clock(t: float, now: float, max_lead_s: float) -> Problem:
    """Refuse a stamp `t` more than `max_lead_s` after the clock time `now` (all s).

    Typically a sensor stamping wall time into a sim-time graph. Fused, it would move the
    filter and the surrogate past every later real measurement. `now` <= 0 means no clock
    yet: no check. Returns (Cause.REJECTED_FUTURE, reason) or `OK`.
    """
    if now > 0.0 and t > now + max_lead_s:
        return (Cause.REJECTED_FUTURE,
                f"t={t} is {t - now:.6g} s ahead of the clock ({now}); more than "
                f"{max_lead_s:g} s ahead is refused (a sensor stamping wall time into a "
                f"sim-time graph?)")
    return OK

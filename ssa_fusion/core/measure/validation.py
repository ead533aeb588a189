"""Checks every consumer of measurements applies before using one.

The consumers are the filter's `Tracker`, the `Surrogate`, and through them the nodes and
the offline replay, so that a bad message is refused the same way live and offline, with a
cause (a `/diagnostics` counter name) and a reason a user can act on. Units: km, rad, s.
"""

from __future__ import annotations

import math

import numpy as np

from ssa_fusion.core.base.rows import MeasurementRows
from ssa_fusion.core.base.types import Cause, Kind, Measurement

HALF_PI = 0.5 * math.pi

Problem = tuple[str, str]
"""(cause, reason); ("", "") when there is none."""

OK: Problem = ("", "")

MAX_CLOCK_LEAD_S = 3600.0
"""Default of how far (s) a measurement's stamp may be ahead of the consumer's clock: far
beyond the lag of a clock message behind a measurement at 10000x (a few hundred sim s),
far below a wall-time stamp in a sim-time graph (months)."""


MAX_RANGE_KM = 1e7
"""Largest plausible range (km): 26 times the Moon's distance; no sensor tracking an Earth
orbiter measures beyond it, and larger values overflow the IOD's arithmetic."""
MIN_RANGE_KM = 1.0
"""Smallest plausible range (km): nothing a sensor tracks in orbit is within 1 km of its
antenna, and the line-of-sight Jacobian grows as 1/range (a range of 0 has no direction)."""
MAX_ABS_VALUE = 1e7
"""Largest plausible magnitude of any measured value (km for positions, rad for angles)."""
MAX_VARIANCE = 1e12
"""Largest plausible covariance entry (km^2 or rad^2): a standard deviation of 1e6 km or
rad carries no information, and such a measurement fused in the initial orbit determination
would poison the filter."""
TWO_PI = 2.0 * math.pi
MAX_OBJECTS = 200_000
"""Default of the most objects a catalog's bank holds (`track_bank.TrackBank`): the public
catalogue's ~30,000 tracked objects several times over, ~100 MB of tracks."""
MAX_ID_CHARS = 128
"""Longest object id or frame id taken (characters): a NORAD number, an international
designator, a station name fit many times over; a megabyte id would be copied into every
estimate and every /diagnostics report."""


def id_problem(object_id: str, frame_id: str) -> Problem:
    """Return `REJECTED_ID` for an object or frame id over `MAX_ID_CHARS`, else `OK`.

    The reason quotes only the id's start: it must stay a line.
    """
    for what, value in (("object_id", object_id), ("frame_id", frame_id)):
        if len(value) > MAX_ID_CHARS:
            return (Cause.REJECTED_ID, f"{what} of {len(value)} characters (at most "
                                       f"{MAX_ID_CHARS}): {value[:32]!r}...")
    return OK


def measurement_problem(m: Measurement, kind: int | tuple[int, ...] | None,
                        frame_id: str = "") -> Problem:
    """Return what is wrong with `m` for a consumer of `kind` from `frame_id`, or `OK`.

    `kind` (one kind or a tuple of them) None and `frame_id` "" accept any. Problems: an
    object or frame id over `MAX_ID_CHARS`, wrong kind or frame, NaN/inf anywhere, an
    impossible range/az/el or ra/dec (declination beyond +-pi/2), an implausible value
    (range below `MIN_RANGE_KM` or beyond `MAX_RANGE_KM`, azimuth or right ascension outside
    [-2pi, 2pi], any value beyond `MAX_ABS_VALUE`, a covariance entry beyond
    `MAX_VARIANCE`), or a covariance that is not symmetric positive semi-definite.
    """
    problem = id_problem(m.object_id, m.frame_id)
    if problem != OK:
        return problem
    z = np.asarray(m.z, dtype=float)
    R = np.asarray(m.R, dtype=float)
    if kind is not None and m.kind not in (kind if isinstance(kind, tuple) else (kind,)):
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
        if z[0] < MIN_RANGE_KM:
            return (Cause.REJECTED_IMPLAUSIBLE,
                    f"range {z[0]:.6g} km below {MIN_RANGE_KM:g} km at t={m.t}")
        if z[0] > MAX_RANGE_KM:
            return (Cause.REJECTED_IMPLAUSIBLE,
                    f"range {z[0]:.6g} km beyond {MAX_RANGE_KM:g} km at t={m.t}")
        if abs(z[1]) > TWO_PI:
            return (Cause.REJECTED_IMPLAUSIBLE,
                    f"azimuth {z[1]:.6g} rad outside [-2pi, 2pi] at t={m.t}")
    if m.kind == Kind.RA_DEC:
        if z.shape != (2,) or R.shape != (2, 2):
            return (Cause.REJECTED_IMPLAUSIBLE,
                    f"ra/dec needs z (2,) and R (2, 2), got {z.shape} and {R.shape} at t={m.t}")
        if not -HALF_PI <= z[1] <= HALF_PI:
            return (Cause.REJECTED_ELEVATION,
                    f"declination {z[1]} rad outside [-pi/2, pi/2] at t={m.t}")
        if abs(z[0]) > TWO_PI:
            return (Cause.REJECTED_IMPLAUSIBLE,
                    f"right ascension {z[0]:.6g} rad outside [-2pi, 2pi] at t={m.t}")
    if float(np.abs(z).max(initial=0.0)) > MAX_ABS_VALUE:
        return (Cause.REJECTED_IMPLAUSIBLE,
                f"a measured value of {float(np.abs(z).max()):.6g} beyond {MAX_ABS_VALUE:g} "
                f"at t={m.t}")
    if float(np.abs(R).max(initial=0.0)) > MAX_VARIANCE:
        return (Cause.REJECTED_IMPLAUSIBLE,
                f"covariance entry {float(np.abs(R).max()):.6g} beyond {MAX_VARIANCE:g} "
                f"(units^2) at t={m.t}")
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
    if not math.isfinite(scale):
        return False
    if scale == 0.0:
        return True
    Rn = R / scale  # entries in [-1, 1]: no overflow in the checks whatever R's magnitude
    if float(np.abs(Rn - Rn.T).max(initial=0.0)) > 1e-9:
        return False
    eig = np.linalg.eigvalsh(0.5 * (Rn + Rn.T))
    return bool(eig[0] >= -1e-12 * np.abs(eig).max())


def state_problem(x: np.ndarray, P: np.ndarray) -> Problem:
    """Return why an estimate (state `x`, covariance `P`, km and km/s) cannot be used, or `OK`.

    Non-finite values (`REJECTED_NONFINITE`), a covariance that is not symmetric positive
    semi-definite (`REJECTED_COVARIANCE`), or a variance over `MAX_VARIANCE`
    (`REJECTED_IMPLAUSIBLE`: a standard deviation of 1e6 km says nothing).
    """
    if not (np.isfinite(x).all() and np.isfinite(P).all()):
        return Cause.REJECTED_NONFINITE, "state or covariance not finite"
    if not is_covariance(P):
        return Cause.REJECTED_COVARIANCE, "covariance not symmetric positive semi-definite"
    if float(np.abs(P).max(initial=0.0)) > MAX_VARIANCE:
        return (Cause.REJECTED_IMPLAUSIBLE,
                f"covariance entry {float(np.abs(P).max()):.3g} over {MAX_VARIANCE:g} km^2")
    return OK


def states_problems(x: np.ndarray, P: np.ndarray) -> np.ndarray:
    """Return the cause `state_problem` gives each estimate, vectorised over the rows.

    States x (k, 6) and covariances P (k, 6, 6), km and km/s: an object array (k,) of
    `Cause` values, "" where the row has none, the same checks in the same order
    (`covariances_ok` for the covariance test). `state_problem` of a row gives its reason.
    """
    x = np.asarray(x, dtype=float).reshape(-1, 6)
    P = np.asarray(P, dtype=float).reshape(-1, 6, 6)
    k = x.shape[0]
    cause = np.full(k, "", dtype=object)
    Pt = np.ascontiguousarray(P.reshape(k, 36).T)  # reduced along the long axis
    finite = np.isfinite(np.ascontiguousarray(x.T)).all(axis=0) & np.isfinite(Pt).all(axis=0)
    cause[~finite] = Cause.REJECTED_NONFINITE
    free = finite.copy()
    bad = free & ~covariances_ok(P)
    cause[bad] = Cause.REJECTED_COVARIANCE
    free &= ~bad
    bad = free & (np.abs(np.where(finite, Pt, 0.0)).max(axis=0, initial=0.0) > MAX_VARIANCE)
    cause[bad] = Cause.REJECTED_IMPLAUSIBLE
    return cause


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


def covariances_ok(R: np.ndarray) -> np.ndarray:
    """Return `is_covariance` of each of the stacked matrices R (M, n, n), as bools (M,).

    The same test, vectorised: relative to each matrix's scale, asymmetry <= 1e-9 and
    eigenvalues >= -1e-12 of the largest in magnitude; all zeros is a covariance, a
    non-finite entry is not.

    A matrix whose diagonal dominates its rows (``S_ii >= sum_j!=i |S_ij|``, as a diagonal
    noise covariance does) has no eigenvalue below 0 (Gershgorin's circles), so it passes
    the eigenvalue test without being decomposed; the others are decomposed.
    """
    R = np.asarray(R, dtype=float)
    m, n = R.shape[0], R.shape[-1]
    # entry (i, j) of every matrix as plane i n + j: reductions over the entries of each
    # matrix run along the long axis (numpy is slow over an axis of 9), the same numbers
    planes = np.ascontiguousarray(R.reshape(m, n * n).T)
    swap = np.arange(n * n).reshape(n, n).T.reshape(-1)  # plane of entry (j, i)
    scale = np.abs(planes).max(axis=0, initial=0.0)
    finite = np.isfinite(scale)
    safe = np.where(finite & (scale > 0.0), scale, 1.0)
    Rn = np.where(finite, planes, 0.0) / safe
    sym = np.abs(Rn - Rn[swap]).max(axis=0, initial=0.0) <= 1e-9
    S = 0.5 * (Rn + Rn[swap])
    A = np.abs(S).reshape(n, n, m)
    row_sum = A[:, 0]
    for j in range(1, n):
        row_sum = row_sum + A[:, j]
    diag = S[np.arange(n) * (n + 1)]
    psd = (2.0 * diag >= row_sum).all(axis=0)  # Gershgorin: no eigenvalue < 0
    rest = np.flatnonzero(~psd)
    if rest.size:
        eig = np.linalg.eigvalsh(S[:, rest].T.reshape(-1, n, n))
        psd[rest] = eig[:, 0] >= -1e-12 * np.abs(eig).max(axis=1, initial=0.0)
    ok: np.ndarray = finite & ((scale == 0.0) | (sym & psd))
    return ok


def rows_problems(rows: MeasurementRows, kind: int) -> np.ndarray:
    """Return the cause `measurement_problem` gives each row for a consumer of `kind`.

    An object array (M,) of `Cause` values, "" where the row has none: the same checks in
    the same order (the first that fails names the cause), vectorised over the rows. For
    each cause, `measurement_problem` of its first row gives the reason to log. Ids are
    checked by length (`MAX_ID_CHARS`); the consumer checks the frame.
    """
    m = len(rows)
    cause = np.full(m, "", dtype=object)
    free = np.ones(m, dtype=bool)  # no cause yet (kept beside `cause`: no string compares)

    def refuse(bad: np.ndarray, why: str) -> None:
        hit = bad & free
        if hit.any():
            cause[hit] = why
            free[hit] = False

    too_long = (np.fromiter(map(len, rows.object_id), np.int64, m) > MAX_ID_CHARS) | \
        (np.fromiter(map(len, rows.frame_id), np.int64, m) > MAX_ID_CHARS)
    refuse(too_long, Cause.REJECTED_ID)
    refuse(rows.kind != kind, Cause.REJECTED_KIND)
    # RA_DEC has two channels: its third, dropped by the per-message conversion, is not read
    radec = rows.kind == Kind.RA_DEC
    z, R = rows.z, rows.R
    if radec.any():
        third = np.array([False, False, True])
        z = np.where(radec[:, None] & third, 0.0, z)
        R = np.where(radec[:, None, None] & (third[:, None] | third[None, :]), 0.0, R)
    zt = np.ascontiguousarray(z.T)  # per channel, per entry: reduced along the long axis
    Rt = np.ascontiguousarray(R.reshape(m, -1).T)
    finite = (np.isfinite(rows.t) & np.isfinite(zt).all(axis=0) & np.isfinite(Rt).all(axis=0)
              & np.isfinite(rows.horizon))
    refuse(~finite, Cause.REJECTED_NONFINITE)
    with np.errstate(invalid="ignore"):
        razel = rows.kind == Kind.RANGE_AZ_EL
        refuse(razel & (z[:, 0] < 0.0), Cause.REJECTED_NEGATIVE_RANGE)
        refuse(razel & ~(np.abs(z[:, 2]) <= HALF_PI), Cause.REJECTED_ELEVATION)
        refuse(razel & ((z[:, 0] < MIN_RANGE_KM) | (z[:, 0] > MAX_RANGE_KM)
                        | (np.abs(z[:, 1]) > TWO_PI)), Cause.REJECTED_IMPLAUSIBLE)
        refuse(radec & ~(np.abs(z[:, 1]) <= HALF_PI), Cause.REJECTED_ELEVATION)
        refuse(radec & (np.abs(z[:, 0]) > TWO_PI), Cause.REJECTED_IMPLAUSIBLE)
        refuse((np.abs(zt).max(axis=0, initial=0.0) > MAX_ABS_VALUE)
               | (np.abs(Rt).max(axis=0, initial=0.0) > MAX_VARIANCE),
               Cause.REJECTED_IMPLAUSIBLE)
    refuse(~covariances_ok(R), Cause.REJECTED_COVARIANCE)
    return cause


def row_measurement(rows: MeasurementRows, i: int) -> Measurement:
    """Return row `i` of `rows` as a `Measurement` (RA_DEC: its two channels)."""
    k = 2 if rows.kind[i] == Kind.RA_DEC else 3
    return Measurement(t=float(rows.t[i]), z=rows.z[i, :k], R=rows.R[i, :k, :k],
                       kind=int(rows.kind[i]), source=int(rows.source[i]),
                       object_id=rows.object_id[i], frame_id=rows.frame_id[i],
                       horizon=float(rows.horizon[i]))

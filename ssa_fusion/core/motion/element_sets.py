"""Element sets and their SGP4/SDP4 states: `CatalogEntry`, `catalog_states`.

A catalog is a list of `CatalogEntry` (object id, name, `sgp4.api.Satrec`); the readers of
TLE/3LE and CCSDS OMM files are `ssa_fusion.formats.element_sets`'. :func:`catalog_states`
propagates every object to many epochs at once with `sgp4.api.SatrecArray` (SGP4 near
Earth, SDP4 for periods >= 225 min, WGS-72 as the element sets assume). SGP4 speaks TEME:
its states are turned to the GCRF, the project's inertial frame, on the way out
(`frames.teme_to_gcrs`; `dynamics.sgp4_ephemeris` does the same for one object): km, km/s.
Epochs are Unix seconds (UTC), as the measurement stamps.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray
from sgp4.api import Satrec, SatrecArray

from ssa_fusion.core.earth.frames import teme_to_gcrs_matrix
from ssa_fusion.core.earth.timescales import DAY_S, UNIX_EPOCH_JD, jd_utc


@dataclass(frozen=True)
class CatalogEntry:
    """One object of a catalog: its id, name and SGP4 element set.

    Attributes
    ----------
    object_id : str
        NORAD catalogue number as a decimal string (the ``object_id`` of its measurements
        and estimates).
    name : str
        Object name (3LE name line, OMM ``OBJECT_NAME``); empty for a bare TLE.
    satrec : sgp4.api.Satrec
        The initialised element set (WGS-72).
    source : str
        Where it was read: ``file:line`` (TLE line 1, OMM/CSV row) or ``file:segment N``.
    """

    object_id: str
    name: str
    satrec: Satrec
    source: str = ""

    @property
    def epoch_unix(self) -> float:
        """Epoch of the element set, Unix seconds (UTC)."""
        sat = self.satrec
        return float((sat.jdsatepoch - UNIX_EPOCH_JD) * DAY_S + sat.jdsatepochF * DAY_S)


@dataclass(frozen=True)
class CatalogStates:
    """SGP4/SDP4 states of a catalog at common epochs.

    Attributes
    ----------
    object_ids : tuple of str
        The objects, in catalog order (axis 0).
    t : ndarray (T,)
        Epochs, Unix seconds (UTC) (axis 1).
    x : ndarray (N, T, 6)
        GCRF position and velocity, km and km/s; NaN where SGP4 failed.
    error : ndarray (N, T) of int
        SGP4 error code (0: fine; see `sgp4.api.SGP4_ERRORS`, e.g. 6: decayed).
    """

    object_ids: tuple[str, ...]
    t: NDArray[np.float64]
    x: NDArray[np.float64]
    error: NDArray[np.int_]


def catalog_states(entries: Sequence[CatalogEntry], t_unix: ArrayLike) -> CatalogStates:
    """SGP4/SDP4 states of every object of `entries` at every epoch of `t_unix`, vectorised.

    Parameters
    ----------
    entries : sequence of CatalogEntry
        The objects (axis 0 of the result).
    t_unix : array_like (T,)
        Epochs, Unix seconds (UTC).

    Returns
    -------
    CatalogStates
        ``x`` (N, T, 6): position km and velocity km/s in the GCRF (SGP4's TEME turned by
        `frames.teme_to_gcrs`), NaN where SGP4 reports an error (``error`` != 0, e.g. an
        object decayed before that epoch).
    """
    jd, fr = jd_utc(np.atleast_1d(np.asarray(t_unix, dtype=float)))
    if not entries:
        return CatalogStates((), jd * 0.0, np.zeros((0, jd.size, 6)),
                             np.zeros((0, jd.size), dtype=int))
    err, r, v = SatrecArray([e.satrec for e in entries]).sgp4(jd, fr)
    t = np.atleast_1d(np.asarray(t_unix, dtype=float))
    m = teme_to_gcrs_matrix(t)  # (T, 3, 3)
    x = np.concatenate([np.einsum("tij,ntj->nti", m, r), np.einsum("tij,ntj->nti", m, v)],
                       axis=-1)
    x[err != 0] = np.nan
    return CatalogStates(tuple(e.object_id for e in entries), t, x, err.astype(int))

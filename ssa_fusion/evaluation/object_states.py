"""Many objects' states, gathered from batches into one array per column: `StatesByObject`.

A catalog run's summary scores tens of millions of estimate rows (30,000 objects for 30 h:
60 million). Kept as a Python tuple per row they took 250 bytes a row (17,787 MiB for those
60 million); here they are kept as the batches' columns (integer object codes,
`catalog_scores.Codes`; epochs; states) and split per object once, at the end
(`StatesByObject.done`): 63 bytes a row held, 122 at the peak (2,000,000 rows).

Units: epochs s (Unix, or any sim time), states GCRF km, km/s.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence
from typing import NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ssa_fusion.evaluation.catalog_scores import Codes


class ObjectStates(NamedTuple):
    """One object's states in epoch order: epochs t (k,) s, states x (k, 6) km, km/s GCRF."""

    t: NDArray[np.float64]
    x: NDArray[np.float64]

    @classmethod
    def of(cls, rows: Iterable[tuple[float, ArrayLike]]) -> ObjectStates:
        """Return the states of (epoch, state) pairs, in epoch order (stable: ties as given)."""
        pairs = list(rows)
        if not pairs:
            return cls(np.zeros(0), np.zeros((0, 6)))
        t = np.array([p[0] for p in pairs], float)
        x = np.array([np.asarray(p[1], float) for p in pairs]).reshape(len(pairs), -1)
        order = np.argsort(t, kind="stable")
        return cls(t[order], x[order])


States = dict[str, ObjectStates]
"""Per object id, its states in epoch order."""


def states_of(rows: Mapping[str, Iterable[tuple[float, ArrayLike]]]) -> States:
    """Return `States` of per-object (epoch, state) pairs (`ObjectStates.of`)."""
    return {oid: ObjectStates.of(r) for oid, r in rows.items()}


class StatesByObject:
    """Rows of many objects, taken batch by batch (`add`), split per object (`done`).

    The rows of an object end in epoch order; rows of one epoch keep the order they came in.
    """

    def __init__(self) -> None:
        self.codes = Codes()
        self._c: list[NDArray[np.int64]] = []
        self._t: list[NDArray[np.float64]] = []
        self._x: list[NDArray[np.float64]] = []
        self.rows = 0
        """Rows taken so far."""

    def add(self, object_id: Sequence[str], t: ArrayLike, x: ArrayLike) -> None:
        """Take rows: object ids (k,), epochs t (k,) s, states x (k, 6) km, km/s GCRF."""
        if not len(object_id):
            return
        self._c.append(self.codes.encode(object_id))
        self._t.append(np.asarray(t, float).reshape(-1))
        self._x.append(np.asarray(x, float).reshape(len(object_id), -1))
        self.rows += len(object_id)

    def done(self) -> States:
        """Return every object's states (and forget the batches: call it once)."""
        if not self.rows:
            return {}
        c = np.concatenate(self._c)
        self._c.clear()
        t = np.concatenate(self._t)
        self._t.clear()
        order = np.lexsort((t, c))  # by object, then epoch; stable
        c, t = c[order], t[order]
        x = np.concatenate(self._x)
        self._x.clear()
        x = x[order]
        del order
        starts = np.flatnonzero(np.r_[True, c[1:] != c[:-1]])
        ends = np.r_[starts[1:], c.size]
        return {self.codes.ids[int(c[a])]: ObjectStates(t[a:b], x[a:b])
                for a, b in zip(starts.tolist(), ends.tolist(), strict=True)}


def merge(parts: Sequence[ObjectStates]) -> ObjectStates:
    """Return the states of `parts` together, in epoch order (stable: ties in part order)."""
    t = np.concatenate([p.t for p in parts])
    order = np.argsort(t, kind="stable")
    return ObjectStates(t[order], np.concatenate([p.x for p in parts])[order])

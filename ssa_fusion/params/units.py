"""Parameter values between the parameters' units (SI) and the core's, by each row's scale.

The parameters are in SI (m, m/s, rad, s), the core in km, km/s, rad, s. A row says how its
unit relates to the core's setting (`rows.Param.scale`: value = core value × scale), so one
function converts any table's values either way (`convert`); no key is converted by hand.
"""

from __future__ import annotations

import enum
from collections.abc import Iterable, Mapping, Sequence
from typing import Any

from ssa_fusion.params.rows import Param


class Units(enum.Enum):
    """The units a value is in."""

    SI = "SI"
    """The parameters' (m, m/s, m²/s³, rad, s)."""
    CORE = "core"
    """The core's (km, km/s, km²/s³, rad, s)."""


Number = int | float
"""A parameter's number (YAML may give an int where a float is meant)."""


def _scaled(value: Number | Sequence[Number], scale: float,
            to: Units) -> float | list[float]:
    """Return one value (a number or a list of numbers) converted by `scale` into `to`."""
    if isinstance(value, Sequence):
        return [float(v) * scale if to is Units.SI else float(v) / scale for v in value]
    return float(value) * scale if to is Units.SI else float(value) / scale


def convert(rows: Iterable[Param], values: Mapping[str, Any], to: Units) -> dict[str, Any]:
    """Return `values` in the units `to`, each by the scale of its row among `rows`.

    Parameters
    ----------
    rows : iterable of Param
        The rows whose `Param.scale` converts (a table, or some of its rows).
    values : mapping
        Values by parameter name, in the other units (SI when `to` is CORE, and back).
        A name without a row, or whose row's scale is 1, keeps its value as it is.
    to : Units
        The units wanted: SI multiplies by the scale, CORE divides by it (arrays element
        by element, returned as lists of floats).

    Returns
    -------
    dict
        The values by name, converted.
    """
    scales = {p.name: p.scale for p in rows if p.scale != 1.0}
    return {name: _scaled(v, scales[name], to) if name in scales else v
            for name, v in values.items()}

"""The high-fidelity force model of one object, from its settings: `force_spec`.

A filter whose motion model is "high_fidelity" records its forces as ``motion_params``
(numbers, as every setting: `core.gaps.estimator.to_dict`); `force_spec` builds the
`core.motion.force_spec.ForceSpec` they say, with the EGM96 geopotential shipped with
ssa_fusion (`icgem.egm96`), and `sphere_params` says them for the geodetic spheres the ILRS
ranges (`core.od.laser_od`'s physics). The keys, each optional:

* ``degree``, ``order``: the geopotential's truncation (20, and the degree);
* ``sun``, ``moon``, ``solid_tides``: 1 or 0 (1);
* ``area_to_mass`` (m^2/kg) and ``cr``: solar radiation pressure on a cannonball (0: none).

Units: m^2/kg; the rest dimensionless.
"""

from __future__ import annotations

import math
from collections.abc import Mapping

from ssa_fusion.core.motion.force_spec import ForceSpec, SrpSpec
from ssa_fusion.core.od import laser_od
from ssa_fusion.formats.icgem import egm96

__all__ = ["KEYS", "SPHERES", "force_spec", "sphere_params"]

KEYS = ("degree", "order", "sun", "moon", "solid_tides", "area_to_mass", "cr")
"""The ``motion_params`` of the "high_fidelity" motion model."""
SPHERES = {7603901: ("LAGEOS-1", math.pi * 0.30**2 / 406.965, laser_od.LAGEOS_CR),
           9207002: ("LAGEOS-2", laser_od.LAGEOS_AREA_TO_MASS, laser_od.LAGEOS_CR)}
"""The spheres whose A/m and Cr are known here, by ILRS id: (name, A/m m^2/kg, Cr)."""


def sphere_params(ilrs_id: int | None) -> dict[str, float]:
    """Return the ``motion_params`` of a geodetic sphere by its ILRS id (`SPHERES`).

    ValueError for another object (its A/m and Cr are not known here).
    """
    if ilrs_id not in SPHERES:
        known = ", ".join(f"{name} ({i})" for i, (name, _, _) in SPHERES.items())
        raise ValueError(f"no cannonball model of the object with ILRS id {ilrs_id}: its "
                         f"area-to-mass ratio and Cr are known for {known}")
    _, am, cr = SPHERES[ilrs_id]
    return {"degree": float(laser_od.DEGREE), "sun": 1.0, "moon": 1.0, "solid_tides": 1.0,
            "area_to_mass": am, "cr": cr}


def force_spec(params: Mapping[str, float]) -> ForceSpec:
    """Return the `ForceSpec` of ``motion_params`` (ValueError naming a bad key or value)."""
    unknown = sorted(set(params) - set(KEYS))
    if unknown:
        raise ValueError(f"unknown high_fidelity motion_params {', '.join(unknown)}: "
                         f"known {', '.join(KEYS)}")
    degree = int(params.get("degree", laser_od.DEGREE))
    order = int(params.get("order", degree))
    am, cr = float(params.get("area_to_mass", 0.0)), float(params.get("cr", 1.0))
    if am < 0.0 or not 0.0 < cr < 3.0:
        raise ValueError(f"area_to_mass {am} m^2/kg must be >= 0, cr {cr} in (0, 3)")
    return ForceSpec(egm96(), degree, order, sun=bool(params.get("sun", 1.0)),
                     moon=bool(params.get("moon", 1.0)),
                     srp=SrpSpec(am, cr) if am > 0.0 else None,
                     solid_tides=bool(params.get("solid_tides", 1.0)))

"""A conjunction of the project's own for the CDM and `pc` command tests (no shared data)."""

from __future__ import annotations

import numpy as np

from ssa_fusion.core.conjunction.encounter import rtn_to_inertial
from ssa_fusion.core.conjunction.probability import collision_probability
from ssa_fusion.formats.ccsds.cdm_out import Conjunction


def own_conjunction(p2: np.ndarray | None = None) -> Conjunction:
    """A LEO conjunction (GCRF states, inertial covariances; `p2` replaces object 2's) and
    its 2D Pc, HBR 15 m."""
    x1 = np.array([6878.0, 10.0, -3.0, 0.01, 7.6127, 0.02])
    x2 = np.array([6878.01, 10.0, -2.97, -0.02, 5.3830, 5.3830])
    p1 = rtn_to_inertial(x1, np.diag([1e-4, 4e-3, 4e-4, 1e-10, 1e-9, 1e-10]) + 1e-12)[0]
    cov2 = rtn_to_inertial(x2, np.diag([4e-4, 1e-2, 1e-3, 1e-9, 1e-9, 1e-9]))[0] \
        if p2 is None else p2
    res = collision_probability(x1, p1, x2, cov2, 0.015)
    return Conjunction(1.7e9 + 0.25, x1, x2, p1, cov2, 0.015, res, ("40001", "40002"),
                       ("SAT A", "DEBRIS B"))

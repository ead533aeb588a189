"""What acts on one object in the high-fidelity force model: `ForceSpec`, `SrpSpec`, `DragSpec`.

A `ForceSpec` says, per object, which forces `high_fidelity.propagate` integrates:

* the geopotential of a `geopotential.GravityField` (EGM96 from `formats.icgem.egm96()`, or any
  ICGEM file) truncated to ``degree`` x ``order`` (default 20 x 20), in the ITRF turned to
  the GCRF with the Earth's orientation of `frames` (IAU 2006/2000A + EOP);
* the Sun and the Moon as point masses (DE421, `earth.ephemeris`), with the indirect term;
* the solid Earth tides of degree 2 the Sun and the Moon raise (``solid_tides``: Love number
  `LOVE_K2` for every order; with a tide-free field such as EGM96 the pair holds the
  permanent tide too), `force_kernel`'s closed form;
* solar radiation pressure on a cannonball (`SrpSpec`: area-to-mass ratio, Cr), with the
  Earth's conical shadow (umbra and penumbra, `srp`);
* drag in the co-rotating exponential atmosphere of `force_model` (`DragSpec`);
* constant empirical accelerations in R, T, N (the parameters ``accel_r/t/n``).

The solve-for parameters are `force_model.PARAMETERS` (`PARAMETERS` here too):
``drag_scale`` k_D, ``accel_r``, ``accel_t``, ``accel_n`` km/s^2 and ``srp_scale`` k_R, a factor
on Cr (nominal 1: the solved Cr is ``k_R SrpSpec.cr``). `ForceSpec.constants` packs the spec
for the compiled kernel (`force_kernel`). The catalog's fast J2 model stays
`force_model.ForceModel`; this spec is for the objects that need metres over days.

Units: km, km/s, s; m^2/kg for area-to-mass, kg/m^2 for the ballistic coefficient.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ssa_fusion.core.base.constants import MU_EARTH, OMEGA_EARTH, R_EARTH
from ssa_fusion.core.motion.force_model import NOMINAL, PARAMETERS
from ssa_fusion.core.motion.geopotential import GravityField

__all__ = [
    "NOMINAL",
    "N_CONST",
    "PARAMETERS",
    "DragSpec",
    "ForceSpec",
    "SrpSpec",
    "parameter_index",
    "point_mass",
]

Array = NDArray[np.float64]

SOLAR_PRESSURE = 4.56e-6
"""Solar radiation pressure at `AU_KM` from the Sun, N/m^2 (IERS Conventions; Orekit's)."""
AU_KM = 149597870.7
"""Astronomical unit, km (IAU 2012)."""
LOVE_K2 = 0.30
"""The degree-2 Love number of the solid tides (IERS Conventions 2010, section 6.2.1: the
nominal k20, k21, k22 are 0.29525, 0.29470, 0.29801 elastic, 0.30190, 0.29830, 0.30102 with
the mantle's anelasticity; one value for all orders, frequency-independent)."""
SUN_RADIUS_KM = 695700.0
"""The Sun's radius, km (IAU 2015 nominal), for the penumbra."""

N_CONST = 24
"""Length of `ForceSpec.constants`."""


@dataclass(frozen=True)
class SrpSpec:
    """A cannonball in sunlight: ``a = nu k_R Cr (A/m) P (AU / d)^2 u`` (`srp`).

    Attributes
    ----------
    area_to_mass : float
        A/m, m^2/kg.
    cr : float
        Radiation pressure coefficient (1: absorbing, 2: specular mirror).
    """

    area_to_mass: float
    cr: float = 1.0


@dataclass(frozen=True)
class DragSpec:
    """Drag in the co-rotating exponential atmosphere (`force_model`'s formula).

    Attributes
    ----------
    bc : float
        Ballistic coefficient m / (Cd A), kg/m^2.
    rho0, h0, scale_height : float
        Density kg/m^3 at altitude ``h0`` km above a sphere of radius `R_EARTH`, and the
        scale height km.
    """

    bc: float = 100.0
    rho0: float = 3.725e-12
    h0: float = 400.0
    scale_height: float = 58.515


def point_mass(gm: float = MU_EARTH, radius: float = R_EARTH) -> GravityField:
    """Return a field with only its central term (two-body), GM km^3/s^2, radius km."""
    c = np.zeros((1, 1))
    c[0, 0] = 1.0
    return GravityField("point mass", gm, radius, c, np.zeros((1, 1)), "none")


@dataclass(frozen=True)
class ForceSpec:
    """The forces on one object (module docstring).

    Attributes
    ----------
    gravity : GravityField
        The geopotential (default: a point mass, two-body; pass `formats.icgem.egm96()`).
    degree : int
        Highest degree of the geopotential (<= the field's).
    order : int or None
        Highest order (None: ``degree``).
    sun, moon : bool
        The Sun and the Moon as third bodies.
    srp : SrpSpec or None
        Solar radiation pressure (None: none).
    drag : DragSpec or None
        Drag (None: none).
    solid_tides : bool
        The solid Earth tides of degree 2 raised by the Sun and the Moon (Love number
        `LOVE_K2`): metres a day on LAGEOS (its orbit's plane turns ~1 m a day further
        without them).
    """

    gravity: GravityField = field(default_factory=point_mass)
    degree: int = 20
    order: int | None = None
    sun: bool = True
    moon: bool = True
    srp: SrpSpec | None = None
    drag: DragSpec | None = None
    solid_tides: bool = False

    def __post_init__(self) -> None:
        """Check the truncation (ValueError naming the problem)."""
        deg = min(self.degree, self.gravity.max_degree)
        if self.gravity.max_degree > 0 and not 0 <= self.degree <= self.gravity.max_degree:
            raise ValueError(f"{self.gravity.name}: degree {self.degree} outside "
                             f"0..{self.gravity.max_degree}")
        if not 0 <= self.truncation[1] <= deg:
            raise ValueError(f"order {self.order} outside 0..{deg}")

    @property
    def truncation(self) -> tuple[int, int]:
        """(degree, order) actually used (a point mass: (0, 0))."""
        deg = min(self.degree, self.gravity.max_degree)
        return deg, deg if self.order is None else min(self.order, deg)

    def constants(self, pole: ArrayLike | None = None) -> Array:
        """Return the kernel's constants (`N_CONST`,) (`force_kernel` reads them by index).

        Parameters
        ----------
        pole : array_like (3,), optional
            The Earth's pole (GCRF unit vector) about which the atmosphere co-rotates.
        """
        p = np.array([0.0, 0.0, 1.0]) if pole is None else np.asarray(pole, dtype=float)
        srp, drag = self.srp, self.drag
        c = np.zeros(N_CONST)
        c[0], c[1] = float(self.sun), float(self.moon)
        if srp is not None:
            c[2] = 1.0
            # km/s^2 per unit nu k_R at 1 AU: P (N/m^2) Cr A/m (m^2/kg) -> m/s^2 -> km/s^2
            c[3] = SOLAR_PRESSURE * srp.cr * srp.area_to_mass * 1e-3 * AU_KM * AU_KM
        c[4], c[5] = SUN_RADIUS_KM, R_EARTH
        if drag is not None:
            c[6] = 1.0
            c[7] = 0.5e3 / drag.bc
            c[8], c[9], c[10] = drag.rho0, drag.h0, drag.scale_height
        c[11] = OMEGA_EARTH
        c[12:15] = p
        c[15] = R_EARTH
        c[22] = LOVE_K2 if self.solid_tides else 0.0
        return c


def parameter_index(names: tuple[str, ...] | list[str]) -> NDArray[np.int64]:
    """Return the indices in `PARAMETERS` of ``names`` (ValueError naming an unknown one)."""
    out = []
    for n in names:
        if n not in PARAMETERS:
            raise ValueError(f"unknown force-model parameter {n!r}: one of "
                             f"{', '.join(PARAMETERS)}")
        out.append(PARAMETERS.index(n))
    return np.array(out, dtype=np.int64)

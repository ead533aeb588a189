"""Orbit determination of laser ranging: the force model and the fit, chosen from physics.

A geodetic sphere ranged by the ILRS (LAGEOS at 5,900 km) is where every force counts at
the centimetre and none is unknown: `laser_force` is the `force_spec.ForceSpec` of such an
object, `fit` the batch least-squares fit (`batch_ls.fit`) of its normal points with a
laser network's model (`laser_model.LaserModels`). The choices, each from physics:

* **forces**: the geopotential to degree and order `DEGREE` (20: the terms beyond move
  LAGEOS by millimetres, its altitude damping degree n by (R/r)^n = 0.52^n), the Sun and
  the Moon (DE421), the solid Earth tides they raise (metres a day: ~1 m a day of
  cross-track drift without them, the fit's residuals 0.22 m instead of 0.03 m), solar
  radiation pressure on the cannonball (conical shadow) with the object's A/m and nominal
  Cr; no drag (the atmosphere at 5,900 km is ~1e-18 kg/m^3). Left out: ocean tides (~10 %
  of the solid ones), the Earth's albedo and infrared, thermal (Yarkovsky-Rubincam) forces
  and general relativity, each <= a few 1e-10 m/s^2 on LAGEOS, the thermal along-track
  drag -3e-12 m/s^2;
* **solve-for**: the epoch state without a prior (the data alone), k_R (a factor on Cr,
  prior `CR_SIGMA`: a cannonball's Cr is known to ~20 % before a fit), each station's range
  bias (its prior from the network: `import crd --bias-sigma`); constant RTN accelerations
  only on request (``accelerations``: on LAGEOS-2's 3 days they come out at 3.7e-8 m/s^2
  radial and -2.0e-8 normal, 7-8 sigma and ten times any force left out: they absorb, they
  do not model; the residuals halve (1.6 -> 0.8 cm), the orbit against the CPF stays as it
  is, 0.28 m);
* **integration**: fixed-step DOP853 of at most `MAX_STEP_S` (120 s: 0.03 mm from 20 s
  steps over 3 days of LAGEOS; 45 s per ~100 steps of an orbit of 3.8 h);
* **noise**: each normal point's own R (`import crd --sigma`, 5 mm: the normal points'
  precision, 1-4 mm one-way in these files (their bins' RMS over the square root of their
  ranges), with the target's signature and the model's short-period errors). What a fit
  leaves (1.6 cm RMS on LAGEOS-2 over 3 days) is mostly not white: drifts of 1-3 cm
  through a pass, the orbit's and the model's errors correlated over minutes; so the
  realistic covariance is the formal one scaled by the weighted RMS squared (the
  a-posteriori variance factor, ~10). It is optimistic for predictions (LAGEOS-2, 12 h on:
  residuals 2.7 times its sigma RMS, the stations new to the fit's biases not in it); the
  state-noise compensation of the filter's `FILTER_Q` would make it 27 times too wide
  instead (white accelerations grow as t^1.5 over a window of days, the forces left out
  are periodic): not used.

`first_guess` takes a reference orbit's state (a CPF prediction: what the stations point
with) as the start of the iterations; the fit has no prior on the state, so where it
converges does not depend on it (`test_laser_od`: from 1 km and 1 m/s off, the same orbit to
a millimetre).

Units: km, km/s, s; GCRF; epochs Unix s (UTC).
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ssa_fusion.core.base.types import Measurement, StateEstimate
from ssa_fusion.core.measure.laser_model import LaserModels
from ssa_fusion.core.motion.force_spec import ForceSpec, SrpSpec
from ssa_fusion.core.motion.geopotential import GravityField
from ssa_fusion.core.od import batch_ls
from ssa_fusion.core.od.batch_ls import BatchFit, BatchOptions

__all__ = [
    "CR_SIGMA",
    "DEGREE",
    "FILTER_Q",
    "LAGEOS_AREA_TO_MASS",
    "LAGEOS_CR",
    "MAX_STEP_S",
    "PRIOR_SIGMA",
    "first_guess",
    "fit",
    "fit_options",
    "laser_force",
]

Array = NDArray[np.float64]

DEGREE = 20
"""Degree and order of the geopotential (module docstring)."""
MAX_STEP_S = 120.0
"""Longest integration step, s (module docstring)."""
CR_SIGMA = 0.2
"""Prior sigma of k_R, the factor on the nominal Cr."""
LAGEOS_AREA_TO_MASS = math.pi * 0.30**2 / 405.38
"""LAGEOS-2's A/m, m^2/kg: a sphere of 60 cm diameter, 405.38 kg (LAGEOS-1: 406.97 kg)."""
LAGEOS_CR = 1.13
"""LAGEOS's radiation pressure coefficient (its 426 retro-reflectors and aluminium shell)."""
ACCELERATION_SIGMA = 1e-11
"""Prior sigma of the constant RTN accelerations when solved for, km/s^2 (1e-8 m/s^2)."""
FILTER_Q = 4e-21
"""The sequential filter's white-noise acceleration PSD, km^2/s^3: what the force model
leaves out (ocean tides, albedo and infrared, thermal forces: ~1e-9 m/s^2 together on
LAGEOS) correlated over about a quarter of an orbit (1 h): q ~ a^2 tau =
(1e-12 km/s^2)^2 3600 s; 0.2 m of position sigma after a 12 h gap."""
PRIOR_SIGMA = (1e-2, 1e-5)
"""The filter's a-priori sigma of position (km) and velocity (km/s) about its a-priori orbit:
10 m and 1 cm/s, ten times what a CPF prediction is off on its day (~1 m, and the velocity
an orbit off by 1 m has: n x 1 m ~ 0.5 mm/s), for the day or two it is carried back or on
to the first normal point."""


def laser_force(gravity: GravityField, area_to_mass: float = LAGEOS_AREA_TO_MASS,
                cr: float = LAGEOS_CR, degree: int = DEGREE) -> ForceSpec:
    """Return the forces on a geodetic sphere (module docstring).

    ``gravity`` the geopotential (`formats.icgem.egm96()`), truncated to ``degree``;
    ``area_to_mass`` m^2/kg and ``cr`` its solar radiation pressure's.
    """
    return ForceSpec(gravity, degree, sun=True, moon=True, srp=SrpSpec(area_to_mass, cr),
                     solid_tides=True)


def fit_options(force: ForceSpec, accelerations: bool = False) -> BatchOptions:
    """Return the batch fit's options (module docstring): k_R (with SRP), the RTN accelerations."""
    acc = ("accel_r", "accel_t", "accel_n") if accelerations else ()
    cr = ("srp_scale",) if force.srp is not None else ()
    return BatchOptions(force=force, solve_for=(*cr, *acc),
                        param_sigma=(1.0, *(ACCELERATION_SIGMA,) * 3, CR_SIGMA),
                        scale_by_rms=True, max_step_s=MAX_STEP_S)


def first_guess(t_ref: ArrayLike, x_ref: ArrayLike, t: float) -> StateEstimate:
    """Return the reference orbit's state nearest epoch ``t`` (GCRF), to start a fit from."""
    tr = np.asarray(t_ref, dtype=float)
    k = int(np.argmin(np.abs(tr - float(t))))
    return StateEstimate(float(tr[k]), np.asarray(x_ref, dtype=float)[k, :6].copy())


def fit(measurements: Sequence[Measurement], models: LaserModels, guess: StateEstimate,
        force: ForceSpec, epoch: float | None = None,
        accelerations: bool = False) -> BatchFit:
    """Fit the laser ranges ``measurements`` (module docstring) from ``guess``.

    The epoch is the last measurement's unless ``epoch`` says otherwise.
    """
    return batch_ls.fit(measurements, models, guess.x[:6], guess.t,
                        fit_options(force, accelerations), epoch)

"""Orbit determination of a laser-ranging bag: the filter's settings, its a-priori orbit, the fit.

What `replay`, `report` and `export oem` do with a bag of `import crd` (`ros.laser_bag`),
through the core:

* `estimator`: the filter (`core.gaps.estimator.laser_filter`) of the object ranged, its
  forces those of its kind (`formats.force_choice.sphere_params`: LAGEOS-1 and -2);
* `apriori`: the orbit the filter starts from, the bag's reference orbit's first state (a
  prediction, as the stations point with; `import crd --reference`), and `tracker` the EKF
  started from it;
* `fit`: the batch least-squares fit of the bag's ranges (`core.od.laser_od.fit`), up to an
  epoch if asked, from the reference state nearest its epoch;
* `GAPS`: what the filter publishes between passes: its own prediction every 300 s (the step
  of the CPF predictions stations point with).

Units: the core's (km, km/s, s).
"""

from __future__ import annotations

from ssa_fusion.core.base.types import StateEstimate
from ssa_fusion.core.filter.tracker import Tracker
from ssa_fusion.core.gaps import estimator as est
from ssa_fusion.core.gaps.estimator import EstimatorConfig
from ssa_fusion.core.gaps.publisher import GapFill
from ssa_fusion.core.measure.laser_model import LaserModels
from ssa_fusion.core.od import laser_od
from ssa_fusion.core.od.batch_ls import BatchFit
from ssa_fusion.formats import force_choice
from ssa_fusion.ros.laser_bag import LaserBag

__all__ = ["GAPS", "apriori", "estimator", "fit", "tracker"]

GAPS = {"predict_period": 300.0, "gap_forecast": str(GapFill.NONE)}
"""The filter's gap parameters for a laser bag (module docstring)."""


def estimator(bag: LaserBag) -> EstimatorConfig:
    """Return the filter of the bag's object (ValueError for an object of unknown A/m)."""
    params = force_choice.sphere_params(bag.ilrs_id)
    return est.laser_filter(bag.network, force_choice.force_spec(params), params)


def apriori(bag: LaserBag) -> StateEstimate:
    """Return the reference orbit's first state (ValueError for a bag without one)."""
    if not bag.reference_t.size:
        raise ValueError("laser ranges alone give no initial orbit: import the bag with "
                         "--reference CPF|OEM (a prediction of the object's orbit)")
    return StateEstimate(float(bag.reference_t[0]), bag.reference_x[0].copy(),
                         object_id=bag.object_id)


def tracker(bag: LaserBag, c: EstimatorConfig) -> Tracker:
    """Return the EKF of `estimator` ``c``, started from `apriori` at its first range."""
    t = est.make_tracker(c, bag.object_id)
    t.set_prior(est.laser_prior(c, apriori(bag)))
    return t


def fit(bag: LaserBag, until: float | None = None, accelerations: bool = False,
        c: EstimatorConfig | None = None) -> BatchFit:
    """Return the batch fit of the bag's ranges (those up to ``until``, Unix s)."""
    ms = [m for m in bag.measurements if until is None or m.t <= until]
    if not ms:
        raise ValueError("no laser range to fit")
    c = c or estimator(bag)
    assert c.force is not None and c.laser is not None
    apriori(bag)  # the same refusal without a reference
    guess = laser_od.first_guess(bag.reference_t, bag.reference_x, ms[-1].t)
    return laser_od.fit(ms, LaserModels(c.laser, bag.meteo), guess, c.force,
                        accelerations=accelerations)

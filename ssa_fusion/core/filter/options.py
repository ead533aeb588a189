"""The options of one filter, the per-object and the catalog one alike: `FilterOptions`.

As open_vins' ``VioManagerOptions`` composes the options of its updaters, `FilterOptions`
composes three small parts, each the settings of one step of the filter:

`NoiseOptions` (predict and update)
    ``q``, ``gate``, ``sigma_bound``: process noise, NIS gate, covariance bound.
`IodOptions` (initialisation and re-initialisation)
    ``iod_samples``, ``iod_max_span_s``, ``p0_sigma``, ``reinit_after``.
`MotionOptions` (the prediction's model)
    ``motion_model``, ``motion_params``, ``max_step_s``.

`tracker.Tracker` (one object) and `track_bank.TrackBank` / `batch_ekf.BatchEKF` (a catalog,
batched) take the same `FilterOptions`, with one set of defaults; `config.EstimatorConfig`
composes it with the surrogate's settings. The field names are unique across the parts, so
`FilterOptions.with_` and `FilterOptions.flat` take and give every field by its name: the
names of the settings the filter node records (`config.to_dict`) and, in SI units, of the
ROS parameters that set them (``iod_max_span`` for ``iod_max_span_s``).

One set of defaults, the per-object and the catalog filter's alike: q 1e-10 km^2/s^3, gate
`DEFAULT_GATE`, no covariance bound; 3 IOD samples within an unlimited span, a P0 floor of
1 km and 1 m/s, no re-initialisation; Kepler, 60 s integration steps. The span is
unlimited so that a scenario measured every 600 s (Molniya) still has an IOD batch; a
catalog user sets the span of one pass (`SKY_FILTER`, the catalog node's and the real-sky
scenarios' filter: 300 s). The catalog bank's own requirements (3 samples or more for
Herrick-Gibbs, 6 states) are checked by `track_bank.TrackBank`.

Units are the core's: km, km/s, s.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field, fields, replace
from typing import Any

from ssa_fusion.core.base.types import MotionModel

__all__ = ["DEFAULT_GATE", "SKY_FILTER", "FilterOptions", "IodOptions", "MotionOptions",
           "NoiseOptions"]

DEFAULT_GATE = 1000.0
"""Default NIS gate: rejects gross glitches only (a 3-channel innovation ~30 sigma away)."""


@dataclass(frozen=True)
class NoiseOptions:
    """Process noise, gate and covariance bound (the predict and update steps).

    Attributes
    ----------
    q : float
        White-noise acceleration spectral density of the process noise, (units/s^2)^2 s
        (km^2/s^3 for an orbit; `ekf.process_noise`).
    gate : float or None
        NIS threshold beyond which an update is rejected (None: no gate; the default only
        catches gross glitches, the estimate's consistency is not gated away).
    sigma_bound : float
        After every prediction, position standard deviations are limited to `sigma_bound`
        times the position's norm and velocity ones to `sigma_bound` times the velocity's
        (`ekf.bound_covariance`; 2 for an orbit: its diameter and twice its speed), so a gap
        of days cannot blow the covariance up beyond what is physically possible; 0 = no
        limit.
    """

    q: float = 1e-10
    gate: float | None = DEFAULT_GATE
    sigma_bound: float = 0.0


@dataclass(frozen=True)
class IodOptions:
    """Initial orbit determination, and when to do it again.

    Attributes
    ----------
    iod_samples : int
        Real measurements used for the initial orbit determination (>= 2; 3 for
        Herrick-Gibbs with range/az/el).
    iod_max_span_s : float
        Longest time (s) one IOD batch may span; a measurement further from the batch's
        first one (or from another station or of another kind) starts a new batch, so the
        initial orbit comes from one pass of one station (Herrick-Gibbs and Gauss need
        closely spaced samples). Unlimited by default.
    p0_sigma : tuple of float, (n,)
        Standard deviations added (in quadrature) to the IOD covariance, state units.
    reinit_after : int
        Real measurements in a row refused by the gate after which the filter forgets its
        state and initialises again (0: never).
    """

    iod_samples: int = 3
    iod_max_span_s: float = math.inf
    p0_sigma: tuple[float, ...] = (1.0, 1.0, 1.0, 1e-3, 1e-3, 1e-3)
    reinit_after: int = 0

    def __post_init__(self) -> None:
        """Hold ``p0_sigma`` as a tuple (a list read from JSON or YAML becomes one)."""
        object.__setattr__(self, "p0_sigma", tuple(self.p0_sigma))


@dataclass(frozen=True)
class MotionOptions:
    """The motion model the filter predicts with.

    Attributes
    ----------
    motion_model : MotionModel
        The model ("placeholder" in the paper); a catalog bank takes "kepler" and the
        integrated ones (`propagation.INTEGRATED_MODELS`).
    motion_params : mapping of str to float
        Parameters of a `dynamics` model (``mu`` km^3/s^2, ``j2``, ``re`` km, ``bc`` kg/m^2,
        the pendulum's m, c, L, ...); for "kepler" only ``mu`` (default
        `constants.MU_EARTH`).
    max_step_s : float
        Longest fixed step of the compiled integration of "two_body", "j2" and "drag"
        (`propagation.integrate_stm`), s.
    """

    motion_model: MotionModel = MotionModel.KEPLER
    motion_params: Mapping[str, float] = field(default_factory=dict)
    max_step_s: float = 60.0

    def __post_init__(self) -> None:
        """Coerce the model and the parameters; check the step (ValueError naming the field)."""
        try:
            object.__setattr__(self, "motion_model", MotionModel(self.motion_model))
        except ValueError:
            raise ValueError(f"motion_model {self.motion_model!r} unknown; known: "
                             f"{', '.join(MotionModel)}") from None
        object.__setattr__(self, "motion_params", dict(self.motion_params))
        if not (self.max_step_s > 0.0 and math.isfinite(self.max_step_s)):
            raise ValueError(f"max_step_s must be > 0 and finite, got {self.max_step_s}")


_PARTS = {"noise": NoiseOptions, "iod": IodOptions, "motion": MotionOptions}
_PART_OF = {f.name: part for part, cls in _PARTS.items() for f in fields(cls)}
"""The part (`FilterOptions` field) each option belongs to, by its name."""


@dataclass(frozen=True)
class FilterOptions:
    """Everything a filter is set with (module docstring).

    Attributes
    ----------
    noise : NoiseOptions
        Process noise, gate, covariance bound.
    iod : IodOptions
        Initial orbit determination and re-initialisation.
    motion : MotionOptions
        The motion model.
    """

    noise: NoiseOptions = field(default_factory=NoiseOptions)
    iod: IodOptions = field(default_factory=IodOptions)
    motion: MotionOptions = field(default_factory=MotionOptions)

    def with_(self, **changes: Any) -> FilterOptions:  # noqa: ANN401
        """Return a copy with options of any part changed, each by its name.

        ``FilterOptions().with_(q=1e-7, iod_samples=7)``; TypeError for an unknown name.
        """
        by_part: dict[str, dict[str, Any]] = {}
        for name, value in changes.items():
            if name not in _PART_OF:
                raise TypeError(f"unknown filter option {name!r}; known: {', '.join(_PART_OF)}")
            by_part.setdefault(_PART_OF[name], {})[name] = value
        return replace(self, **{part: replace(getattr(self, part), **values)
                                for part, values in by_part.items()})

    def flat(self) -> dict[str, Any]:
        """Return every option by its name (what `with_` takes)."""
        return {name: getattr(getattr(self, part), name) for name, part in _PART_OF.items()}


SKY_FILTER = FilterOptions(
    noise=NoiseOptions(q=1e-13, sigma_bound=2.0),
    iod=IodOptions(iod_samples=7, iod_max_span_s=300.0, reinit_after=10),
    motion=MotionOptions(motion_model=MotionModel.J2))
"""The filter of the real sky: the real-sky scenarios' (`sim.sky`) and, in SI, the catalog
filter node's defaults (`params.defaults`).

Two-body + J2; q 1e-13 km^2/s^3 (tuned on the real sky: `sim.sky.SKY_Q`); IOD from 7
measurements within 300 s (one pass of one station), initialised again after 10 real
measurements in a row refused by the gate; covariance bounded by the orbit (2); the P0
floor (1 km, 1 m/s) and the gate are the defaults."""

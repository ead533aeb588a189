"""Hostile input to the surrogate: training on range 1e308 m, azimuth 1e6 rad and
elevation beyond +pi/2, and a covariance of 1e308, once broke the covariance check.
Now `Surrogate.add` refuses each with a cause and buffers nothing; elevation exactly +-pi/2
(zenith/nadir) is a legal value and is buffered."""

import math

import numpy as np
import pytest

from ssa_fusion.core.base.types import Cause, Kind, Measurement
from ssa_fusion.core.gaps.surrogate import Surrogate, SurrogateConfig

R = np.diag([1e-6, 1e-8, 1e-8])


def add(z, cov=R) -> Surrogate:
    s = Surrogate(SurrogateConfig(kind=Kind.RANGE_AZ_EL, frame_id="columbus"))
    s.add(Measurement(1.7e9, np.asarray(z, float), np.asarray(cov, float),
                      kind=Kind.RANGE_AZ_EL, frame_id="columbus"))
    return s


@pytest.mark.parametrize(("z", "cov", "cause"), [
    ([1e305, 1.0, 0.5], R, Cause.REJECTED_IMPLAUSIBLE),  # 1e308 m
    ([0.0, 1.0, 0.5], R, Cause.REJECTED_IMPLAUSIBLE),  # range 0 m
    ([7000.0, 1e6, 0.5], R, Cause.REJECTED_IMPLAUSIBLE),
    ([7000.0, 1.0, float(np.nextafter(math.pi / 2, 4.0))], R, Cause.REJECTED_ELEVATION),
    ([7000.0, 1.0, 0.5], 1e308 * np.eye(3), Cause.REJECTED_IMPLAUSIBLE),
])
def test_surrogate_refuses_implausible_measurements(z, cov, cause):
    s = add(z, cov)
    assert s.rejected[0] == cause
    assert s.last is None  # nothing buffered, nothing to train on


@pytest.mark.parametrize("el", [math.pi / 2, -math.pi / 2, 0.5])
def test_surrogate_takes_legal_elevations_up_to_the_zenith(el):
    s = add([7000.0, 1.0, el])
    assert s.rejected == ("", "")
    assert s.last is not None

"""Tests of the nodes' parameter checks (`params.checks`, the functions only: no ROS).

Every numeric check refuses inf and NaN (max_horizon = inf made the surrogate raise, q = inf
rejected every update, a NaN in p0_sigma kept the filter from ever initialising), and a
list check looks at every element (``min(v) >= 0`` lets a NaN through unless it is first).
"""

import math

import pytest

from ssa_fusion.params.checks import NON_NEGATIVE, POSITIVE
from ssa_fusion.params.tables.filter import PARAMETERS as FILTER
from ssa_fusion.params.tables.sensor_sim import PARAMETERS as SENSOR_SIM

non_negative, positive = NON_NEGATIVE, POSITIVE
_p0_check = FILTER["p0_sigma"].reason
_gaps_check = SENSOR_SIM["gaps"].reason
_noise_check = SENSOR_SIM["noise_sigma"].reason

NON_FINITE = [math.inf, -math.inf, math.nan]


@pytest.mark.parametrize("value", [1, 0.5, 1e-300, 1e300])
def test_positive_accepts_finite_numbers_above_zero(value):
    assert positive(value) is None


@pytest.mark.parametrize("value", [0, 0.0, -1.0, "1", None, *NON_FINITE])
def test_positive_refuses_with_a_reason(value):
    assert positive(value) == "must be a finite number > 0"


@pytest.mark.parametrize("value", [0, 0.0, -0.0, 3, 1e300])
def test_non_negative_accepts_finite_numbers_from_zero(value):
    assert non_negative(value) is None


@pytest.mark.parametrize("value", [-1, -1e-300, "0", None, *NON_FINITE])
def test_non_negative_refuses_with_a_reason(value):
    assert non_negative(value) == "must be a finite number >= 0"


def _with(values: list, i: int, bad: float) -> list:
    return [bad if j == i else v for j, v in enumerate(values)]


P0 = [100.0, 100.0, 100.0, 0.1, 0.1, 0.1]
NOISE = [1000.0, 0.01, 0.01]
GAPS = [3600.0, 600.0, 9000.0, 1200.0]

# (check, a valid value, the reason it gives for an invalid one)
LIST_CHECKS = {
    "p0_sigma": (_p0_check, P0, "needs 6 standard deviations, each a finite number >= 0"),
    "noise_sigma": (_noise_check, NOISE, "needs 3 values, each a finite number >= 0 (or [-1.0])"),
    "gaps": (_gaps_check, GAPS, "starts and lengths must be finite numbers >= 0"),
}


@pytest.mark.parametrize("name", LIST_CHECKS)
def test_list_check_accepts_finite_values_from_zero(name):
    check, good, _ = LIST_CHECKS[name]
    assert check(good) is None
    assert check([0.0] * len(good)) is None


@pytest.mark.parametrize("bad", [-1.0, *NON_FINITE])
@pytest.mark.parametrize("name", LIST_CHECKS)
def test_list_check_refuses_a_bad_element_wherever_it_is(name, bad):
    check, good, reason = LIST_CHECKS[name]
    for i in range(len(good)):
        assert check(_with(good, i, bad)) == reason, (i, bad)


@pytest.mark.parametrize(("check", "value", "reason"), [
    (_p0_check, P0[:5], "needs 6 standard deviations, each a finite number >= 0"),
    (_noise_check, NOISE[:2], "needs 3 values, each a finite number >= 0 (or [-1.0])"),
    (_gaps_check, GAPS[:3], "needs pairs [start_s, length_s, ...]"),
])
def test_list_check_refuses_a_wrong_length(check, value, reason):
    assert check(value) == reason


def test_noise_sigma_keeps_its_scenario_default_marker():
    assert _noise_check([-1.0]) is None

"""`core.gaps.estimator`: one EstimatorConfig, its builders and its JSON form."""

import json
import math

import numpy as np
import pytest

from ssa_fusion.core.base.types import Kind, MotionModel
from ssa_fusion.core.filter.options import FilterOptions
from ssa_fusion.core.gaps import estimator as config
from ssa_fusion.core.gaps.estimator import EstimatorConfig, Lift
from ssa_fusion.core.gaps.surrogate import EciLift, SurrogateConfig
from ssa_fusion.core.motion import kepler

X0 = np.array([6778.0, 0.0, 0.0, 0.0, 5.0, 5.8])


def test_to_dict_round_trips_through_json():
    c = EstimatorConfig(lift=Lift.ECI,
                        filter=FilterOptions().with_(motion_model=MotionModel.J2,
                                                     p0_sigma=(2.0,) * 6, q=3e-9, gate=None),
                        surrogate=SurrogateConfig(delays=77, rank=5, retrain_period_s=math.inf))
    d = json.loads(json.dumps(config.to_dict(c)))
    assert d["frame"] == "gcrf"  # settings recorded with a bag name the states' frame
    back = config.from_dict(d)
    assert back == c
    with pytest.raises(ValueError, match="frame 'eci'"):
        config.from_dict({**d, "frame": "eci"})


def test_from_dict_keeps_the_base_for_missing_keys_and_names_unknown_ones():
    base = EstimatorConfig(filter=FilterOptions().with_(q=5e-8))
    got = config.from_dict({"surrogate": {"delays": 12}}, base)
    assert got.filter.noise.q == 5e-8 and got.surrogate.delays == 12
    with pytest.raises(ValueError, match=r"unknown tracker setting.*qq"):
        config.from_dict({"tracker": {"qq": 1}})
    with pytest.raises(ValueError, match="kind 'radar' unknown"):
        config.from_dict({"kind": "radar"})
    with pytest.raises(ValueError, match="lift 'eci' needs kind range_az_el"):
        EstimatorConfig(kind=Kind.POSITION, lift=Lift.ECI)


def test_builders_wire_the_stream_into_tracker_and_surrogate():
    c = EstimatorConfig(lift=Lift.ECI)
    tracker = config.make_tracker(c, "iss")
    assert tracker.frame_id == "columbus" and tracker.object_id == "iss"
    assert tracker.config == c.filter  # frozen: run-time changes replace Tracker.config
    surrogate = config.make_surrogate(c)
    assert surrogate.config.kind == Kind.RANGE_AZ_EL and surrogate.config.frame_id == "columbus"
    assert isinstance(surrogate.config.lift, EciLift)
    pos = config.make_tracker(EstimatorConfig(kind=Kind.POSITION))
    assert pos.frame_id == "gcrf"


def _with_model(name: str) -> EstimatorConfig:
    return EstimatorConfig(filter=FilterOptions().with_(motion_model=name))


def test_kepler_motion_is_the_analytic_two_body_and_j2_differs_by_j2():
    f = config.motion(EstimatorConfig())
    t0 = 1.7e9
    x1, _ = f(X0, 600.0, t0)
    x_ref, F_ref = kepler.propagate(X0, 600.0)
    np.testing.assert_array_equal(x1, x_ref)
    two = config.motion(_with_model("two_body"))(X0, 600.0, t0)
    np.testing.assert_allclose(two[0], x_ref, atol=1e-6)  # integrated (1e-9 km tolerance)
    np.testing.assert_allclose(two[1], F_ref, atol=1e-6)
    j2 = config.motion(_with_model("j2"))(X0, 600.0, t0)[0]
    assert 0.1 < np.linalg.norm(j2[:3] - x_ref[:3]) < 10.0  # J2 moves LEO km in 10 min

"""Tests for ssa_fusion.core.filter.initiation: the IOD batch on its own, against references that do
not use it.

* Positions: finite differences are linear in the measurements, so the covariance the
  numerical Jacobian gives must equal the closed-form one of the difference weights
  (backward difference for 2 samples, the second-order one-sided stencil for 3).
* Range/az/el: a two-body orbit seen from a station (measurements from `frames.razel_gcrs`,
  truth from `kepler.propagate`): noise free, Herrick-Gibbs reproduces the true state at the
  middle epoch; with noise, the mean NEES of the solution against the truth over Monte Carlo
  runs lies in the two-sided 99.9 % chi-square interval (6 * runs degrees of freedom), at the
  middle epoch (the raw IOD covariance) and at the last (floor zero, moved there by the
  initiator).
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.stats import chi2

from ssa_fusion.core.base.constants import MU_EARTH
from ssa_fusion.core.base.types import Cause, Kind, Measurement, Source
from ssa_fusion.core.earth import frames
from ssa_fusion.core.filter.initiation import InitialState, OrbitInitiator
from ssa_fusion.core.measure.measurement import PositionModel, RazelModel
from ssa_fusion.core.motion import kepler

JD0 = 2460000.5
T0_UNIX = (JD0 - 2440587.5) * 86400.0
STATION = frames.COLUMBUS
CADENCE = 30.0


def _truth() -> np.ndarray:
    """A circular low orbit ~600 km above and 300 km north of the station at t = 0 (GCRF)."""
    lat, lon = STATION.lat_rad, STATION.lon_rad
    up, north = frames.enu_matrix(lat, lon)[2], frames.enu_matrix(lat, lon)[1]
    r = frames.itrs_to_gcrs(STATION.itrs + 600.0 * up + 300.0 * north, T0_UNIX)
    v_dir = np.cross([0.3, 0.2, 1.0], r)
    v = np.sqrt(MU_EARTH / np.linalg.norm(r)) * v_dir / np.linalg.norm(v_dir)
    return np.concatenate([r, v])


def _states(x0: np.ndarray, t: np.ndarray) -> np.ndarray:
    return np.array([kepler.propagate(x0, float(ti))[0] for ti in t])


ZERO = (0.0,) * 6


class _Initiator(OrbitInitiator):
    """An OrbitInitiator with its two settings fixed (the tracker passes them per call)."""

    def __init__(self, model, samples: int, p0_sigma: tuple[float, ...] = ZERO) -> None:
        super().__init__(lambda x, dt, _t0: kepler.propagate(x, dt), model, 6)
        self.settings = (samples, p0_sigma)

    def add(self, m):
        return super().add(m, *self.settings)


def _pos_initiator(samples: int, p0_sigma: tuple[float, ...] = ZERO) -> _Initiator:
    return _Initiator(PositionModel(), samples, p0_sigma)


def _rae_initiator() -> _Initiator:
    return _Initiator(RazelModel(STATION, JD0), 3)


def _pos(t: float, z: np.ndarray, R: np.ndarray, source: int = Source.SENSOR) -> Measurement:
    return Measurement(t, np.asarray(z, float), R, kind=Kind.POSITION, source=source)


def _rae(t: float, z: np.ndarray, R: np.ndarray) -> Measurement:
    return Measurement(t, np.asarray(z, float), R, kind=Kind.RANGE_AZ_EL,
                       frame_id=STATION.name)


# ------------------------------------------------------------------------------ rules
def test_rules_during_iod():
    ini = _pos_initiator(3)
    R = np.eye(3)
    assert ini.add(_pos(0.0, [7000, 0, 0], R, Source.FORECAST)) == (
        Cause.IGNORED_BEFORE_IOD, "forecast before IOD")
    assert ini.add(_pos(30.0, [7000, 1, 0], R))[0] == Cause.IOD_PENDING
    assert ini.add(_pos(29.0, [7000, 1, 0], R)) == (Cause.REJECTED_STALE, "t=29.0 during IOD")
    assert ini.add(_pos(30.0, [7000, 1, 0], R)) == (Cause.REJECTED_DUPLICATE,
                                                    "t=30.0 during IOD")
    other = Measurement(30.0, np.array([7000.0, 1, 0]), R, kind=Kind.POSITION,
                        frame_id="elsewhere")
    assert ini.add(other)[0] == Cause.IGNORED_BEFORE_IOD  # another station, same epoch
    assert len(ini.batch) == 1
    assert ini.add(_pos(60.0, [7000, 2, 0], R))[0] == Cause.IOD_PENDING
    assert len(ini.batch) == 2
    got = ini.add(_pos(90.0, [7000, 3, 0], R))
    assert isinstance(got, InitialState) and got.t == 90.0
    assert ini.batch == []  # a new batch starts (stamps are no longer compared to the old)
    assert ini.add(_pos(10.0, [7000, 0, 0], R))[0] == Cause.IOD_PENDING


def test_at_least_two_samples():
    ini = _pos_initiator(1)
    assert ini.add(_pos(0.0, [7000, 0, 0], np.eye(3)))[0] == Cause.IOD_PENDING
    assert isinstance(ini.add(_pos(30.0, [7000, 1, 0], np.eye(3))), InitialState)


def test_settings_apply_to_the_batch_being_collected():
    """The settings come with each call, so a run-time change applies to the current batch."""
    ini = OrbitInitiator(lambda x, dt, _t0: kepler.propagate(x, dt), PositionModel(), 6)
    R = np.eye(3)
    assert ini.add(_pos(0.0, [7000, 0, 0], R), 4, ZERO)[0] == Cause.IOD_PENDING
    assert ini.add(_pos(30.0, [7000, 1, 0], R), 4, ZERO)[0] == Cause.IOD_PENDING
    got = ini.add(_pos(60.0, [7000, 2, 0], R), 3, (2.0,) * 6)
    assert isinstance(got, InitialState)
    ref = OrbitInitiator(lambda x, dt, _t0: kepler.propagate(x, dt), PositionModel(), 6)
    _, _, P_iod = ref.solve([_pos(30.0 * j, [7000, j, 0], R) for j in range(3)])
    np.testing.assert_allclose(got.P, P_iod + 4.0 * np.eye(6), atol=1e-12)


@pytest.mark.filterwarnings("ignore::RuntimeWarning")
def test_non_finite_solution_fails_and_empties_the_batch():
    ini = _pos_initiator(2)
    ini.add(_pos(0.0, [-1e308, 0, 0], np.eye(3)))
    assert ini.add(_pos(1.0, [1e308, 0, 0], np.eye(3)))[0] == Cause.IOD_FAILED
    assert ini.batch == []


# ------------------------------------------------------------------------------ positions
@pytest.mark.parametrize("samples", [2, 3])
def test_position_covariance_equals_the_closed_form_of_the_stencil(samples):
    """Noise free, the FD state is the truth to the stencil's truncation error; its
    covariance is w-weighted sums of the R_j: pos = R_last, vel = sum w_j^2 R_j,
    cross = w_last R_last (w: derivative weights at the last node)."""
    x0 = _truth()
    t = CADENCE * np.arange(samples)
    truth = _states(x0, t)
    Rs = [np.diag([1.0, 2.0, 0.5]) * (j + 1) for j in range(samples)]
    Rs[-1] = Rs[-1] + 0.1 * (np.ones((3, 3)) - np.eye(3))  # correlated channels too
    w = (np.array([-1.0, 1.0]) / CADENCE if samples == 2
         else np.array([1.0, -4.0, 3.0]) / (2 * CADENCE))
    ini = _pos_initiator(samples)
    for j in range(samples):
        got = ini.add(_pos(float(t[j]), truth[j, :3], Rs[j]))
    assert isinstance(got, InitialState) and got.t == t[-1]
    np.testing.assert_array_equal(got.x[:3], truth[-1, :3])
    # truncation: ~ a dt / 2 (backward) or ~ jerk dt^2 / 3 (second order)
    np.testing.assert_allclose(got.x[3:], truth[-1, 3:], atol=0.15 if samples == 2 else 5e-3)
    P_ref = np.zeros((6, 6))
    P_ref[:3, :3] = Rs[-1]
    P_ref[3:, 3:] = sum(wj**2 * Rj for wj, Rj in zip(w, Rs, strict=True))
    P_ref[:3, 3:] = P_ref[3:, :3] = w[-1] * Rs[-1]
    np.testing.assert_allclose(got.P, P_ref, rtol=1e-6, atol=1e-12)


def test_position_floor_is_added_in_quadrature():
    sigma = (1.0, 2.0, 3.0, 0.1, 0.2, 0.3)
    a, b = _pos_initiator(2), _pos_initiator(2, sigma)
    for t, z in ((0.0, [7000.0, 0, 0]), (30.0, [7000.0, 200.0, 0])):
        ga, gb = a.add(_pos(t, z, np.eye(3))), b.add(_pos(t, z, np.eye(3)))
    assert isinstance(ga, InitialState) and isinstance(gb, InitialState)
    np.testing.assert_array_equal(ga.x, gb.x)
    np.testing.assert_allclose(gb.P - ga.P, np.diag(np.square(sigma)), atol=1e-12)


# ------------------------------------------------------------------------------ range/az/el
def _rae_truth() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    t = CADENCE * np.arange(3)
    x = _states(_truth(), t)
    z = frames.razel_gcrs(x, T0_UNIX + t, STATION)
    return t, x, z


def test_herrick_gibbs_noise_free_reproduces_the_kepler_state():
    t, x, z = _rae_truth()
    assert np.all(z[:, 2] > np.radians(20.0))  # well above the horizon, away from zenith
    ini = _rae_initiator()
    batch = [_rae(float(ti), zi, np.eye(3)) for ti, zi in zip(t, z, strict=True)]
    t_init, x_hg, _ = ini.solve(batch)
    assert t_init == t[1]
    np.testing.assert_allclose(x_hg[:3], x[1, :3], atol=1e-8)
    np.testing.assert_allclose(x_hg[3:], x[1, 3:], atol=1e-5)  # Herrick-Gibbs: O(dt^4)


def test_herrick_gibbs_is_consistent_with_its_covariance():
    t, x, z = _rae_truth()
    sigma = np.array([0.1, 1e-3, 1e-3])
    R = np.diag(sigma**2)
    rng = np.random.default_rng(11)
    runs = 300
    nees_mid, nees_last = [], []
    for _ in range(runs):
        ini = _rae_initiator()
        ms = [_rae(float(ti), zi + sigma * rng.standard_normal(3), R)
              for ti, zi in zip(t, z, strict=True)]
        _, x_hg, P_hg = ini.solve(ms)
        err = x_hg - x[1]
        nees_mid.append(err @ np.linalg.solve(P_hg, err))
        for m in ms:
            got = ini.add(m)
        assert isinstance(got, InitialState) and got.t == t[-1]
        err = got.x - x[-1]
        nees_last.append(err @ np.linalg.solve(got.P, err))
    lo, hi = chi2.ppf([0.0005, 0.9995], 6 * runs) / runs
    assert lo < np.mean(nees_mid) < hi, (np.mean(nees_mid), lo, hi)
    assert lo < np.mean(nees_last) < hi, (np.mean(nees_last), lo, hi)

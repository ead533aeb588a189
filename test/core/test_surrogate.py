"""Tests for ssa_fusion.core.gaps.surrogate: which epochs get a forecast, when, with what value and
covariance -- through the public behaviour only (Hankel-DMD internals may change).

Data: the iss_j2_pos / iss_j2_rae scenarios shortened to 360 training samples (3 h at 30 s)
and 60 delays instead of 720 / 120, so one fit takes milliseconds. `retrain_period_s` is set
huge where the periodic refit is irrelevant: a gap always refits on the buffer up to the last
real measurement, so this changes no forecast, only the run time.
"""

from __future__ import annotations

import functools
import math

import numpy as np
import pytest

from ssa_fusion.core.base.types import Kind, Measurement, Source
from ssa_fusion.core.gaps.surrogate import EciLift, Surrogate, SurrogateConfig
from ssa_fusion.sim import scenarios as sc
from ssa_fusion.sim.simulate import Simulation, simulate

DT = 30.0
DELAYS = 60
TRACK_N = 360
GAP_N = 186  # one ISS orbit
R_FREE = np.eye(3) * 1e-6  # the sensor covariance claimed for noise-free data, km^2


@functools.cache
def _sim(name: str = "iss_j2_pos", seed: int = 0, **changes) -> Simulation:
    s = sc.get(name).with_(track_s=TRACK_N * DT, gap_s=GAP_N * DT, after_s=0.0,
                           delays=DELAYS, **changes)
    return simulate(s, seed=seed)


def _config(**changes) -> SurrogateConfig:
    cfg = dict(buffer_s=TRACK_N * DT, delays=DELAYS, retrain_period_s=1e12,
               max_horizon_s=7200.0)
    cfg.update(changes)
    return SurrogateConfig(**cfg)


def _meas(sim: Simulation, i: int, R: np.ndarray | None = None) -> Measurement:
    kind = sim.scenario.kind
    return Measurement(float(sim.t[i]), sim.z[i].copy(),
                       (sim.R if R is None else R).copy(), kind=kind, source=Source.SENSOR,
                       object_id="iss", frame_id="columbus" if kind == Kind.RANGE_AZ_EL else "gcrf")


def _track(sur: Surrogate, sim: Simulation, n: int = TRACK_N, R=None) -> list[Measurement]:
    """Add the first n samples; returns every forecast add() released (should be none)."""
    out = []
    for i in range(n):
        out += sur.add(_meas(sim, i, R))
    return out


def _same(a: list[Measurement], b: list[Measurement]) -> None:
    assert [m.t for m in a] == [m.t for m in b]
    for ma, mb in zip(a, b, strict=True):
        np.testing.assert_array_equal(ma.z, mb.z)
        np.testing.assert_array_equal(ma.R, mb.R)
        assert (ma.horizon, ma.kind, ma.source, ma.frame_id) == (
            mb.horizon, mb.kind, mb.source, mb.frame_id)


# ------------------------------------------------------------------------------ on time / gap
def test_no_forecasts_while_measurements_arrive_on_time():
    sim = _sim()
    sur = Surrogate(_config(retrain_period_s=3000.0))
    for i in range(TRACK_N):
        assert sur.add(_meas(sim, i, R_FREE)) == []
        # right up to the end of the grace period of the next epoch nothing is due
        t = float(sim.t[i])
        assert sur.due(t) == []
        assert sur.due(t + DT) == []
        assert sur.due(t + 1.49 * DT) == []
    assert sur.status.startswith("fitted")
    assert sur.fits >= 1


def test_gap_forecasts_each_missed_epoch_once_on_the_cadence_grid():
    sim = _sim()
    sur = Surrogate(_config())
    assert _track(sur, sim, R=R_FREE) == []
    t_last = float(sim.t[TRACK_N - 1])
    got: list[Measurement] = []
    now = t_last
    while now < t_last + 40 * DT:
        now += 7.0
        new = sur.due(now)
        assert sur.due(now) == []  # asking again at the same time: nothing new
        # an epoch is released once it is more than grace * dt overdue, not earlier
        assert all(m.t + 0.5 * DT <= now + 1e-6 for m in new)
        got += new
    k_max = math.floor((now - 0.5 * DT - t_last) / DT)
    assert [m.t for m in got] == [t_last + k * DT for k in range(1, k_max + 1)]
    for k, m in enumerate(got, start=1):
        assert m.horizon == k * DT
        assert m.source == Source.FORECAST and m.kind == Kind.POSITION
        assert m.frame_id == "gcrf" and m.object_id == "iss"
        assert np.isfinite(m.z).all() and m.z.shape == (3,) and m.R.shape == (3, 3)
    # the measurement that ends the gap releases the epochs still owed before it
    end = TRACK_N + 50
    owed = sur.add(_meas(sim, end, R_FREE))
    assert [m.t for m in owed] == [t_last + k * DT for k in range(k_max + 1, 51)]
    assert sur.due(float(sim.t[end]) + 1.4 * DT) == []


def test_never_beyond_max_horizon():
    sim = _sim()
    sur = Surrogate(_config(max_horizon_s=20 * DT))
    _track(sur, sim, R=R_FREE)
    t_last = float(sim.t[TRACK_N - 1])
    got = sur.due(t_last + 1000 * DT)
    assert len(got) == 20
    assert max(m.horizon for m in got) <= 20 * DT
    assert got[-1].t == t_last + 20 * DT
    assert sur.due(t_last + 5000 * DT) == []
    # the gap ends after the horizon: nothing more is owed
    assert sur.add(_meas(sim, TRACK_N + 100, R_FREE)) == []


def test_gap_shorter_than_max_horizon_via_add_only():
    sim = _sim()
    sur = Surrogate(_config(max_horizon_s=20 * DT))
    _track(sur, sim, R=R_FREE)
    owed = sur.add(_meas(sim, TRACK_N - 1 + 8, R_FREE))  # 7 missed epochs
    assert [round(m.horizon / DT) for m in owed] == list(range(1, 8))


def test_forecasts_do_not_depend_on_when_due_is_called():
    sim = _sim()
    end = TRACK_N - 1 + 120  # a 119-epoch gap, ended by a real measurement
    t_end = float(sim.t[end])
    t_last = float(sim.t[TRACK_N - 1])

    def run(due_times) -> list[Measurement]:
        sur = Surrogate(_config())
        out = _track(sur, sim, R=R_FREE)
        for now in due_times:
            out += sur.due(now)
        out += sur.add(_meas(sim, end, R_FREE))
        return out

    rng = np.random.default_rng(3)
    small_steps = run(np.arange(t_last, t_end, 3.7))
    one_big_step = run([t_end - 1.0])
    add_only = run([])
    random_times = run(np.sort(rng.uniform(t_last - 100.0, t_end, 25)))
    assert [m.t for m in add_only] == [t_last + k * DT for k in range(1, 120)]
    _same(small_steps, add_only)
    _same(one_big_step, add_only)
    _same(random_times, add_only)


def test_periodic_retraining_schedule_does_not_change_gap_forecasts():
    """A gap always starts from a model fitted on the buffer up to the last real sample."""
    sim = _sim()
    a, b = Surrogate(_config(retrain_period_s=1500.0)), Surrogate(_config())
    _track(a, sim, R=R_FREE)
    _track(b, sim, R=R_FREE)
    t = float(sim.t[TRACK_N - 1]) + 30 * DT
    got = a.due(t)
    assert len(got) == 29  # epochs 1..29 of the gap (grace 0.5 cadence)
    _same(got, b.due(t))


# ------------------------------------------------------------------------------ covariance
@pytest.mark.parametrize(("name", "changes"), [
    ("iss_j2_pos", {"noise_sigma": (1.0, 1.0, 1.0)}),
    ("iss_j2_pos", {}),
    ("iss_j2_rae", {"noise_sigma": (0.1, 1e-3, 1e-3)}),
])
def test_forecast_covariance_grows_with_horizon_and_is_at_least_R(name, changes):
    sim = _sim(name, **changes)
    R = sim.R if sim.sigma.any() else R_FREE
    sur = Surrogate(_config())
    _track(sur, sim, R=R)
    got = sur.due(float(sim.t[TRACK_N - 1]) + (GAP_N + 0.6) * DT)
    # every missed epoch gets a forecast, or is counted as withheld when the raw range/az/el
    # forecast is not a possible measurement (negative range, |el| > pi/2)
    assert len(got) + sur.invalid == GAP_N and len(got) > 0
    tr = np.array([np.trace(m.R) for m in got])
    assert (np.diff(tr) >= -1e-12 * tr[1:]).all()  # non-decreasing
    for m in got:
        np.testing.assert_array_equal(m.R, m.R.T)
        w = np.linalg.eigvalsh(m.R - R)
        assert w.min() >= -1e-9 * max(1.0, w.max())  # R_forecast - R_sensor is PSD
    if sim.sigma.any():
        assert tr[-1] > 2.0 * tr[0]  # honestly grows over an orbit


# ------------------------------------------------------------------------------ accuracy
def test_forecast_accuracy_noise_free_position_over_one_orbit():
    """Noise-free ISS positions (two-body + J2): with 360 samples / 60 delays the forecast
    stays within ~0.25 km over a full orbit (measured 0.24 km; 720 / 120 delays, the paper's
    setting, gives ~1e-5 km). Tolerance 1 km = 1.5e-4 of the orbit radius."""
    sim = _sim()
    sur = Surrogate(_config())
    _track(sur, sim, R=R_FREE)
    got = sur.due(float(sim.t[TRACK_N - 1]) + (GAP_N + 0.6) * DT)
    idx = sim.gap_index
    assert [m.t for m in got] == list(sim.t[idx])
    err = np.linalg.norm(np.array([m.z for m in got]) - sim.z_true[idx], axis=1)
    assert err[0] < 1e-3  # one step ahead: metres
    assert err.max() < 1.0  # km, orbit radius ~6800 km


def test_range_az_el_forecasts_keep_azimuth_wrapped():
    sim = _sim("iss_j2_rae", noise_sigma=(0.1, 1e-3, 1e-3))
    sur = Surrogate(_config())
    _track(sur, sim)
    got = sur.due(float(sim.t[TRACK_N - 1]) + (GAP_N + 0.6) * DT)
    az = np.array([m.z[1] for m in got])
    assert ((az >= 0.0) & (az < 2 * np.pi)).all()
    assert all(m.kind == Kind.RANGE_AZ_EL and m.frame_id == "columbus" for m in got)


# ------------------------------------------------------------------------------ cannot fit
def test_too_few_samples_no_forecast_status_says_why():
    sim = _sim()
    need = 2 * DELAYS + 2
    sur = Surrogate(_config())
    _track(sur, sim, n=need - 1, R=R_FREE)
    assert sur.due(float(sim.t[need - 2]) + 50 * DT) == []
    assert sur.status.startswith("cannot fit")
    assert str(need - 1) in sur.status and str(need) in sur.status
    # one more sample and it forecasts
    sur = Surrogate(_config())
    _track(sur, sim, n=need, R=R_FREE)
    assert len(sur.due(float(sim.t[need - 1]) + 10.6 * DT)) == 10
    assert sur.status.startswith("fitted")


def test_no_measurements_no_forecast():
    sur = Surrogate(_config())
    assert sur.due(1e9) == []
    assert sur.last is None and math.isnan(sur.cadence())


def test_constant_data_no_forecast_status_says_why():
    sur = Surrogate(_config())
    for i in range(TRACK_N):
        assert sur.add(Measurement(1000.0 + i * DT, np.array([7000.0, 0.0, 0.0]), R_FREE)) == []
    assert sur.due(1000.0 + TRACK_N * DT + 20 * DT) == []
    assert sur.status.startswith("cannot fit") and "constant" in sur.status
    assert sur.fits == 0


def test_gap_inside_buffer_keeps_regular_tail_or_says_why():
    sim = _sim()
    sur = Surrogate(_config())
    # too few samples before the hole to forecast it (so it is not filled), and only 50
    # regular samples after it
    for i in list(range(0, 100)) + list(range(110, 160)):
        sur.add(_meas(sim, i, R_FREE))
    assert sur.due(float(sim.t[159]) + 10 * DT) == []
    assert "cadence" in sur.status
    for i in range(160, 240):  # 130 regular samples now: enough for 60 delays
        sur.add(_meas(sim, i, R_FREE))
    assert len(sur.due(float(sim.t[239]) + 10.6 * DT)) == 10
    assert sur.status.startswith("fitted on 130 samples")


# ------------------------------------------------------------------------------ reset
def test_reset_forgets_everything():
    sim = _sim()
    sur = Surrogate(_config())
    _track(sur, sim, R=R_FREE)
    assert sur.due(float(sim.t[TRACK_N - 1]) + 5.6 * DT)
    sur.reset()
    assert sur.last is None and math.isnan(sur.cadence())
    assert sur.due(float(sim.t[TRACK_N - 1]) + 100 * DT) == []
    # after the reset (a backwards clock jump) it starts from scratch: a few samples are not
    # enough, and the full history again gives exactly what a new surrogate gives
    for i in range(10):
        assert sur.add(_meas(sim, i, R_FREE)) == []
    assert sur.due(float(sim.t[9]) + 20 * DT) == []
    sur.reset()
    fresh = Surrogate(_config())
    _track(sur, sim, R=R_FREE)
    _track(fresh, sim, R=R_FREE)
    t = float(sim.t[TRACK_N - 1]) + 30 * DT
    _same(sur.due(t), fresh.due(t))


def _gap_forecasts(sur: Surrogate, sim: Simulation) -> list[Measurement]:
    return sur.due(float(sim.t[TRACK_N - 1]) + 20.6 * DT)


def test_a_stray_kind_or_frame_is_refused_and_changes_nothing():
    sim = _sim()
    clean, sur = Surrogate(_config()), Surrogate(_config())
    _track(clean, sim, R=R_FREE)
    _track(sur, sim, TRACK_N - 1, R=R_FREE)
    stray = _meas(sim, TRACK_N - 1, R_FREE)
    stray.kind, stray.frame_id = Kind.RANGE_AZ_EL, "columbus"
    assert sur.problem(stray)[0] == "rejected_kind"
    other = _replace(_meas(sim, TRACK_N - 1, R_FREE), frame_id="teme")
    assert sur.problem(other)[0] == "rejected_frame"
    for m in (stray, other):
        assert sur.add(m) == []
        assert "ignored" in sur.status
    sur.add(_meas(sim, TRACK_N - 1, R_FREE))
    _same(_gap_forecasts(sur, sim), _gap_forecasts(clean, sim))


def test_a_configured_kind_and_frame_are_not_taken_from_a_stray_first_message():
    """Without a configured kind the first message would decide it for the whole run."""
    sim = _sim()
    clean = Surrogate(_config(kind=Kind.POSITION, frame_id="gcrf"))
    sur = Surrogate(_config(kind=Kind.POSITION, frame_id="gcrf"))
    stray = _meas(sim, 0, R_FREE)
    stray.kind, stray.frame_id, stray.t = Kind.RANGE_AZ_EL, "columbus", stray.t - DT
    assert sur.add(stray) == [] and sur.last is None
    _track(clean, sim, R=R_FREE)
    _track(sur, sim, R=R_FREE)
    _same(_gap_forecasts(sur, sim), _gap_forecasts(clean, sim))


@pytest.mark.parametrize(("z", "cause"), [
    ((-1.0, 1.0, 0.2), "rejected_negative_range"),
    ((800.0, 1.0, 2.0), "rejected_elevation"),
])
def test_impossible_range_az_el_is_refused(z, cause):
    sim = _sim("iss_j2_rae")
    sur = Surrogate(_config())
    _track(sur, sim, 10)
    m = _replace(_meas(sim, 10), z=np.array(z))
    assert sur.problem(m)[0] == cause
    assert sur.add(m) == [] and sur.last.t == sim.t[9]


def test_stamp_jitter_within_tolerance_is_fitted_as_the_cadence():
    """Real stamps jitter; +-20 ms at 30 s (0.07 %) used to stop every fit."""
    sim = _sim()
    rng = np.random.default_rng(0)
    clean = Surrogate(_config())
    _track(clean, sim, R=R_FREE)
    ref = _gap_forecasts(clean, sim)
    for cadence in (0.0, DT):
        sur = Surrogate(_config(cadence_s=cadence))
        for i in range(TRACK_N):
            sur.add(_replace(_meas(sim, i, R_FREE), t=float(sim.t[i]) + rng.uniform(-0.2, 0.2)))
        got = _gap_forecasts(sur, sim)[:20]  # a jittered last stamp may make it 21
        assert len(got) == 20, sur.status
        assert sur.status.startswith("fitted on 360 samples")
        err = max(np.abs(a.z - b.z).max() for a, b in zip(got, ref, strict=True))
        assert err < 1.0  # km: 0.2 s of a 7.7 km/s orbit is 1.5 km at most per sample


@pytest.mark.parametrize("t0", [0.0, None])  # stamps from 0 (cr3bp, pendulum) or Unix time
def test_a_late_stamp_is_its_own_epoch_not_a_missed_one(t0):
    """Every other stamp 2.4 s (8 %) late: no forecast for the epoch a real measurement
    covers, while tracking or when it ends a gap, and no refit forced by one."""
    sim = _sim()
    shift = (0.0 if t0 is None else t0 - float(sim.t[0]))
    late = [0.08 * DT if i % 2 else 0.0 for i in range(TRACK_N)]
    for cadence in (0.0, DT):
        sur = Surrogate(_config(cadence_s=cadence))
        released = []
        for i in range(TRACK_N):
            released += sur.add(_replace(_meas(sim, i, R_FREE), t=sim.t[i] + shift + late[i]))
        assert released == [] and sur.fits == 0
        assert abs(sur.cadence() - DT) < 1e-3
        i = TRACK_N + 10  # the gap ends with a late stamp: forecasts for epochs before it only
        end = _replace(_meas(sim, i, R_FREE), t=sim.t[i] + shift + 0.08 * DT)
        owed = sur.add(end)
        assert len(owed) == 10 and owed[-1].t < end.t - 0.5 * DT


def test_an_interval_beyond_the_jitter_tolerance_says_so():
    sim = _sim()
    sur = Surrogate(_config(cadence_s=DT))
    for i in range(TRACK_N):
        shift = 0.2 * DT if i >= TRACK_N - 20 else 0.0  # one interval of 1.2 cadences
        sur.add(_replace(_meas(sim, i, R_FREE), t=float(sim.t[i]) + shift))
    assert _gap_forecasts(sur, sim) == []
    assert "not at a fixed cadence" in sur.status and "20 samples after it" in sur.status


# ------------------------------------------------------------------------------ bad input

def _with_bad(bad_at: int, make_bad) -> tuple[list[Measurement], list[Measurement]]:
    sim = _sim()
    clean, dirty = Surrogate(_config()), Surrogate(_config())
    for i in range(TRACK_N):
        m = _meas(sim, i, R_FREE)
        clean.add(m)
        for d in make_bad(m) if i == bad_at else [m]:
            dirty.add(d)
    t = float(sim.t[TRACK_N - 1]) + 20.6 * DT
    return clean.due(t), dirty.due(t)


def _replace(m: Measurement, **changes) -> Measurement:
    return Measurement(**{**m.__dict__, **changes})


@pytest.mark.parametrize(("case", "bad_at", "make_bad", "first"), [
    ("nan_z_mid_buffer", 200, lambda m: [_replace(m, z=m.z * np.nan)], TRACK_N),
    ("duplicate_last", TRACK_N - 1, lambda m: [m, m], TRACK_N),
    ("out_of_order_last", TRACK_N - 1, lambda m: [m, _replace(m, t=m.t - 95.0)], TRACK_N),
    ("nan_cov_last", TRACK_N - 1, lambda m: [_replace(m, R=m.R * np.nan)], TRACK_N - 1),
])
def test_bad_measurement_does_not_disable_forecasts(case, bad_at, make_bad, first):
    """Bad input is refused, never trained on: the forecasts still follow the truth (and
    are the clean ones exactly where the bad message only repeats a good one). A refused
    last sample makes its epoch the gap's first."""
    clean, dirty = _with_bad(bad_at, make_bad)
    assert len(clean) == 20
    if case in ("duplicate_last", "out_of_order_last"):
        _same(dirty, clean)
    sim = _sim()
    assert [m.t for m in dirty] == list(sim.t[first:TRACK_N + 20])
    truth = sim.z_true[first:TRACK_N + 20]
    assert np.abs(np.array([m.z for m in dirty]) - truth).max() < 1e-2  # km


# ------------------------------------------------------------------------------ ECI lift
def test_lifted_forecast_covariance_is_not_the_lifted_noise():
    """Range/az/el learned through the ECI lift: the lifted samples carry the angle noise
    times the range (10-130 km); pushed back through J at the forecast epoch it used to
    claim a range sigma of ~60 km for a first forecast that is off by ~20 km, against a
    sensor sigma of 1 km. Only the model error maps back; the sensor noise is R again."""
    sim = _sim("iss_j2_rae")
    sur = Surrogate(_config(lift=EciLift(sc.measurement_model(sim.scenario))))
    _track(sur, sim)
    got = sur.due(float(sim.t[TRACK_N - 1]) + (GAP_N + 0.6) * DT)
    assert len(got) == GAP_N
    assert math.sqrt(got[0].R[0, 0]) < 20.0  # km
    err = np.array([m.z for m in got]) - sim.z_true[sim.gap_index]
    err[:, 1] = (err[:, 1] + math.pi) % (2 * math.pi) - math.pi
    nees = [e @ np.linalg.solve(m.R, e) for e, m in zip(err, got, strict=True)]
    assert np.mean(nees[:10]) < 3 * 3.0  # not overconfident where it is trusted most


# ------------------------------------------------------------------------------ second gap
def test_a_second_gap_soon_after_the_first_is_still_forecast():
    """ISS positions with 10 m noise: 360 samples, a 20-epoch gap, 60 samples, a second gap.
    The regular stretch after the first gap (60) is shorter than a fit needs (2 x 60 + 2);
    the first gap's forecasts fill its epochs in the buffer, so the second gap is forecast
    from the whole window, as accurately as the first (measured 0.19 km over the first
    gap's 30 steps, 0.12 km over the second's). Noisy data: on noise-free windows of this
    length the fit is ill-conditioned (30-step errors from 1e-4 to 4e3 km depending on
    where the window starts, with the old Gram basis as with the SVD), so a noise-free
    window tests luck, not the gap fill."""
    sim = _sim(noise_sigma=(1e-2,) * 3)
    first_sur = Surrogate(_config())
    _track(first_sur, sim)
    first = first_sur.due(float(sim.t[TRACK_N - 1]) + 30.6 * DT)
    err_first = np.linalg.norm(np.array([m.z for m in first]) - sim.z_true[TRACK_N:TRACK_N + 30],
                               axis=1)
    sur = Surrogate(_config())
    _track(sur, sim)
    gap1, back = range(TRACK_N, TRACK_N + 20), range(TRACK_N + 20, TRACK_N + 80)
    owed = []
    for i in back:
        owed += sur.add(_meas(sim, i))
    assert [m.t for m in owed] == [float(sim.t[i]) for i in gap1]
    got = sur.due(float(sim.t[back[-1]]) + 30.6 * DT)
    assert len(got) == 30 and "forecasts filling a gap" in sur.status
    err = np.linalg.norm(np.array([m.z for m in got]) - sim.z_true[back[-1] + 1:back[-1] + 31],
                         axis=1)
    assert err.max() < 1.0  # km
    assert err.max() < 2.0 * err_first.max()


def test_a_gap_longer_than_the_forecasts_is_not_filled():
    sim = _sim()
    sur = Surrogate(_config(max_horizon_s=10 * DT))
    _track(sur, sim, R=R_FREE)
    for i in range(TRACK_N + 20, TRACK_N + 30):  # 20 missed epochs, only 10 forecast
        sur.add(_meas(sim, i, R_FREE))
    assert not any(m.source == Source.FORECAST for m in sur._buf)
    assert sur.due(float(sim.t[TRACK_N + 29]) + 3 * DT) == []
    assert "fixed cadence" in sur.status


def test_only_the_model_error_is_scaled_through_the_gap():
    """All forecasts of a gap share one model error D(k), but the sensor noise R inside
    Var(e(k)) = R + D(k) is independent per epoch: the k-th forecast carries R + k D(k). On
    range/az/el through the ECI lift, where the model error in elevation is small against
    the sensor's 0.01 rad, the last forecast of an orbit-long gap claims an elevation sigma
    of 0.013 rad (measured; scaling all of Var(e(k)) by k claimed 0.137 rad) and is still
    not overconfident against the noise-free measurement."""
    sim = _sim("iss_j2_rae")
    plain = Surrogate(_config(lift=EciLift(sc.measurement_model(sim.scenario)),
                              inflate_correlated=False))
    sur = Surrogate(_config(lift=EciLift(sc.measurement_model(sim.scenario))))
    now = float(sim.t[TRACK_N - 1]) + (GAP_N + 0.6) * DT
    _track(plain, sim)
    _track(sur, sim)
    base, got = plain.due(now), sur.due(now)
    assert len(got) == len(base) == GAP_N
    for k, (b, m) in enumerate(zip(base, got, strict=True), start=1):
        np.testing.assert_allclose(m.R - sim.R, k * (b.R - sim.R), rtol=1e-9, atol=1e-15)
    assert math.sqrt(got[-1].R[2, 2]) < 2 * sim.sigma[2]
    err = np.array([m.z for m in got]) - sim.z_true[sim.gap_index]
    err[:, 1] = (err[:, 1] + math.pi) % (2 * math.pi) - math.pi
    nees = [e @ np.linalg.solve(m.R, e) for e, m in zip(err, got, strict=True)]
    assert np.mean(nees) < 3 * 3.0


def test_noise_share_scales_only_the_sensor_noise_part():
    """`noise_share` a (for studies) keeps a R of the sensor noise: the k-th forecast carries
    a R + k D(k), with the same model part D(k) as the paper's a = 1."""
    sim = _sim("iss_j2_pos_noisy")
    full, part = Surrogate(_config()), Surrogate(_config(noise_share=0.25))
    now = float(sim.t[TRACK_N - 1]) + (GAP_N + 0.6) * DT
    _track(full, sim)
    _track(part, sim)
    a, b = full.due(now), part.due(now)
    assert len(a) == len(b) == GAP_N
    for fa, fb in zip(a, b, strict=True):
        np.testing.assert_array_equal(fa.z, fb.z)
        np.testing.assert_allclose(fb.R - 0.25 * sim.R, fa.R - sim.R, rtol=1e-9,
                                   atol=1e-9 * sim.R.max())


@pytest.mark.parametrize("share", [0.0, -0.5, 1.5, math.nan])
def test_noise_share_outside_zero_one_is_refused(share):
    with pytest.raises(ValueError, match="noise_share"):
        SurrogateConfig(noise_share=share)

"""Tests for ssa_fusion.core.catalog.gap_bank: the catalog's gap forecasts equal each object's own
`gap_forecaster.GapForecaster`, beat coasting on the motion model against a J2 truth, and the fits
keep to their wall-time budget (newest pass end first, a gap that ends first skipped)."""

from dataclasses import replace

import numpy as np
import pytest

from ssa_fusion.core.catalog.gap_bank import GapBank, GapBankConfig
from ssa_fusion.core.gaps.forecaster import GapForecaster
from ssa_fusion.core.gaps.residual import LIVE_RESIDUAL
from ssa_fusion.core.motion import dynamics
from ssa_fusion.sim.scenarios import ISS_ELEMENTS

X0 = np.array(dynamics.elements_to_state(**ISS_ELEMENTS))
P = np.diag([1e-6] * 3 + [1e-12] * 3)  # 1 m, 1 mm/s
CFG = GapBankConfig(
    motion_model="kepler", period_s=60.0, pass_break_s=600.0, hold_s=0.0, fit_budget=1.0,
    residual=replace(LIVE_RESIDUAL, min_anchors=3, min_span_s=3 * 3600.0,
                     window_s=12 * 3600.0, max_horizon_s=6 * 3600.0, heldout_fits=1),
    physics=None)  # the learned residual alone (the physics-only fit: test_physics_fit)


def _stream(x0: np.ndarray, offset_s: float, hours: float) -> tuple[np.ndarray, np.ndarray]:
    """Estimates of a J2 truth during passes of 5 min every 97 min (30 s apart): (t, x)."""
    starts = np.arange(offset_s, hours * 3600.0, 97 * 60.0)
    t = np.concatenate([s + np.arange(0.0, 300.0, 30.0) for s in starts])
    x = dynamics.propagate("j2", x0, np.concatenate([[0.0], t]))[1:]
    return t, x


class FakeWall:
    """A wall clock the test moves."""

    def __init__(self) -> None:
        self.now = 0.0

    def __call__(self) -> float:
        return self.now


@pytest.fixture(scope="module")
def streams():
    x1 = X0.copy()
    x1[3:] *= 1.001  # a slightly higher orbit
    return {"a": _stream(X0, 60.0, 14.0), "b": _stream(x1, 1800.0, 14.0)}


def _run(bank: GapBank, streams, wall: FakeWall, grid: np.ndarray):
    """Feed every estimate in epoch order, stepping the bank on `grid` (sim s); the wall moves
    1 s per step. Return the forecasts as {(object, t): (x, P)}, and the bank's order of fits."""
    events = sorted((t, oid, x) for oid, (ts, xs) in streams.items()
                    for t, x in zip(ts, xs, strict=True))
    out, i = {}, 0
    for now in grid:
        while i < len(events) and events[i][0] <= now:
            t, oid, x = events[i]
            for f in bank.on_estimate(oid, t, x, P):
                out[(f.object_id, f.t)] = (f.x, f.P)
            i += 1
        wall.now += 1.0
        for f in bank.step(float(now)):
            assert f.t <= now - bank.config.hold_s
            out[(f.object_id, f.t)] = (f.x, f.P)
    return out


@pytest.fixture(scope="module")
def run(streams):
    wall = FakeWall()
    bank = GapBank(CFG, wall=wall)
    return bank, _run(bank, streams, wall, np.arange(0.0, 14 * 3600.0, 60.0))


def test_the_bank_gives_each_object_its_own_forecasters_forecasts(streams, run):
    bank, got = run
    assert bank.counts["fitted"] >= 6 and bank.counts["forecasts"] == len(got) > 300
    assert bank.counts["skipped"] == 0 and bank.counts["overtaken"] == 0
    for oid, (ts, xs) in streams.items():  # the reference: the single-object forecaster
        ref = GapForecaster.for_model("kepler", CFG.period_s, CFG.residual)
        mine = sorted(t for o, t in got if o == oid)
        assert mine
        k = 0
        for t in mine:
            while k < len(ts) and ts[k] < t:
                ref.on_estimate(ts[k], xs[k], P)
                k += 1
            assert t - ts[k - 1] >= CFG.pass_break_s and (k == len(ts) or t < ts[k])
            want = ref.forecast(t)
            assert want is not None
            np.testing.assert_array_equal(got[(oid, t)][0], want[0])
            np.testing.assert_array_equal(got[(oid, t)][1], want[1])


def test_the_forecasts_beat_coasting_on_the_motion_model(streams, run):
    _, got = run
    ratios = []
    for oid, (ts, xs) in streams.items():
        mine = np.array(sorted(t for o, t in got if o == oid))
        truth = dynamics.propagate("j2", xs[0], np.concatenate([[ts[0]], mine]))[1:]
        fc = np.array([got[(oid, t)][0] for t in mine])
        last = np.searchsorted(ts, mine) - 1  # the pass end each forecast starts from
        coast = np.empty((mine.size, 6))
        for j in np.unique(last):  # the EKF's mean coasting from there (two-body)
            at = last == j
            coast[at] = dynamics.propagate("two_body", xs[j], np.r_[ts[j], mine[at]])[1:]
        e_fc = np.linalg.norm(fc[:, :3] - truth[:, :3], axis=1)
        e_coast = np.linalg.norm(coast[:, :3] - truth[:, :3], axis=1)
        ratios.append(np.median(e_coast) / np.median(e_fc))
    assert min(ratios) > 2.0, ratios  # measured: 3.54 and 5.44


def test_fits_keep_to_the_budget_newest_pass_end_first(streams, monkeypatch):
    wall = FakeWall()
    cost = 2.0  # wall s per fit
    fitted: list[str] = []
    real = GapForecaster.forecast

    def costly(self, t):
        if self.fitted_t != self.last[0]:
            wall.now += cost
            fitted.append(next(o for o, r in bank._rows.items() if bank._gaps[r] is self))
        return real(self, t)

    monkeypatch.setattr(GapForecaster, "forecast", costly)
    bank = GapBank(replace(CFG, fit_budget=0.25), wall=wall)
    # both objects' passes end; their gaps are due together, b's pass ended last
    for oid, (ts, xs) in streams.items():
        for t, x in zip(ts[ts < 7 * 3600.0], xs[ts < 7 * 3600.0], strict=True):
            bank.on_estimate(oid, t, x, P)
    now = 8 * 3600.0
    ends = {oid: ts[ts < 7 * 3600.0][-1] for oid, (ts, _) in streams.items()}
    first, second = sorted(ends, key=ends.get, reverse=True)
    steps = 0
    while len(fitted) < 2 and steps < 100:
        wall.now += 1.0
        bank.step(now)
        steps += 1
    assert fitted == [first, second]
    # 2 fits of 2 s at a quarter of the wall time: the second waits until the first is repaid
    assert bank.fit_seconds == 2 * cost
    assert wall.now >= (bank.fit_seconds - CFG.fit_budget) / 0.25
    # a gap that ends before its turn is skipped, not fitted
    bank.on_estimate(first, now + 60.0, streams[first][1][-1], P)
    assert bank.counts["skipped"] == 0  # first was fitted already: nothing skipped
    later = now + 2 * 3600.0
    bank.step(later)  # queues first's new pass end (budget in debt: no fit)
    assert bank.waiting == 1 + (bank.counts["fitted"] + bank.counts["refused"] < 2)
    bank.on_estimate(first, later + 60.0, streams[first][1][-1], P)
    assert bank.counts["skipped"] == 1


def test_a_forecast_for_an_epoch_a_real_estimate_covers_is_counted_overtaken(streams):
    wall = FakeWall()
    bank = GapBank(CFG, wall=wall)
    ts, xs = streams["a"]
    for t, x in zip(ts[ts < 9 * 3600.0], xs[ts < 9 * 3600.0], strict=True):
        bank.on_estimate("a", t, x, P)
    end = ts[ts < 9 * 3600.0][-1]
    assert not bank.step(end + 3600.0)  # the budget starts empty
    wall.now += 10.0
    out = bank.step(end + 3600.0)
    assert out and bank.counts["overtaken"] == 0
    assert not bank.on_estimate("a", end + 1800.0, xs[-1], P)  # inside what was released
    assert bank.counts["overtaken"] == 30  # the forecasts at end + 1800 ... end + 3600 s


def test_without_a_budget_every_pass_end_is_fitted_at_its_step_whatever_the_wall(streams,
                                                                                monkeypatch):
    """fit_budget 0: which gaps get a fit depends on sim time alone. A machine so slow that
    each fit takes an hour of wall time, and a wall clock that never moves, fit the same
    objects at the same step, and give the same forecasts."""
    real = GapForecaster.forecast
    runs = []
    for cost in (0.0, 3600.0):
        wall = FakeWall()

        def slow(self, t, wall=wall, cost=cost):
            wall.now += cost
            return real(self, t)

        monkeypatch.setattr(GapForecaster, "forecast", slow)
        bank = GapBank(replace(CFG, fit_budget=0.0), wall=wall)
        for oid, (ts, xs) in streams.items():
            for t, x in zip(ts[ts < 7 * 3600.0], xs[ts < 7 * 3600.0], strict=True):
                bank.on_estimate(oid, t, x, P)
        out = bank.step(8 * 3600.0)  # the first step after both passes ended
        assert bank.counts["fitted"] + bank.counts["refused"] == 2 and bank.waiting == 0
        runs.append(out)
    assert runs[0] and [(f.object_id, f.t) for f in runs[0]] == [(f.object_id, f.t)
                                                                  for f in runs[1]]
    for a, b in zip(*runs, strict=True):
        np.testing.assert_array_equal(a.x, b.x)
        np.testing.assert_array_equal(a.P, b.P)


def test_the_configuration_is_checked():
    with pytest.raises(ValueError, match="fit_budget"):
        GapBankConfig(fit_budget=-0.1)
    with pytest.raises(ValueError, match="fit_budget"):
        GapBankConfig(fit_budget=1.5)
    with pytest.raises(ValueError, match="motion_model"):
        GapBankConfig(motion_model="sgp4")
    with pytest.raises(ValueError, match="period_s"):
        GapBankConfig(period_s=float("nan"))


def test_a_flood_of_object_ids_stops_at_max_objects_and_a_same_epoch_estimate_replaces():
    """`admits` holds the bank at `max_objects`; a second estimate at an object's newest
    epoch (another station's measurement fused after the first) replaces the first."""
    bank = GapBank(CFG, max_objects=2)
    assert bank.admits("a") and bank.admits("b")
    bank.on_estimate("a", 0.0, X0, P)
    bank.on_estimate("b", 0.0, X0, P)
    assert not bank.admits("c") and bank.admits("a") and len(bank) == 2
    better = X0 + 1e-3
    assert bank.on_estimate("a", 0.0, better, 0.5 * P) == []
    r = bank._rows["a"]
    last = bank._gaps[r].last
    assert last is not None and np.array_equal(last[1], better)
    assert bank.on_estimate("a", -1.0, X0, P) == [] and bank._gaps[r].last[0] == 0.0

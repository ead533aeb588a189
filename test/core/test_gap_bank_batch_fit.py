"""Tests for the batch fit of a catalog's gaps (`core.catalog.gap_bank` with `GapFill.BATCH_FIT`,
`core.gaps.measurement_windows`): an object's forecasts equal the single-object filter's
`batch_gap.BatchGapForecaster` given the same measurements and estimates; the fits keep to
the wall-time budget like the residual's (newest pass end first, a gap that ends first
skipped); an object's window keeps its last passes and no more than its bound of rows."""

from dataclasses import replace

import numpy as np
import pytest
from test_gap_bank import FakeWall

from ssa_fusion.core.base.rows import MeasurementRows
from ssa_fusion.core.base.types import Kind, Measurement, Source
from ssa_fusion.core.catalog.gap_bank import GapBank, GapBankConfig, last_passes_forecaster
from ssa_fusion.core.earth.timescales import UNIX_EPOCH_JD
from ssa_fusion.core.gaps.measurement_windows import ROW, MeasurementWindows
from ssa_fusion.core.gaps.publisher import GapFill
from ssa_fusion.core.measure.measurement import StationModels
from ssa_fusion.core.motion.element_sets import catalog_states
from ssa_fusion.formats import element_sets as catalog_io
from ssa_fusion.sim import survey
from ssa_fusion.sim.sky import SKY_SCENARIOS
from ssa_fusion.studies.catalog_gaps import SAMPLE

P = np.diag([1e-4] * 3 + [1e-8] * 3)
CFG = GapBankConfig(motion_model="j2", period_s=600.0, pass_break_s=600.0, hold_s=0.0,
                    fit_budget=0.0, gap_forecast=GapFill.BATCH_FIT)
HOURS = 14.0


@pytest.fixture(scope="module")
def sky():
    """Three synthetic LEO objects seen by iss_network's radars for 14 h: the measurements
    (MeasurementRows, epoch order), the model, and per object its 'estimates' (the SGP4
    truth at its measurement epochs, off by 100 m and 1 cm/s: the fit's first guess)."""
    radars = SKY_SCENARIOS["iss_network"].radars
    entries = survey.synthetic_catalog(catalog_io.read_catalog(SAMPLE)[0], 3, seed=7)
    t0 = survey.catalog_start(entries)
    obs = survey.observe_catalog(entries, radars, t0, HOURS * 3600.0, seed=7)
    R = np.array([r.R for r in radars])
    rows = MeasurementRows(obs.t, [obs.object_ids[i] for i in obs.obj],
                           [radars[i].station.name for i in obs.sensor], obs.z,
                           R[obs.sensor], kind=np.full(len(obs.t), Kind.RANGE_AZ_EL, np.uint8),
                           source=np.full(len(obs.t), Source.SENSOR, np.uint8))
    model = StationModels({r.station.name: r.station for r in radars}, UNIX_EPOCH_JD)
    off = np.r_[0.1, 0.0, 0.0, 0.0, 1e-5, 0.0]
    est = {}
    for k, e in enumerate(entries):
        t = np.unique(obs.t[obs.obj == k])
        est[obs.object_ids[k]] = (t, catalog_states([e], t).x[0] + off)
    return rows, model, est, t0


def _run(bank: GapBank, rows: MeasurementRows, est, grid: np.ndarray):
    """Feed the measurements and estimates in epoch order, stepping the bank on `grid`."""
    events = sorted([(float(t), 0, i) for i, t in enumerate(rows.t)]
                    + [(float(t), 1, (oid, j)) for oid, (ts, _) in est.items()
                       for j, t in enumerate(ts)], key=lambda e: (e[0], e[1]))
    out, k = {}, 0
    for now in grid:
        while k < len(events) and events[k][0] <= now:
            _, what, i = events[k]
            if what == 0:
                bank.on_measurements(rows.take(np.array([i])))
            else:
                oid, j = i
                for f in bank.on_estimate(oid, est[oid][0][j], est[oid][1][j], P):
                    out[(f.object_id, f.t)] = (f.x, f.P)
            k += 1
        if isinstance(bank.wall, FakeWall):
            bank.wall.now += 1.0
        for f in bank.step(float(now)):
            out[(f.object_id, f.t)] = (f.x, f.P)
    return out


def test_an_objects_forecasts_equal_the_single_object_batch_fits(sky):
    rows, model, est, t0 = sky
    bank = GapBank(CFG, wall=FakeWall(), model=model)
    got = _run(bank, rows, est, t0 + np.arange(0.0, HOURS * 3600.0, 60.0))
    assert bank.counts["fitted_batch_fit"] >= 6 and bank.counts["forecasts"] == len(got) > 100
    assert bank.counts["measurements"] > 0
    for oid, (ts, xs) in est.items():  # the reference: the single-object filter's forecaster
        ref = last_passes_forecaster(model, CFG.period_s)
        mine = sorted(t for o, t in got if o == oid)
        assert mine, oid
        mt = [i for i, o in enumerate(rows.object_id) if o == oid]
        k = m = 0
        for t in mine:
            while m < len(mt) and rows.t[mt[m]] < t:
                i = mt[m]
                ref.on_measurement(Measurement(float(rows.t[i]), rows.z[i], rows.R[i],
                                               kind=Kind.RANGE_AZ_EL, object_id=oid,
                                               frame_id=rows.frame_id[i]))
                m += 1
            while k < len(ts) and ts[k] < t:
                ref.on_estimate(ts[k], xs[k], P)
                k += 1
            want = ref.forecast(t)
            assert want is not None
            np.testing.assert_allclose(got[(oid, t)][0], want[0], rtol=1e-9, atol=0)
            np.testing.assert_allclose(got[(oid, t)][1], want[1], rtol=1e-9,
                                       atol=1e-9 * np.abs(want[1]).max())
        assert len(ref.starts) == bank.windows.pass_count(bank._rows[oid])


def test_batch_fits_keep_to_the_budget_newest_pass_end_first(sky, monkeypatch):
    rows, model, est, t0 = sky
    wall = FakeWall()
    cost = 2.0  # wall s per fit
    fitted: list[int] = []
    real = GapBank.batch_fit

    def costly(self, r, first):
        wall.now += cost
        fitted.append(r)
        return real(self, r, first)

    monkeypatch.setattr(GapBank, "batch_fit", costly)
    bank = GapBank(replace(CFG, fit_budget=0.25), wall=wall, model=model)
    cut = t0 + 7 * 3600.0
    bank.on_measurements(rows.take(np.flatnonzero(rows.t < cut)))
    for oid, (ts, xs) in est.items():
        for t, x in zip(ts[ts < cut], xs[ts < cut], strict=True):
            bank.on_estimate(oid, t, x, P)
    now = cut + 3600.0  # every pass has ended; the gaps are due together
    ends = {bank._rows[oid]: ts[ts < cut][-1] for oid, (ts, _) in est.items()}
    assert len(set(ends.values())) == 3
    steps = 0
    while len(fitted) < 3 and steps < 100:
        wall.now += 1.0
        bank.step(now)
        steps += 1
    assert fitted == sorted(ends, key=ends.get, reverse=True)  # newest pass end first
    assert bank.fit_seconds == 3 * cost
    # 3 fits of 2 s at a quarter of the wall time: each waits until the last is repaid
    assert wall.now >= (bank.fit_seconds - cost - 1.0) / 0.25
    # a gap that ends before its turn is skipped, not fitted
    oid = bank.object_ids[0]
    later = now + 2 * 3600.0
    bank.on_estimate(oid, now + 60.0, est[oid][1][-1], P)
    bank.step(later)  # queues its new pass end (budget in debt: no fit)
    assert bank.waiting == 1
    bank.on_estimate(oid, later + 60.0, est[oid][1][-1], P)
    assert bank.counts["skipped"] == 1 and len(fitted) == 3


def test_a_window_keeps_the_last_passes_and_at_most_max_rows():
    """Five passes of 40 measurements, 10 s apart, 95 min between passes: a window of three
    passes keeps the last three (as `BatchGapForecaster`'s list does); one of at most 50 rows
    keeps the newest 50, and its memory is that bound's."""
    R = np.diag([1e-6, 1e-8, 1e-8])
    t = np.concatenate([k * 5700.0 + 10.0 * np.arange(40) for k in range(5)])
    ms = [Measurement(float(ti), np.array([1000.0 + ti, 0.1, 0.2]), R,
                      kind=Kind.RANGE_AZ_EL, frame_id="s1" if ti % 20 else "s2") for ti in t]
    ref = last_passes_forecaster(None, 60.0)  # type: ignore[arg-type]
    big, small = MeasurementWindows(3, 600.0, 512), MeasurementWindows(3, 600.0, 50)
    one = MeasurementWindows(1, 600.0, 512)
    big.grow(2)
    small.grow(1)
    one.grow(1)
    for m in ms:
        ref.on_measurement(m)
        for w in (big, small, one):
            w.add(0, m.t, m.z, m.R, m.kind, m.frame_id)
        assert small.count(0) <= 50 and small.pass_count(0) <= 3
    assert not big.add(0, ms[-1].t, ms[-1].z, R, Kind.RANGE_AZ_EL, "s1")  # not after: ignored
    got = big.window(0)
    assert [m.t for m in got] == [m.t for m in ref.window] and big.pass_count(0) == 3
    for a, b in zip(got, ref.window, strict=True):
        np.testing.assert_array_equal(a.z, b.z)
        np.testing.assert_array_equal(a.R, b.R)
        assert a.frame_id == b.frame_id and a.kind == b.kind
    assert [m.t for m in small.window(0)] == [m.t for m in ms[-50:]]
    assert small.pass_count(0) == 2  # the newest pass, and ten of the one before
    assert [m.t for m in one.window(0)] == [m.t for m in ms[-40:]] and one.pass_count(0) == 1
    assert big.count(1) == 0 and big.window(1) == []
    assert small.nbytes() <= 50 * ROW.itemsize + 64
    assert len(big.noise) == 1 and len(big.stations) == 2  # one covariance stored once


def test_objects_choose_their_gap_forecast():
    with pytest.raises(ValueError, match="model"):
        GapBank(CFG)
    with pytest.raises(ValueError, match="gap_forecast"):
        GapBankConfig(gap_forecast=GapFill.BATCH_INIT)
    bank = GapBank(replace(CFG, gap_forecast=GapFill.RESIDUAL))
    assert bank.gap_forecast("a") == GapFill.RESIDUAL
    with pytest.raises(ValueError, match="model"):
        bank.choose("a", GapFill.BATCH_FIT)
    bank = GapBank(replace(CFG, gap_forecast=GapFill.RESIDUAL), model=object())  # type: ignore
    bank.choose("a", GapFill.BATCH_FIT)
    assert bank.gap_forecast("a") == GapFill.BATCH_FIT
    assert bank.gap_forecast("b") == GapFill.RESIDUAL
    R = np.eye(3)
    rows = MeasurementRows(np.array([1.0, 2.0]), ["a", "b"], ["s", "s"], np.ones((2, 3)),
                           np.stack([R, R]), kind=np.full(2, Kind.RANGE_AZ_EL, np.uint8),
                           source=np.full(2, Source.SENSOR, np.uint8))
    assert bank.on_measurements(rows) == 1  # b is the residual's: not kept (not even held)
    assert len(bank) == 1
    bank.choose("a", GapFill.RESIDUAL)
    assert bank.windows.count(0) == 0 and bank._gaps[0] is not None


def test_measurements_ahead_of_the_clock_wait_out_of_the_fit_of_the_gap_before(sky):
    """A lockstep step's measurements run ahead of its clock: the next pass's, given before
    the step that fits the gap, change nothing of that fit (they wait for the clock)."""
    rows, model, est, t0 = sky
    cut = t0 + 7 * 3600.0
    now = cut + 1800.0
    got = []
    for early in (False, True):
        bank = GapBank(CFG, wall=FakeWall(), model=model)
        bank.on_measurements(rows.take(np.flatnonzero(rows.t < cut)))
        if early:
            bank.on_measurements(rows.take(np.flatnonzero(rows.t > now)))
        for oid, (ts, xs) in est.items():
            for t, x in zip(ts[ts < cut], xs[ts < cut], strict=True):
                bank.on_estimate(oid, t, x, P)
        got.append({(f.object_id, f.t): f.x for f in bank.step(now)})
        assert bank.counts["fitted_batch_fit"] == 3
    assert got[0] and got[0].keys() == got[1].keys()
    for k, x in got[0].items():
        np.testing.assert_array_equal(got[1][k], x)

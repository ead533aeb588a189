"""`core.gaps.batch_gap`: the window of the gap fit (passes or hours) and its options."""

import numpy as np
import pytest

from ssa_fusion.core.base.types import Kind, Measurement
from ssa_fusion.core.gaps import batch_gap
from ssa_fusion.core.gaps.batch_gap import BatchGapForecaster, GapWindow
from ssa_fusion.core.measure.pass_windows import PASS_BREAK_S, fit_window, passes

H = 3600.0


def stream(t, kind: Kind = Kind.POSITION) -> list[Measurement]:
    return [Measurement(float(ti), np.zeros(3), np.eye(3), kind=kind, frame_id="gcrf")
            for ti in t]


def pass_times(rng: np.random.Generator, n: int) -> np.ndarray:
    """`n` passes of 3-12 measurements 30 s apart, 1.5 to 14 h apart."""
    t, out = 0.0, []
    for _ in range(n):
        k = int(rng.integers(3, 13))
        out.append(t + 30.0 * np.arange(k))
        t = out[-1][-1] + rng.uniform(1.5, 14.0) * H
    return np.concatenate(out)


@pytest.mark.parametrize(("passes_min", "span_h", "cap"),
                         [(3, 0.0, None), (3, 24.0, None), (2, 36.0, 40), (1, 48.0, 25)])
def test_the_forecaster_holds_exactly_the_window_by_hours(passes_min, span_h, cap):
    """What the live forecaster keeps, cut by its rule, is at every measurement the window
    `fit_window` cuts from the whole stream: forgetting passes never loses one a window
    could still span."""
    rng = np.random.default_rng(7)
    m = stream(pass_times(rng, 25))
    f = BatchGapForecaster(model=None, period_s=60.0, passes=passes_min, span_h=span_h,  # type: ignore[arg-type]
                           max_measurements=cap)
    sizes = set()
    for i, mi in enumerate(m):
        f.on_measurement(mi)
        want = fit_window(m[: i + 1], np.inf, passes_min, span_h * H, cap)
        got = f.window[f.rule.start(f.window):]
        assert got == want
        assert f.starts == [a for a, _ in passes(f.window)]
        sizes.add(len(passes(want)))
        # every pass of the window starts within the span, or is one of the last passes_min
        firsts = [want[a].t for a, _ in passes(want)]
        assert all(want[-1].t - s <= span_h * H for s in firsts[:-passes_min])
    assert max(sizes) > passes_min or span_h == 0.0  # the span did add passes
    if span_h == 0.0:
        assert sizes == {1, 2, 3}


def test_the_module_window_is_read_at_the_call(monkeypatch):
    monkeypatch.setattr(batch_gap, "GAP_FIT_SPAN_H", 30.0)
    monkeypatch.setattr(batch_gap, "GAP_FIT_PASSES", 2)
    assert batch_gap.gap_window() == GapWindow(2, 30.0, batch_gap.GAP_FIT_MAX_MEASUREMENTS)
    f = BatchGapForecaster(model=None, period_s=60.0)  # type: ignore[arg-type]
    assert f.rule == batch_gap.gap_window()
    m = stream([0.0, 10.0, 20 * H, 25 * H, 40 * H])
    assert [x.t for x in batch_gap.gap_window().select(m)] == [20 * H, 25 * H, 40 * H]
    assert [x.t for x in batch_gap.gap_window().select(m, 40 * H)] == [0.0, 10.0, 20 * H,
                                                                         25 * H]


def test_a_long_ranged_window_solves_for_the_along_track_acceleration(monkeypatch):
    monkeypatch.setattr(batch_gap, "GAP_FIT_SOLVE_T_SPAN_H", 10.0)
    short = stream([0.0, 9.9 * H], Kind.RANGE_AZ_EL)
    long = stream([0.0, 10.0 * H], Kind.RANGE_AZ_EL)
    assert batch_gap.gap_fit_options(short) == batch_gap.GAP_FIT
    opts = batch_gap.gap_fit_options(long)
    assert opts.solve_for == (*batch_gap.GAP_FIT.solve_for, "accel_t")
    assert "accel_t" not in opts.consider and set(opts.consider) == {"accel_r", "accel_n"}
    # its prior is the considered sigma, and angles alone never solve for it
    assert opts.param_sigma == batch_gap.GAP_FIT.param_sigma
    assert batch_gap.gap_fit_options(stream([0.0, 20 * H], Kind.RA_DEC)) == \
        batch_gap.GAP_FIT_ANGLES
    assert PASS_BREAK_S < H


def test_angles_only_windows_have_their_own_span():
    """Six passes 5 h apart: with ranges the 24 h span holds the passes starting within 24 h
    of the last measurement (five), with angles alone its own span 0 the last three."""
    t = [k * 5 * H + s for k in range(6) for s in (0.0, 30.0)]
    rule = GapWindow(passes=3, span_h=24.0, max_measurements=None, span_h_angles=0.0)
    ranged, angles = stream(t), stream(t, Kind.RA_DEC)
    assert [m.t for m in rule.select(ranged)] == t[2:]
    assert [m.t for m in rule.select(angles)] == t[6:]
    assert rule.keep(angles) == rule.keep(ranged) == 2  # the wider span is kept for either

"""`core.measure.pass_windows`: passes cut at the break, the last n before an epoch."""

import numpy as np
import pytest

from ssa_fusion.core.base.types import Kind, Measurement
from ssa_fusion.core.measure.pass_windows import (
    PASS_BREAK_S,
    fit_window,
    last_passes,
    passes,
    window_start,
)


def stream(t):
    return [Measurement(float(ti), np.zeros(3), np.eye(3), kind=Kind.POSITION) for ti in t]


def test_passes_break_only_beyond_the_threshold():
    t = [0.0, 60.0, 60.0 + PASS_BREAK_S, 60.0 + 2 * PASS_BREAK_S + 1.0, 5000.0]
    assert passes(stream(t)) == [(0, 2), (3, 3), (4, 4)]
    assert passes([]) == []


def test_last_passes_before_an_epoch():
    t = [0.0, 10.0, 2000.0, 2010.0, 4000.0, 4010.0, 6000.0]
    m = stream(t)
    assert [x.t for x in last_passes(m, 2, 4005.0)] == [2000.0, 2010.0, 4000.0]
    assert [x.t for x in last_passes(m, 1, 6000.0)] == [4000.0, 4010.0]
    assert [x.t for x in last_passes(m, 9, 2000.0)] == [0.0, 10.0]  # fewer exist
    assert last_passes(m, 1, 0.0) == []
    with pytest.raises(ValueError, match="at least one pass"):
        last_passes(m, 0, 100.0)


def test_fit_window_spans_whole_passes_that_start_within_the_span():
    """Passes starting 0, 10, 20, 30 h (3 measurements each, 60 s apart); last at 30 h + 120 s."""
    h = 3600.0
    t = [s * h + k * 60.0 for s in (0.0, 10.0, 20.0, 30.0) for k in range(3)]
    m = stream(t)
    starts = lambda w: sorted({round(x.t // h) for x in w})  # noqa: E731
    # a pass joins when its first measurement is within the span of the last measurement
    assert starts(fit_window(m, np.inf, 1, span_s=20 * h + 120.0)) == [10, 20, 30]
    assert starts(fit_window(m, np.inf, 1, span_s=20 * h + 119.0)) == [20, 30]
    assert starts(fit_window(m, np.inf, 1, span_s=0.0)) == [30]
    # at least min_passes, whatever the span
    assert starts(fit_window(m, np.inf, 3, span_s=1.0)) == [10, 20, 30]
    # the epoch cuts the stream first
    assert starts(fit_window(m, 20 * h + 1.0, 1, span_s=10 * h)) == [10, 20]
    # the cap drops the oldest passes, never one of the last min_passes
    assert starts(fit_window(m, np.inf, 1, span_s=100 * h, max_measurements=7)) == [20, 30]
    assert starts(fit_window(m, np.inf, 3, span_s=100 * h, max_measurements=2)) == [10, 20, 30]
    assert fit_window([], np.inf, 2, span_s=h) == []
    with pytest.raises(ValueError, match="at least one pass"):
        fit_window(m, np.inf, 0)


@pytest.mark.parametrize("seed", range(5))
def test_fit_window_without_a_span_is_the_last_passes(seed):
    rng = np.random.default_rng(seed)
    t = np.cumsum(rng.choice([30.0, 60.0, 2 * PASS_BREAK_S, 5 * 3600.0], size=60))
    m = stream(t)
    for before in rng.uniform(t[0], t[-1] + 1.0, size=10):
        for n in (1, 2, 3, 5):
            assert fit_window(m, before, n) == last_passes(m, n, before)
            assert window_start(m, n) == len(m) - len(last_passes(m, n, np.inf))

"""`core.pass_windows`: passes cut at the break, the window of the last n before an epoch."""

import numpy as np
import pytest

from ssa_fusion.core.pass_windows import PASS_BREAK_S, last_passes, passes
from ssa_fusion.core.types import Kind, Measurement


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

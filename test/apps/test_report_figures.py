"""The reports' robust panel scale against hand-computed percentiles, and the outliers marked
on the panel's edge."""

from __future__ import annotations

import numpy as np
import pytest

from ssa_fusion.apps import report_figures
from ssa_fusion.apps.report_figures import mark_outside, robust_limit


def test_robust_limit_is_the_98th_percentile_with_a_margin():
    """|values| 1..100 (signs alternating): the 98th percentile, linear between the order
    statistics at rank 0.98 × 99 = 97.02 (0-based), is 98 + 0.02 × (99 - 98) = 98.02; the
    half-height 1.3 × 98.02. One value of 600 added (101 values): rank 0.98 × 100 = 98, the
    value 99 exactly, so the half-height 1.3 × 99 = 128.7 — the outlier moves it by 1 %,
    not to 600."""
    v = np.arange(1.0, 101.0) * np.where(np.arange(100) % 2, -1.0, 1.0)
    assert robust_limit(v) == pytest.approx(1.3 * 98.02, rel=1e-12)
    with_outlier = np.append(v, -600.0)
    assert robust_limit(with_outlier) == pytest.approx(128.7, rel=1e-12)
    # NaN and infinities are not values; a floor above the bulk wins; nothing to scale: 1
    assert robust_limit(np.append(with_outlier, [np.nan, np.inf])) == pytest.approx(128.7)
    assert robust_limit(v, floor=200.0) == pytest.approx(260.0)
    assert robust_limit(v, floor=float("nan")) == pytest.approx(1.3 * 98.02)
    assert robust_limit(np.zeros(5)) == 1.0 and robust_limit(np.array([np.nan])) == 1.0


def test_mark_outside_draws_the_values_beyond_on_the_edge_pointing_out():
    plt = report_figures.pyplot()
    _, ax = plt.subplots()
    x = np.arange(6.0)
    y = np.array([1.0, -2.0, 600.0, 3.0, -45.0, np.nan])
    n = mark_outside(ax, x, y, 10.0, "km")
    assert n == 2 and ax.get_ylim() == (-10.0, 10.0)
    lines = ax.get_lines()
    assert [ln.get_marker() for ln in lines] == ["^", "v"]
    up, down = lines
    assert list(up.get_xdata()) == [2.0] and list(up.get_ydata()) == [9.7]
    assert list(down.get_xdata()) == [4.0] and list(down.get_ydata()) == [-9.7]
    assert up.get_label() == "2 beyond ±10 km (largest 600)"
    assert down.get_label().startswith("_")  # one legend entry for both edges
    ax.plot(x, y, label="error")
    report_figures.beyond_legend(ax)  # the triangles' entry only
    assert [t.get_text() for t in ax.get_legend().get_texts()] == [up.get_label()]
    # nothing beyond: the scale set, nothing drawn
    _, ax = plt.subplots()
    assert mark_outside(ax, x, np.clip(y, -5, 5), 10.0, "km") == 0
    assert ax.get_ylim() == (-10.0, 10.0) and not ax.get_lines()
    report_figures.beyond_legend(ax)
    assert ax.get_legend() is None

"""The report's PNG plots are readable: a title, labelled axes with units, angles in degrees,
no line across a gap or across an angle's wrap, NIS against its chi-square band."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from plot_checks import assert_readable  # test/apps on sys.path

from ssa_fusion.apps import evaluate, report, report_figures
from ssa_fusion.core.base import types

SAMPLE = Path(__file__).resolve().parents[2] / "bags" / "sample_iss_j2_rae"


@pytest.fixture(scope="module")
def figures(tmp_path_factory):
    """Every figure the report draws for the sample bag, by file name."""
    data = evaluate.load(SAMPLE)
    ev = evaluate.evaluate(data)
    out = tmp_path_factory.mktemp("plots")
    drawn = {}
    saved = report_figures.save

    def keep(fig, path, dpi=100):
        drawn[Path(path).name] = fig
        saved(fig, path, dpi)

    report_figures.save = keep
    try:
        report.plot_arms(ev, out / "arms.png")
        report.plot_sigma(data, out / "estimate_3sigma.png")
        report.plot_forecasts(data, out / "forecast_vs_withheld.png")
        report.plot_nis(data, out / "nis.png")
    finally:
        report_figures.save = saved
    assert all((out / name).stat().st_size > 10_000 for name in drawn)
    return drawn


def test_every_plot_has_a_title_and_labelled_axes(figures):
    assert set(figures) == {"arms.png", "estimate_3sigma.png", "forecast_vs_withheld.png",
                            "nis.png"}
    for name, fig in figures.items():
        assert_readable(name, fig)


def test_angles_in_degrees_without_wrap_lines(figures):
    axes = figures["forecast_vs_withheld.png"].get_axes()
    labels = [ax.get_ylabel() for ax in axes]
    assert labels == ["range [km]", "azimuth [deg]", "elevation [deg]"]
    for ax in axes[1:]:
        for line in ax.get_lines():
            y = np.asarray(line.get_ydata(), dtype=float)
            finite = y[np.isfinite(y)]
            assert finite.min() >= -90.0 and finite.max() <= 360.0  # degrees, not rad
            runs = np.split(y, np.flatnonzero(np.isnan(y)))
            assert all(np.all(np.abs(np.diff(r[np.isfinite(r)])) < 180.0) for r in runs)


def test_nis_against_its_band_and_no_forecast_at_a_fake_value(figures):
    ax = figures["nis.png"].get_axes()[0]
    labels = [text.get_text() for text in ax.get_legend().get_texts()]
    assert any(label.startswith("95 % χ² band") for label in labels)
    assert "outage (withheld)" in labels
    for line in ax.get_lines():
        y = np.asarray(line.get_ydata(), dtype=float)
        assert np.all(y > 1e-6), "a NIS of 0 drawn at a floor value"


def test_the_html_log_axes_are_labelled_at_each_decade():
    """Plotly's default log ticks label 2 and 5 between decades without their exponent (so
    50-70 read as 5-7); the report's NEES and NIS axes tick at each decade only."""
    from ssa_fusion.apps import report_html

    data = evaluate.load(SAMPLE)
    ev = evaluate.evaluate(data)
    for fig in (report_html.nees_plot(ev), report_html.nis_plot(data)):
        assert fig is not None
        assert fig.layout.yaxis.type == "log" and fig.layout.yaxis.dtick == 1
        assert fig.layout.title.text and fig.layout.yaxis.title.text


OUTLIER_KM = 600.0


@pytest.fixture(scope="module")
def outlier():
    """The sample bag with one fused estimate 600 km off in x (GCRF), and its epoch."""
    data = evaluate.load(SAMPLE)
    truth = {e.t for e in data.truth}
    fused = [e for e in data.estimates
             if e.t in truth and e.update_source == types.UpdateSource.SENSOR]
    bad = fused[len(fused) // 2]
    bad.x = bad.x + np.array([OUTLIER_KM, 0.0, 0.0, 0.0, 0.0, 0.0])
    return data, bad.t


def _drawn(monkeypatch):
    drawn = {}
    monkeypatch.setattr(report_figures, "save",
                        lambda fig, path, dpi=100: drawn.__setitem__(Path(path).name, fig))
    return drawn


def _edge_marks(ax):
    return [ln for ln in ax.get_lines() if ln.get_marker() in ("^", "v")]


def test_one_600_km_error_neither_scales_the_panel_nor_hides(outlier, monkeypatch, tmp_path):
    """The x panel of estimate_3sigma.png keeps the scale of the run's bulk and shows the
    600 km error as one triangle on its upper edge, labelled with the count and the largest
    error. The bulk of this coarse simulated radar run: 98 % of |x error| under ~21 km, its
    settled 3σ (95th percentile over the run) ~41 km; the panel is ±1.3 × the larger, ~54 km,
    where a scale set by the largest error would be ±600 km and more."""
    data, t_bad = outlier
    drawn = _drawn(monkeypatch)
    report.plot_sigma(data, tmp_path / "estimate_3sigma.png")
    fig = drawn["estimate_3sigma.png"]
    assert_readable("estimate_3sigma.png", fig)
    axes = fig.get_axes()
    x_panel = axes[0]
    assert x_panel.get_ylabel() == "x [km]"
    lo, hi = x_panel.get_ylim()
    truth = {e.t: e.x for e in data.truth}
    est = [e for e in data.estimates
           if e.t in truth and e.update_source != types.UpdateSource.NONE]
    err = np.array([e.x[0] - truth[e.t][0] for e in est])
    three = 3.0 * np.sqrt([e.P[0, 0] for e in est])
    bulk = max(np.percentile(np.abs(err), 98), np.percentile(three, 95))
    assert lo == -hi and hi == pytest.approx(1.3 * bulk, rel=1e-9)
    assert 0.001 < hi < 0.2 * OUTLIER_KM, hi  # metres to tens of km, not ±600 km
    marks = _edge_marks(x_panel)
    assert len(marks) == 1 and marks[0].get_marker() == "^"
    assert list(marks[0].get_ydata()) == pytest.approx([0.97 * hi])
    worst = float(err[[e.t for e in est].index(t_bad)])  # its own error plus the 600 km
    assert abs(worst - OUTLIER_KM) < 0.1 * OUTLIER_KM
    assert marks[0].get_label() == f"1 beyond ±{hi:.3g} km (largest {worst:.3g})"
    t0 = min(e.t for e in est)
    h_bad = (t_bad - t0) / 3600.0
    assert list(marks[0].get_xdata()) == pytest.approx([h_bad])
    legend = [x.get_text() for x in x_panel.get_legend().get_texts()]
    assert marks[0].get_label() in legend
    for ax in axes[1:]:  # the other states are untouched at that epoch (their own tails
        for mark in _edge_marks(ax):  # beyond their bulk may be marked)
            assert h_bad not in list(mark.get_xdata()), ax.get_ylabel()


def test_the_residual_after_it_neither_scales_its_panel_nor_hides(outlier, monkeypatch,
                                                                   tmp_path):
    """`report_own`'s residuals.png on the same estimates: the measurement fused after the
    600 km estimate has a pre-fit range residual of hundreds of km; the range panel stays at
    the bulk's scale and marks it on its edge. This simulated radar's range σ is ~1.2 km, so
    the bulk is the settled 3σ of the innovation, ~3.6 km (its median: the floor, above the
    98th percentile of |residual|, ~2.8 km): the panel is ±1.3 × that, not ±600 km."""
    from ssa_fusion.apps import report_own

    data, t_bad = outlier
    rep = report_own.build(data, evaluate.evaluate(data).settings)
    drawn = _drawn(monkeypatch)
    report_own.plot_residuals(rep, data.measurements[0].t, tmp_path / "residuals.png")
    fig = drawn["residuals.png"]
    assert_readable("residuals.png", fig)
    rng = fig.get_axes()[0]
    assert rng.get_ylabel() == "range [m]"
    lo, hi = rng.get_ylim()
    y = np.array([r.y[0] for r in rep.residuals]) * 1000.0
    settled = 3000.0 * float(np.median([r.sigma[0] for r in rep.residuals]))
    assert lo == -hi and 1.0 < hi < 10_000.0, hi  # metres to km, not ±600 km
    assert hi == pytest.approx(1.3 * max(settled, np.percentile(np.abs(y), 98)), rel=1e-9)
    far = np.abs(y) > hi
    assert far.sum() >= 1 and np.abs(y).max() > 100_000.0  # the outlier is there
    labels = [ln.get_label() for ln in _edge_marks(rng) if not ln.get_label().startswith("_")]
    worst = y[far][np.argmax(np.abs(y[far]))]
    assert labels == [f"{int(far.sum())} beyond ±{hi:.3g} m (largest {worst:.3g})"]
    legend = [x.get_text() for x in rng.get_legend().get_texts()]
    assert labels[0] in legend
    # one triangle at the measurement fused next after the 600 km estimate (its prior)
    t_next = min(e.t for e in data.estimates
                 if e.t > t_bad and e.update_source == types.UpdateSource.SENSOR)
    drawn_at = np.concatenate([ln.get_xdata() for ln in _edge_marks(rng)])
    t0 = data.measurements[0].t
    assert np.isclose(drawn_at, (t_next - t0) / 3600.0, rtol=0, atol=1e-9).sum() == 1


def test_a_forecast_line_stops_where_the_forecasts_do(monkeypatch, tmp_path):
    """With ten minutes of the outage's forecasts left out (the withheld measurements all
    kept; shorter than the 30 min that break any line, `GAP_BREAK_S`), the forecast line has
    no segment over them: no line joins the last forecast before to the first after."""
    data = evaluate.load(SAMPLE)
    withheld = {m.t for m in data.withheld}
    ts = sorted(m.t for m in data.forecasts if m.t in withheld)
    a = ts[len(ts) // 2]
    b = min(t for t in ts if t >= a + 600.0)
    assert b - a < report.GAP_BREAK_S
    data.forecasts = [m for m in data.forecasts if not a <= m.t < b]
    drawn = _drawn(monkeypatch)
    report.plot_forecasts(data, tmp_path / "forecast_vs_withheld.png")
    ax = drawn["forecast_vs_withheld.png"].get_axes()[0]
    line = next(ln for ln in ax.get_lines() if str(ln.get_label()).startswith("forecast"))
    x = np.asarray(line.get_xdata(), dtype=float)
    t0 = min(withheld)
    before, after = (max(t for t in ts if t < a) - t0) / 3600.0, (b - t0) / 3600.0
    i = int(np.flatnonzero(np.isclose(x, before, rtol=0, atol=1e-9))[0])
    assert np.isnan(x[i + 1]) and x[i + 2] == pytest.approx(after)
    points = next(ln for ln in ax.get_lines() if ln.get_label() == "withheld (sensor)")
    assert np.isfinite(np.asarray(points.get_xdata(), float)).sum() == len(withheld)

"""The report's PNG plots are readable: a title, labelled axes with units, angles in degrees,
no line across a gap or across an angle's wrap, NIS against its chi-square band."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from plot_checks import assert_readable  # test/apps on sys.path

from ssa_fusion.apps import evaluate, report, report_figures

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

"""`report` on one's own data: a panel for every channel of every measurement kind in the
bag, and the NIS-reproduction check printed as passed or FAILED."""

from __future__ import annotations

import types as pytypes

import numpy as np

from ssa_fusion.apps import report_figures, report_own
from ssa_fusion.core.base.types import Kind, StateEstimate, UpdateSource
from ssa_fusion.evaluation.residuals import NisSummary, Residual


def _residual(t: float, station: str, kind: Kind, m: int, nis_filter: float = 1.0) -> Residual:
    return Residual(t=t, station=station, kind=int(kind), y=np.full(m, 1e-6),
                    sigma=np.full(m, 1e-5), sigma_r=np.full(m, 5e-6), nis=1.0,
                    nis_filter=nis_filter)


def _rep(residuals: list[Residual]) -> pytypes.SimpleNamespace:
    return pytypes.SimpleNamespace(residuals=residuals, gaps=[], published=[],
                                   unknown_stations=[], nis=NisSummary(0, 0, {}),
                                   settings=pytypes.SimpleNamespace(origin="given"))


def test_a_radar_and_a_telescope_each_get_their_channels(monkeypatch, tmp_path):
    drawn = {}
    monkeypatch.setattr(report_figures, "save", lambda fig, path, dpi=100:
                        drawn.setdefault("fig", fig))
    rep = _rep([_residual(60.0 * k, "radar", Kind.RANGE_AZ_EL, 3) for k in range(5)]
               + [_residual(600.0 + 60.0 * k, "scope", Kind.RA_DEC, 2) for k in range(5)])
    report_own.plot_residuals(rep, 0.0, tmp_path / "residuals.png")
    labels = [ax.get_ylabel() for ax in drawn["fig"].get_axes()]
    assert labels == ["range [m]", "azimuth [arcsec]", "elevation [arcsec]",
                      "right ascension [arcsec]", "declination [arcsec]"]
    for ax, station in zip(drawn["fig"].get_axes(), ["radar"] * 3 + ["scope"] * 2,
                           strict=True):  # each panel holds only its kind's points
        assert station in [line.get_label() for line in ax.get_lines()]


def test_the_nis_check_says_passed_or_failed():
    good = _rep([_residual(0.0, "radar", Kind.RANGE_AZ_EL, 3)])
    line = next(x for x in report_own.notes(good) if "reproduces" in x)
    assert "reproduces the filter's published one: passed (0.0e+00 relative)" in line
    bad = _rep([_residual(0.0, "radar", Kind.RANGE_AZ_EL, 3, nis_filter=1 / 56.0)])
    line = next(x for x in report_own.notes(bad) if "reproduces" in x)
    assert "FAILED (more than 1e-06)" in line and "5.5e+01 relative" in line, line
    rms = next(x for x in report_own.notes(bad) if x.startswith("residual RMS"))
    assert "range 0.10, azimuth 0.10, elevation 0.10" in rms, rms


def test_gap_forecasts_are_not_labelled_as_fused_measurements(monkeypatch, tmp_path):
    drawn = {}
    monkeypatch.setattr(report_figures, "save", lambda fig, path, dpi=100:
                        drawn.setdefault("fig", fig))
    P = np.eye(6) * 1e-4
    estimates = ([StateEstimate(60.0 * k, np.zeros(6), P, update_source=UpdateSource.SENSOR)
                  for k in range(5)]
                 + [StateEstimate(3600.0 + 60.0 * k, np.zeros(6), 4 * P,
                                  update_source=UpdateSource.FORECAST) for k in range(5)])
    data = pytypes.SimpleNamespace(estimates=estimates, smoothed=[])
    report_own.plot_sigma(data, _rep([]), 0.0, tmp_path / "position_sigma.png")
    lines = {line.get_label(): line for line in drawn["fig"].get_axes()[0].get_lines()}
    assert set(lines) == {"filter, epochs of fused measurements",
                          "filter, epochs of fused gap forecasts"}
    forecast = lines["filter, epochs of fused gap forecasts"]
    assert np.nanmin(np.asarray(forecast.get_xdata(), float)) == 1.0  # hours: the forecasts'

"""Late or dropped forecasts: `evaluate.unfused_forecasts` counts the gap
epochs the surrogate forecast but the filter never fused, and `live` turns that, and a time
scale the machine did not sustain, into one warning line each. Synthetic data, no ROS."""

from __future__ import annotations

import argparse
from types import SimpleNamespace

import numpy as np
import pytest
from gap_bags import CADENCE, T0, around_a_gap

from ssa_fusion.apps import cli, evaluate, live, runs
from ssa_fusion.core.base import types

TRACK, GAP, AFTER = 30, 20, 5  # epochs
FUSED = 12  # the filter fused the forecasts of the gap's first 12 epochs, predicted the rest


def synthetic(fused: int = FUSED, forecasts: bool = True) -> evaluate.BagData:
    """Two-body truth; real measurements and SENSOR estimates around a gap; a forecast for
    every gap epoch; FORECAST estimates for the first `fused` gap epochs and predictions
    (update_source NONE, what the filter publishes once `predict_period` passes) after."""
    data, epochs = around_a_gap(TRACK, GAP, AFTER)
    for i, ti, xi, in_gap in epochs:
        if in_gap and forecasts:
            data.forecasts.append(types.Measurement(ti, xi[:3], 1e-4 * np.eye(3),
                                                    source=types.Source.FORECAST))
        source = (types.UpdateSource.SENSOR if not in_gap
                  else types.UpdateSource.FORECAST if i < TRACK + fused
                  else types.UpdateSource.NONE)
        data.estimates.append(types.StateEstimate(ti, xi, 1e-2 * np.eye(6),
                                                  update_source=source))
    return data


def gap_epochs(data: evaluate.BagData) -> np.ndarray:
    return np.array(sorted(m.t for m in data.withheld))


def test_gap_epochs_with_a_forecast_and_only_a_prediction_are_counted():
    data = synthetic()
    late = evaluate.unfused_forecasts(data, gap_epochs(data))
    assert (late.epochs, late.forecast_epochs) == (GAP - FUSED, GAP)
    assert late.first_t == T0 + CADENCE * (TRACK + FUSED)
    # the same epochs the evaluation scores from the filter's prediction
    assert evaluate.evaluate(data).gap.predicted == late.epochs


def test_what_is_not_late():
    data = synthetic(fused=GAP)
    t_gap = gap_epochs(data)
    assert evaluate.unfused_forecasts(data, t_gap).epochs == 0  # all fused
    # a newer model's second forecast for an epoch, and one off by round-off: one epoch
    data.forecasts.append(data.forecasts[3])
    data.forecasts.append(types.Measurement(data.forecasts[4].t + 1e-9, np.zeros(3),
                                            np.eye(3), source=types.Source.FORECAST))
    # forecasts after the gap: superseded by the real measurements there, by design
    data.forecasts.append(types.Measurement(data.measurements[-1].t, np.zeros(3), np.eye(3),
                                            source=types.Source.FORECAST))
    late = evaluate.unfused_forecasts(data, t_gap)
    assert (late.epochs, late.forecast_epochs) == (0, GAP)
    # a real measurement at a gap epoch (another station) supersedes its forecast: not late
    k = TRACK + 5
    data.estimates[k] = types.StateEstimate(data.estimates[k].t, data.estimates[k].x,
                                            update_source=types.UpdateSource.SENSOR)
    assert evaluate.unfused_forecasts(data, t_gap).epochs == 0
    # no forecasts at all (the surrogate could not fit): nothing late, nothing to warn of
    bare = synthetic(forecasts=False)
    late = evaluate.unfused_forecasts(bare, gap_epochs(bare))
    assert (late.epochs, late.forecast_epochs) == (0, 0)
    assert live.late_warning(late, {}) is None


def test_an_epoch_counts_as_fused_wherever_its_estimate_sits_in_the_bag():
    """An estimate fused later for an earlier epoch (rolled back and re-fused) counts as
    fused wherever it sits in the bag; a prediction published twice is still not fused."""
    data = synthetic()
    t_late = data.estimates[TRACK + FUSED].t
    data.estimates.append(types.StateEstimate(t_late, data.estimates[0].x,
                                              update_source=types.UpdateSource.NONE))
    assert evaluate.unfused_forecasts(data, gap_epochs(data)).epochs == GAP - FUSED
    data.estimates.append(types.StateEstimate(t_late, data.estimates[0].x,
                                              update_source=types.UpdateSource.FORECAST))
    assert evaluate.unfused_forecasts(data, gap_epochs(data)).epochs == GAP - FUSED - 1


def test_the_warning_is_one_line_and_quotes_the_filters_counters():
    late = evaluate.unfused_forecasts(synthetic(), gap_epochs(synthetic()))
    diag = [_diagnostics("surrogate", {"forecast_invalid": "3"}),
            _diagnostics("filter", {"forecast_superseded": "1", "forecasts_rolled_back": "0"}),
            _diagnostics("filter", {"forecast_superseded": "7", "forecasts_rolled_back": "2",
                                    "rejected_gate": "0", "model": "fitted"})]
    counters = live.filter_counters(diag)
    assert counters == {"forecast_superseded": 7, "forecasts_rolled_back": 2, "rejected_gate": 0}
    text = live.late_warning(late, counters)
    assert text is not None and "\n" not in text and text.startswith("warning:")
    assert f"{GAP - FUSED} of {GAP} gap epochs" in text
    assert "forecast_superseded=7, forecasts_rolled_back=2" in text
    assert "rejected_gate" not in text  # zero counters are left out
    assert live.filter_counters([]) == {}


def _diagnostics(node: str, values: dict[str, str]) -> SimpleNamespace:
    """A DiagnosticArray look-alike with one status."""
    kv = [SimpleNamespace(key=k, value=v) for k, v in values.items()]
    return SimpleNamespace(status=[SimpleNamespace(name=node, values=kv)])


def test_strict_is_an_option_of_live():
    parser = cli.build_parser()
    assert parser.parse_args(["live", "--strict"]).strict is True
    assert parser.parse_args(["live"]).strict is False
    p = argparse.ArgumentParser()
    live.add_arguments(p)
    assert "--strict" in p.format_help()


SENSOR_LOG = """\
[INFO] [1795577894.451110721] [sensor_sim]: iss: 516 measurements, time scale 1000.0x
[INFO] [1795577899.000000000] [sensor_sim]: waiting for: /ssa/forecast=2 (has 0)
[INFO] [1795577900.000000000] [sensor_sim]: subscribers matched; starting
[INFO] [1795577960.500000000] [sensor_sim]: schedule done: 445 measurements, 71 withheld
"""


def test_the_simulations_wall_time_comes_from_the_sensor_log(tmp_path):
    log = tmp_path / "sensor_sim.err"
    log.write_text(SENSOR_LOG)
    assert runs.sensor_wall_times(log) == pytest.approx((1795577900.0, 1795577960.5))
    log.write_text(SENSOR_LOG.replace("subscribers matched; starting",
                                      "starting (no subscribers awaited: wait_for is empty)"))
    assert runs.sensor_wall_times(log) == pytest.approx((1795577900.0, 1795577960.5))
    log.write_text(SENSOR_LOG.splitlines()[0])  # killed before it finished
    assert runs.sensor_wall_times(log) is None
    assert runs.sensor_wall_times(tmp_path / "missing.err") is None


@pytest.mark.parametrize("ran, warned", [(60.0, False), (71.9, False), (72.1, True),
                                         (300.0, True)])
def test_a_run_more_than_20_percent_slower_than_asked_is_warned_of(ran, warned):
    text = live.slow_warning(ran, sim_s=60000.0, time_scale=1000.0)  # 60 s asked
    assert (text is not None) == warned
    if text:
        assert text.startswith("warning: --time-scale 1000") and "\n" not in text
        assert f"took {ran:.1f} s" in text


def test_sub_second_runs_get_some_slack():
    assert live.slow_warning(0.9, sim_s=60000.0, time_scale=100000.0) is None  # 0.6 s asked
    assert live.slow_warning(1.2, sim_s=60000.0, time_scale=100000.0) is not None


def test_late_count_for_an_empty_gap_is_zero():
    assert evaluate.unfused_forecasts(synthetic(), np.array([])).epochs == 0

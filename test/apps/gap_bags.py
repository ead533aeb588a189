"""Synthetic bag contents (`evaluate.BagData`) around a gap, shared by the app tests:
two-body truth of the ISS scenario every `CADENCE` s from `T0`, noise-free position
measurements, withheld inside the gap."""

from collections.abc import Iterator

import numpy as np

from ssa_fusion.apps import evaluate
from ssa_fusion.core.base import types
from ssa_fusion.core.motion import kepler
from ssa_fusion.sim import scenarios

T0, CADENCE = 1000.0, 120.0


def around_a_gap(track: int, gap: int, after: int
                 ) -> tuple[evaluate.BagData, Iterator[tuple[int, float, np.ndarray, bool]]]:
    """BagData with the truth and the (real or withheld) measurements of `track` epochs,
    a gap of `gap` and `after` more; and (index, epoch, true state, in the gap) per epoch,
    for the caller to add its estimates and forecasts."""
    t = T0 + CADENCE * np.arange(track + gap + after)
    x0 = np.array(scenarios.get("iss_j2_pos").x0)
    x = np.array([kepler.propagate(x0, ti - T0)[0] for ti in t])
    data = evaluate.BagData()
    epochs = []
    for i, (ti, xi) in enumerate(zip(t, x, strict=True)):
        data.truth.append(types.StateEstimate(ti, xi))
        in_gap = track <= i < track + gap
        (data.withheld if in_gap else data.measurements).append(
            types.Measurement(ti, xi[:3], 1e-6 * np.eye(3)))
        epochs.append((i, float(ti), xi, in_gap))
    return data, iter(epochs)

"""Study (not a test): the Hankel-DMD delay count chosen on the training window only.

For each seed, the tracking window before the gap is split: the surrogate is fitted on all
of it but its last gap length (at most half of it), forecasts that stretch, and is scored
by the RMS error of the forecast against the *measurements* there (noisy: the sensor noise
adds the same amount to every candidate, so the ranking is that of the forecast error).
The gap itself is never looked at. Data are prepared as the surrogate prepares them (ECI lift for
range/az/el, noisy position channels divided by their noise sigma).

Usage::

    python bench/holdout_delays.py [--scenario iss_j2_rae] [--delays 120 185 250 372 450]
                                   [--seeds 6]

Prints one ``delays: ...`` line per candidate; the mean is in the data's units (km for the
ECI lift, noise sigmas for whitened channels). Asserts that each holdout lies inside the
training window and that every candidate's forecast of it is finite.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # run from a source checkout

from ssa_fusion import limit_blas_threads

limit_blas_threads()  # before numpy: the nodes' round-off

import numpy as np  # noqa: E402

from ssa_fusion.core.gaps.hankel_dmd import HankelDMD  # noqa: E402
from ssa_fusion.core.gaps.surrogate import EciLift  # noqa: E402
from ssa_fusion.sim import scenarios  # noqa: E402
from ssa_fusion.sim.simulate import simulate  # noqa: E402


def holdout_rms(s: scenarios.Scenario, seed: int, delays: list[int]) -> list[float]:
    """RMS forecast error over the held-out end of the training window, per delay count."""
    sim = simulate(s, seed)
    train = ~sim.in_gap & (sim.t < s.gap_start - 1e-9 * s.cadence_s)
    z, t = sim.z[train], sim.t[train]
    if s.lift == "eci":
        z = EciLift(scenarios.measurement_model(s)).forward(z, t)
    elif np.all(sim.sigma > 0):
        z = z / sim.sigma
    h = min(round(s.gap_s / s.cadence_s), len(z) // 2)
    # what is claimed: a holdout of at least one epoch, inside the training window only
    assert h >= 1 and t[-1] < s.gap_start, (h, t[-1], s.gap_start)
    fit, held = z[:-h].T, z[-h:].T
    return [float(np.sqrt(np.mean(np.sum((HankelDMD(d).fit(fit).forecast(h) - held) ** 2,
                                         axis=0))))
            for d in delays]


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--scenario", default="iss_j2_rae", choices=list(scenarios.SCENARIOS))
    p.add_argument("--delays", type=int, nargs="+", default=[120, 185, 250, 372, 450])
    p.add_argument("--seeds", type=int, default=6)
    args = p.parse_args()
    s = scenarios.get(args.scenario)
    rms = np.array([holdout_rms(s, seed, args.delays) for seed in range(1, args.seeds + 1)])
    assert np.isfinite(rms).all(), "a forecast of the holdout was not finite"
    print(f"scenario: {s.name}  training samples: {round(s.track_s / s.cadence_s)}  "
          f"held out: {min(round(s.gap_s / s.cadence_s), round(s.track_s / s.cadence_s) // 2)}  "
          f"configured delays: {s.delays}")
    for j, d in enumerate(args.delays):
        print(f"delays: {d:4d}  holdout_rms_mean: {rms[:, j].mean():.5g}  "
              f"per_seed: {[float(format(v, '.4g')) for v in rms[:, j]]}")


if __name__ == "__main__":
    main()

"""Study (not a test): accuracy against consistency of the DMD-EKF over noise seeds.

For each scenario, process-noise density q and forecast `noise_share` a (the k-th forecast
of a gap carries a R + k D(k); the reproduction uses a = 1), runs the DMD-EKF and the
hypothetical EKF on `--seeds` noise seeds and prints the ratio eps(DMD-EKF) / eps(hyp) per
seed, its mean and maximum, how many seeds meet the ratio target (<= 1.5), and the
mean NEES of both filters over the gap (per-epoch NEES averaged over the seeds, as in
`ssa-fusion reproduce`) with its two-sided 95 % chi-square band. This is how
docs/RESULTS.md shows that no q and no share puts cr3bp_halo_noisy's DMD-EKF inside the NEES
band while keeping its ratio, and that a share below 1 breaks iss_j2_pos_noisy.

Usage::

    python bench/consistency_tradeoff.py [--scenario cr3bp_halo_noisy] [--q 1e-6 1e-9]
                                         [--share 1 0.3] [--seeds 10]

`--q` defaults to the scenario's own q. About 20 s per (scenario, q, share) for 10 seeds on
two cores. Asserts that on every seed the DMD-EKF fused forecasts at >= 90 % of the gap
epochs (else its ratio would be that of a filter coasting through the gap).
"""

from __future__ import annotations

import argparse
import itertools
import sys
from multiprocessing import Pool
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # run from a source checkout

from ssa_fusion import limit_blas_threads

limit_blas_threads()  # before numpy: the nodes' round-off

import numpy as np  # noqa: E402

from ssa_fusion.core.base.metrics import chi2_bounds  # noqa: E402
from ssa_fusion.evaluation.arms import ArmName  # noqa: E402
from ssa_fusion.sim import scenarios  # noqa: E402
from ssa_fusion.sim.simulate import simulate  # noqa: E402
from ssa_fusion.studies.experiments import evaluate_sim  # noqa: E402


def one_seed(job: tuple[str, float, float, int]
             ) -> tuple[float, np.ndarray, np.ndarray, float]:
    """(ratio, per-epoch NEES of the DMD-EKF, of the hypothetical EKF, share of the gap
    epochs at which the DMD-EKF fused a forecast) for one seed."""
    name, q, share, seed = job
    s = scenarios.get(name).with_(q=q)
    sim = simulate(s, seed)
    ev, _ = evaluate_sim(s, sim, seed, only=(ArmName.DMD_EKF, ArmName.HYPOTHETICAL_EKF),
                         noise_share=share)
    dmd, hyp = ev.scores[ArmName.DMD_EKF], ev.scores[ArmName.HYPOTHETICAL_EKF]
    return dmd.epsilon / hyp.epsilon, dmd.nees, hyp.nees, ev.coverage


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--scenario", nargs="+", default=["cr3bp_halo_noisy"])
    ap.add_argument("--q", nargs="+", type=float, default=None)
    ap.add_argument("--share", nargs="+", type=float, default=[1.0])
    ap.add_argument("--seeds", type=int, default=10)
    a = ap.parse_args()
    with Pool(2) as pool:
        for name in a.scenario:
            s = scenarios.get(name)
            lo, hi = chi2_bounds(s.n, a.seeds)
            for q, share in itertools.product(a.q or [s.q], a.share):
                jobs = [(name, q, share, seed) for seed in range(1, a.seeds + 1)]
                out = pool.map(one_seed, jobs)
                r = np.array([o[0] for o in out])
                nees_dmd = float(np.mean(np.mean([o[1] for o in out], axis=0)))
                nees_hyp = float(np.mean(np.mean([o[2] for o in out], axis=0)))
                fused = min(o[3] for o in out)
                print(f"{name} q={q:g} share={share:g}: ratio {np.round(r, 2).tolist()} "
                      f"mean {r.mean():.2f} max {r.max():.2f} <=1.5: {(r <= 1.5).sum()}"
                      f"/{len(r)}; NEES DMD-EKF {nees_dmd:.2f} hypothetical {nees_hyp:.2f} "
                      f"(band {lo:.2f}-{hi:.2f}); forecasts fused at >= {fused:.0%} of the "
                      f"gap epochs", flush=True)
                # the DMD-EKF arm is what it claims only if it fused forecasts through the
                # gap (the threshold of test_reproduce)
                assert fused >= 0.9, f"{name}: DMD-EKF fused forecasts at {fused:.0%} of the gap"


if __name__ == "__main__":
    main()

"""Run in a subprocess by test_blas_kernels.py under one OpenBLAS core type.

``probe``: prints the BLAS kernel numpy and scipy run, and checks an SVD with known
singular values (exit 0 only if the kernel runs and computes correctly).
``forecast OUT.npz``: Hankel-DMD forecasts and ranks of the reference cases to OUT.npz.
"""

from __future__ import annotations

import json
import sys

import numpy as np
import scipy.linalg as sla
import threadpoolctl


def probe() -> None:
    rng = np.random.default_rng(0)
    left = np.linalg.qr(rng.standard_normal((200, 200)))[0]
    right = np.linalg.qr(rng.standard_normal((300, 200)))[0]
    s = np.logspace(0, -6, 200)
    got = sla.svd((left * s) @ right.T, compute_uv=False)
    if not np.allclose(got, s, rtol=1e-8, atol=1e-14):
        sys.exit("wrong singular values")
    kernels = sorted({i.get("architecture", "?") for i in threadpoolctl.threadpool_info()
                      if i.get("internal_api") == "openblas"})
    print(json.dumps(kernels))


def cases() -> dict[str, tuple[np.ndarray, int, int | None, int]]:
    """name -> (training data (channels, samples), delays, rank, forecast steps)."""
    from ssa_fusion.core.motion.dynamics import elements_to_state, propagate
    from ssa_fusion.sim.scenarios import ISS_ELEMENTS

    x0 = elements_to_state(**ISS_ELEMENTS)
    pos = np.asarray(propagate("j2", x0, np.arange(2100) * 30.0))[:, :3].T * 1e3  # m
    noisy = pos[:, :1000] + np.random.default_rng(1).normal(0.0, 1e4, (3, 1000))  # 10 km
    return {
        # noise-free, short window: the test suite's one-orbit case (rank at the floor/cap)
        "iss_360_60": (pos[:, :360], 60, None, 186),
        # noise-free, the paper's window and delays
        "iss_1860_120": (pos[:, :1860], 120, None, 186),
        # more Hankel rows than columns (the structural-zero median case)
        "iss_700_372": (pos[:, :700], 372, None, 186),
        # noisy: the rank is the Gavish-Donoho threshold's
        "iss_noisy_1000_120": (noisy, 120, None, 186),
    }


def forecast(out: str) -> None:
    from ssa_fusion.core.gaps.hankel_dmd import HankelDMD

    res = {}
    for name, (z, d, rank, n) in cases().items():
        m = HankelDMD(d, rank).fit(z)
        res[name] = m.forecast(n)
        res[name + ":rank"] = np.array(m.rank_)
        res[name + ":scale"] = np.array(np.abs(z).max())
    np.savez(out, **res)


if __name__ == "__main__":
    probe() if sys.argv[1] == "probe" else forecast(sys.argv[2])

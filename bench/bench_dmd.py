"""Benchmark: ssa_fusion HankelDMD vs PyDMD HankelDMD on ISS two-body + J2 positions.

3 channels x 720 samples at 30 s, 120 delays, fit + 200-step forecast. Runs are
interleaved (ours, PyDMD, ours, ...) so machine load affects both alike. Prints
parseable ``key: value`` lines. Run: ``.venv/bin/python bench/bench_dmd.py``.
"""

from __future__ import annotations

import os
import sys
import time
import warnings

import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), ".."))
from ssa_fusion.core.gaps.hankel_dmd import HankelDMD
from ssa_fusion.core.motion.dynamics import elements_to_state, propagate
from ssa_fusion.sim.scenarios import ISS_ELEMENTS

N_TRAIN, N_FC, DELAYS, DT, REPEATS = 720, 200, 120, 30.0, 41


def iss_positions(n: int) -> np.ndarray:
    """ISS two-body + J2 ECI positions (3, n), km, every DT s."""
    x0 = elements_to_state(**ISS_ELEMENTS)
    return np.asarray(propagate("j2", x0, np.arange(n) * DT))[:, :3].T.copy()


def ours(z: np.ndarray) -> np.ndarray:
    return HankelDMD(DELAYS).fit(z).forecast(N_FC)


def pydmd_run(z: np.ndarray) -> np.ndarray:
    from pydmd import HankelDMD as PyHankelDMD

    dmd = PyHankelDMD(svd_rank=0, exact=True, d=DELAYS).fit(z)
    dmd.dmd_time["tend"] = z.shape[1] + N_FC - 1
    return dmd.reconstructed_data[:, z.shape[1] :].real


def timed(fn, *args) -> tuple[float, object]:
    t0 = time.perf_counter()
    out = fn(*args)
    return (time.perf_counter() - t0) * 1e3, out


def bench(label: str, noise_km: float = 0.0) -> None:
    """Time fit + forecast on ISS positions with ``noise_km`` Gaussian noise (0: noise-free,
    where only the SVD resolves the kept directions; noisy data take the Gram route)."""
    pos = iss_positions(N_TRAIN + N_FC)
    z, truth = pos[:, :N_TRAIN], pos[:, N_TRAIN:]
    if noise_km:
        z = z + np.random.default_rng(0).normal(0.0, noise_km, z.shape)
    t_ours, t_py, t_cov = [], [], []
    for _ in range(3):  # warm-up
        ours(z)
        pydmd_run(z)
    for _ in range(REPEATS):
        dt, f_ours = timed(ours, z)
        t_ours.append(dt)
        dt, f_py = timed(pydmd_run, z)
        t_py.append(dt)
        model = HankelDMD(DELAYS).fit(z)
        dt, cov = timed(model.forecast_covariance, N_FC)
        t_cov.append(dt)
    err_ours = np.linalg.norm(f_ours - truth, axis=0).max()
    err_py = np.linalg.norm(f_py - truth, axis=0).max()
    med_o, med_p = float(np.median(t_ours)), float(np.median(t_py))
    sfx = label
    print(f"dmd_fit_forecast_ms_median{sfx}: {med_o:.2f}")
    print(f"dmd_fit_forecast_ms_min{sfx}: {min(t_ours):.2f}")
    print(f"pydmd_ms_median{sfx}: {med_p:.2f}")
    print(f"speedup{sfx}: {med_p / med_o:.1f}")
    print(f"dmd_forecast_cov_ms_median{sfx}: {float(np.median(t_cov)):.2f}")
    print(f"rank ours: {model.rank_}")
    print(f"max_err_km ours: {err_ours:.3e} pydmd: {err_py:.3e}")
    sig = np.sqrt(np.trace(cov, axis1=1, axis2=2))
    print(f"cov_sqrt_trace_km h1: {sig[0]:.3e} h100: {sig[99]:.3e} h200: {sig[-1]:.3e}")
    # what was timed really forecast the orbit (a bound far above both libraries' errors)
    assert f_ours.shape == truth.shape and np.isfinite(f_ours).all()
    bound = 0.1 if not noise_km else 10.0 * noise_km  # km
    assert err_ours < bound and err_py < bound, (err_ours, err_py)
    assert cov.shape == (N_FC, 3, 3) and np.all(np.diff(sig) >= -1e-9 * sig[1:])


def main() -> None:
    warnings.simplefilter("ignore")
    print(f"cpus: {os.cpu_count()} load_avg_1min: {os.getloadavg()[0]:.2f}")
    bench("")
    try:
        from threadpoolctl import threadpool_limits
    except ImportError:
        return
    with threadpool_limits(1):
        bench("_1thread")
        bench("_1thread_noisy_1km", noise_km=1.0)


if __name__ == "__main__":
    main()

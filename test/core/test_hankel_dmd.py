"""Tests of ssa_fusion.core.gaps.hankel_dmd against analytic signals and PyDMD."""

from __future__ import annotations

import warnings

import numpy as np
import pytest
from scipy.stats import chi2

from ssa_fusion.core.gaps.hankel_dmd import (
    HankelDMD,
    _gram_subspace,
    _hankel,
    _leading_subspace,
    resolvable_rank,
    svht_rank,
)
from ssa_fusion.core.motion.dynamics import elements_to_state, propagate
from ssa_fusion.sim.scenarios import ISS_ELEMENTS

FREQS = (0.011, 0.037, 0.071)  # cycles per sample


def iss_positions(n: int, dt: float = 30.0) -> np.ndarray:
    """ISS two-body + J2 ECI positions (3, n) in km at cadence dt s (test data only)."""
    x0 = elements_to_state(**ISS_ELEMENTS)
    return np.asarray(propagate("j2", x0, np.arange(n) * dt))[:, :3].T.copy()


def sinusoids(k: np.ndarray) -> np.ndarray:
    """Two channels, sum of three known frequencies (6 real modes); k = sample index."""
    w = 2 * np.pi * np.asarray(FREQS)
    return np.vstack(
        [
            np.sin(w[0] * k) + 0.5 * np.cos(w[1] * k + 0.3),
            0.8 * np.cos(w[2] * k) + 0.2 * np.sin(w[0] * k + 1.0),
        ]
    )


def pydmd_forecast(z: np.ndarray, d: int, rank: int, n: int) -> tuple[np.ndarray, np.ndarray]:
    """PyDMD HankelDMD (exact) forecast of the n samples after z, and its eigenvalues."""
    pydmd = pytest.importorskip("pydmd")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        dmd = pydmd.HankelDMD(svd_rank=rank, exact=True, d=d).fit(z)
        dmd.dmd_time["tend"] = z.shape[1] + n - 1
        rec = dmd.reconstructed_data
    return rec[:, z.shape[1] :].real, np.asarray(dmd.eigs)


@pytest.fixture(scope="module")
def iss() -> np.ndarray:
    return iss_positions(920)


@pytest.mark.parametrize("shape", [(2, 9), (40, 70), (360, 600), (70, 40)])
def test_leading_subspace_matches_numpy_svd(shape: tuple[int, int]) -> None:
    """The LQ + SVD route (wide) and the thin SVD (tall) against numpy's SVD."""
    rng = np.random.default_rng(4)
    n, k = shape
    p = min(n, k)
    # distinct, well-resolved singular values 1 .. 1e-3
    left = np.linalg.qr(rng.standard_normal((n, p)))[0]
    right = np.linalg.qr(rng.standard_normal((k, p)))[0]
    s_true = np.logspace(0, -3, p)
    x = (left * s_true) @ right.T
    r = max(1, p // 3)
    sigma, u = _leading_subspace(x, lambda s: r)
    u_ref, s_ref, _ = np.linalg.svd(x, full_matrices=False)
    np.testing.assert_allclose(sigma, s_true, rtol=1e-9)
    np.testing.assert_allclose(sigma, s_ref, rtol=1e-9, atol=1e-12)
    assert u.shape == (n, r)
    np.testing.assert_allclose(np.abs(np.sum(u * u_ref[:, :r], axis=0)), 1.0, atol=1e-9)


def test_gram_route_only_where_it_matches_the_svd(iss: np.ndarray) -> None:
    """Noisy data: the Gram route is taken and keeps the SVD's rank and subspace (to 1e-9);
    noise-free data (median singular value at round-off): it declines, the SVD decides."""
    rng = np.random.default_rng(3)
    z = iss[:, :720] + rng.normal(0.0, 1.0, (3, 720))  # 1 km noise
    x = _hankel(z, 120)[:, :-1]
    rule = lambda s: svht_rank(s, *x.shape)  # noqa: E731
    fast = _gram_subspace(x, rule)
    assert fast is not None
    u_ref, s_ref, _ = np.linalg.svd(x, full_matrices=False)
    r = fast[1].shape[1]
    assert r == svht_rank(s_ref, *x.shape)
    np.testing.assert_allclose(fast[0], s_ref, rtol=1e-6)
    cosines = np.linalg.svd(fast[1].T @ u_ref[:, :r], compute_uv=False)  # principal angles
    np.testing.assert_allclose(cosines, 1.0, atol=1e-9)
    assert _gram_subspace(_hankel(iss[:, :720], 120)[:, :-1], rule) is None


def test_svht_rank_matches_pydmd() -> None:
    from pydmd.utils import _svht

    rng = np.random.default_rng(0)
    s = np.sort(np.abs(rng.standard_normal(50)))[::-1] * np.r_[np.full(5, 100.0), np.ones(45)]
    assert svht_rank(s, 50, 80) == _svht(s, 50, 80)


def test_exact_sinusoids_match_pydmd() -> None:
    z = sinusoids(np.arange(400))
    ours = HankelDMD(50, rank=6).fit(z)
    ref, ref_eigs = pydmd_forecast(z, 50, 6, 200)
    np.testing.assert_allclose(ours.forecast(200), ref, atol=1e-9)
    np.testing.assert_allclose(np.sort_complex(ours.eigs), np.sort_complex(ref_eigs), atol=1e-10)
    # modes: same directions (up to complex scaling) as PyDMD's exact modes
    pydmd = pytest.importorskip("pydmd")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        ref_modes = pydmd.HankelDMD(svd_rank=6, exact=True, d=50).fit(z).modes
    for j, lam in enumerate(ours.eigs):
        k = int(np.argmin(np.abs(ref_eigs - lam)))
        a, b = ours.modes[:, j], ref_modes[:, k]
        cos = abs(np.vdot(a, b)) / (np.linalg.norm(a) * np.linalg.norm(b))
        assert cos == pytest.approx(1.0, abs=1e-9)


def test_iss_eigs_match_pydmd_at_resolved_rank(iss: np.ndarray) -> None:
    z = iss[:, :720]
    ours = HankelDMD(120, rank=9).fit(z)
    _, ref_eigs = pydmd_forecast(z, 120, 9, 1)
    np.testing.assert_allclose(np.sort_complex(ours.eigs), np.sort_complex(ref_eigs), atol=1e-8)


def test_iss_forecast_not_worse_than_pydmd(iss: np.ndarray) -> None:
    z, truth = iss[:, :720], iss[:, 720:920]
    ours = HankelDMD(120).fit(z)
    ref, _ = pydmd_forecast(z, 120, 0, 200)
    err_ours = np.linalg.norm(ours.forecast(200) - truth, axis=0).max()
    err_ref = np.linalg.norm(ref - truth, axis=0).max()
    assert err_ours <= err_ref
    assert err_ours < 1e-3  # km over 100 min
    assert np.all(np.abs(ours.eigs_stable_) <= 1.0 + 1e-12)


def test_pure_sinusoids_recovered_exactly() -> None:
    k = np.arange(600)
    z = sinusoids(k)
    dmd = HankelDMD(50).fit(z[:, :400])
    np.testing.assert_allclose(dmd.forecast(200), z[:, 400:], atol=1e-8)
    fixed = HankelDMD(50, rank=6).fit(z[:, :400])
    freqs = np.sort(np.abs(np.angle(fixed.eigs)) / (2 * np.pi))[::2]
    np.testing.assert_allclose(freqs, FREQS, atol=1e-10)
    np.testing.assert_allclose(np.abs(fixed.eigs), 1.0, atol=1e-10)


@pytest.mark.parametrize("sigma", [1e-3, 1e-2, 5e-2])
def test_rank_selection_finds_number_of_modes(sigma: float) -> None:
    rng = np.random.default_rng(7)
    z = sinusoids(np.arange(400))
    dmd = HankelDMD(50).fit(z + sigma * rng.standard_normal(z.shape))
    assert dmd.rank_ == 2 * len(FREQS)


def test_rank_rule_on_a_tall_hankel_matrix() -> None:
    """More Hankel rows (2 x 150) than columns (130): the threshold's median is taken over
    the 130 singular values there are, not over 170 structural zeros besides them (which
    put the median at 0 and selected the cap, 48)."""
    rng = np.random.default_rng(7)
    z = sinusoids(np.arange(280))
    dmd = HankelDMD(150).fit(z + 1e-3 * rng.standard_normal(z.shape))
    assert dmd.singular_values_.size == 130
    assert dmd.rank_ == 2 * len(FREQS)


@pytest.mark.parametrize("delays", [50, 300])
def test_never_keeps_a_direction_the_svd_cannot_resolve(delays: int) -> None:
    """Noise-free sinusoids are rank 6: every further singular value is round-off, below
    max(rows, cols) * eps * sigma_max, so neither the automatic rule (whose median is at
    round-off) nor a fixed rank 20 keeps one."""
    z = sinusoids(np.arange(400))
    for rank in (None, 20):
        dmd = HankelDMD(delays, rank).fit(z)
        s = dmd.singular_values_
        assert dmd.rank_ == 6 == resolvable_rank(s, 2 * delays, 400 - delays)
    assert resolvable_rank([2.0, 1e-12, 1e-14], 10, 100) == 2  # floor 2 * 100 * eps = 4.4e-14
    assert resolvable_rank([0.0, 0.0], 3, 3) == 1


def test_wrapping_angle_forecast() -> None:
    k = np.arange(700)
    rate = 0.013  # rad per sample: wraps every ~483 samples
    rng_km = 1000.0 + 300.0 * np.sin(2 * np.pi * 0.004 * k)
    az = np.mod(5.0 + rate * k, 2 * np.pi)
    el = 0.3 * np.cos(2 * np.pi * 0.004 * k)
    z = np.vstack([rng_km, az, el])
    dmd = HankelDMD(60, angle_channels=(1,)).fit(z[:, :500])
    f = dmd.forecast(200)
    assert np.all((f[1] >= 0.0) & (f[1] < 2 * np.pi))
    daz = np.angle(np.exp(1j * (f[1] - z[1, 500:])))
    assert np.abs(daz).max() < 1e-6
    np.testing.assert_allclose(f[0], z[0, 500:], atol=1e-6)
    np.testing.assert_allclose(f[2], z[2, 500:], atol=1e-9)


def test_long_forecast_bounded(iss: np.ndarray) -> None:
    rng = np.random.default_rng(3)
    z = sinusoids(np.arange(400)) + 0.05 * rng.standard_normal((2, 400))
    f = HankelDMD(50).fit(z).forecast(10_000)
    assert np.all(np.isfinite(f)) and np.abs(f).max() < 2.0 * np.abs(z).max()
    f_iss = HankelDMD(120).fit(iss[:, :720]).forecast(10_000)
    assert np.abs(f_iss).max() < 1.05 * np.abs(iss).max()
    # a genuinely growing oscillation: growth is capped, never exponential
    k = np.arange(400)
    grow = np.exp(0.004 * k) * np.sin(2 * np.pi * 0.02 * k)
    g = HankelDMD(40).fit(grow[None]).forecast(10_000)
    assert np.isfinite(g).all() and np.abs(g).max() < 4.0 * np.abs(grow).max()


def test_forecast_covariance_properties(iss: np.ndarray) -> None:
    rng = np.random.default_rng(11)
    z = sinusoids(np.arange(400)) + 0.05 * rng.standard_normal((2, 400))
    dmd = HankelDMD(50).fit(z)
    cov = dmd.forecast_covariance(600)  # beyond the in-sample horizons too
    assert cov.shape == (600, 2, 2)
    np.testing.assert_allclose(cov, cov.transpose(0, 2, 1), atol=0)
    assert np.linalg.eigvalsh(cov).min() >= -1e-15
    tr = np.trace(cov, axis1=1, axis2=2)
    assert np.all(np.diff(tr) >= -1e-12 * tr[1:]) and tr[-1] > tr[0]
    np.testing.assert_allclose(cov[0], dmd.residual_cov_, rtol=1e-12)
    # noise level: the one-step residual is about the sensor noise
    np.testing.assert_allclose(np.sqrt(np.diag(dmd.residual_cov_)), 0.05, rtol=0.2)
    # noise-free data: tiny, not inflated
    clean = HankelDMD(120).fit(iss[:, :720])
    c = clean.forecast_covariance(200)
    assert np.sqrt(np.trace(c[-1])) < 1e-3  # km


def test_forecast_covariance_consistent_nees() -> None:
    """Monte Carlo: forecast minus future noisy measurement vs published covariance."""
    rng = np.random.default_rng(2024)
    sigma, n_train, n_fc, runs = 0.05, 400, 200, 200
    k = np.arange(n_train + n_fc)
    truth = sinusoids(k)
    nees = np.empty((runs, n_fc))
    for i in range(runs):
        z = truth + sigma * rng.standard_normal(truth.shape)
        dmd = HankelDMD(50).fit(z[:, :n_train])
        err = dmd.forecast(n_fc) - z[:, n_train:]
        cov = dmd.forecast_covariance(n_fc)
        nees[i] = np.einsum("ik,kij,jk->k", err, np.linalg.inv(cov), err)
    dof = 2
    lo, hi = chi2.ppf([0.0005, 0.9995], dof * runs) / runs
    per_horizon = nees.mean(axis=0)
    assert lo < nees.mean() < hi
    # loose per-horizon band (errors are correlated across horizons)
    assert np.mean((per_horizon > lo) & (per_horizon < hi)) > 0.9


def test_input_validation() -> None:
    with pytest.raises(ValueError):
        HankelDMD(10).fit(np.zeros((2, 11)))
    z = sinusoids(np.arange(100))
    z[0, 5] = np.nan
    with pytest.raises(ValueError):
        HankelDMD(10).fit(z)
    with pytest.raises(RuntimeError):
        HankelDMD(10).forecast(3)
    with pytest.raises(ValueError, match="max_rank"):
        HankelDMD(10, max_rank=0)
    dmd = HankelDMD(10).fit(sinusoids(np.arange(100)))
    assert dmd.forecast(0).shape == (2, 0)
    assert dmd.forecast_covariance(0).shape == (0, 2, 2)


def test_warm_up_imports_what_a_fit_uses():
    """`warm_up` leaves scipy.linalg imported (in a fresh interpreter, where it was not)."""
    import subprocess
    import sys

    code = ("import sys, ssa_fusion.core.gaps.hankel_dmd as h; a = 'scipy.linalg' in sys.modules; "
            "h.warm_up(); print(a, 'scipy.linalg' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True).stdout.split()
    assert out == ["False", "True"]

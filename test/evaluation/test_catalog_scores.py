"""`evaluation.catalog_scores`: grouping and matching against direct per-group numpy."""

from __future__ import annotations

import numpy as np

from ssa_fusion.evaluation import catalog_scores as cs


def test_group_percentiles_are_numpys_per_group():
    rng = np.random.default_rng(3)
    n = 7
    code = rng.integers(0, n - 1, 500)  # group n-1 has no row
    values = rng.lognormal(size=500)
    values[::17] = np.nan  # not counted
    count, (med, p95) = cs.group_percentiles(code, values, n, (50.0, 95.0))
    for g in range(n):
        v = values[(code == g) & np.isfinite(values)]
        assert count[g] == v.size
        if v.size:
            assert med[g] == np.median(v) and np.isclose(p95[g], np.percentile(v, 95),
                                                         rtol=1e-14)
        else:
            assert np.isnan(med[g]) and np.isnan(p95[g])


def test_matcher_finds_the_same_object_and_epoch_only_the_last_row_of_a_pair():
    ref_code = np.array([0, 1, 0, 2, 0])
    ref_t = np.array([10.0, 10.0, 20.0, 30.0, 20.0])
    m = cs.Matcher(ref_code, ref_t)
    got = m.find(np.array([0, 1, 0, 2, 1, 0, -1, 3]),
                 np.array([10.0, 10.0, 20.0, 30.0, 20.0, 20.0 + 1e-9, 10.0, 10.0]))
    assert got.tolist() == [0, 1, 4, 3, -1, -1, -1, -1]


def test_nees_is_the_quadratic_form_and_nan_without_covariance():
    rng = np.random.default_rng(5)
    A = rng.normal(size=(4, 6, 6))
    P = A @ np.swapaxes(A, 1, 2) + 0.1 * np.eye(6)
    P[3] = 0.0
    e = rng.normal(size=(4, 6))
    got = cs.nees(e, P)
    for i in range(3):
        assert np.isclose(got[i], e[i] @ np.linalg.solve(P[i], e[i]), rtol=1e-10)
    assert np.isnan(got[3])

"""`validation.rows_problems`: per row, the cause `measurement_problem` gives the same
measurement (property-tested over rows with every kind of defect)."""

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from ssa_fusion.core.base.rows import MeasurementRows
from ssa_fusion.core.base.types import Kind
from ssa_fusion.core.measure import validation

VALUES = st.sampled_from([0.0, 0.5, -0.5, 1.0, 3.0, 7.0, 7000.0, -7000.0, 2e7, 1e13, np.nan,
                          np.inf, 1e-13])


@st.composite
def rows_of_every_defect(draw: st.DrawFn) -> MeasurementRows:
    m = draw(st.integers(1, 20))
    z = np.array(draw(st.lists(st.tuples(VALUES, VALUES, VALUES), min_size=m, max_size=m)))
    diag = np.array(draw(st.lists(st.tuples(VALUES, VALUES, VALUES), min_size=m, max_size=m)))
    R = np.zeros((m, 3, 3))
    R[:, [0, 1, 2], [0, 1, 2]] = diag
    off = np.array(draw(st.lists(VALUES, min_size=m, max_size=m)))
    asym = np.array(draw(st.lists(st.booleans(), min_size=m, max_size=m)))
    R[:, 0, 1] = off
    R[:, 1, 0] = np.where(asym, -off, off)
    ids = draw(st.lists(st.sampled_from(["a", "25544", "x" * 129]), min_size=m, max_size=m))
    return MeasurementRows(
        t=np.array(draw(st.lists(st.sampled_from([1.7e9, np.nan, np.inf]), min_size=m,
                                 max_size=m))),
        object_id=ids, frame_id=draw(st.lists(st.sampled_from(["millstone", "f" * 200]),
                                              min_size=m, max_size=m)),
        z=z, R=R,
        kind=np.array(draw(st.lists(st.sampled_from([0, 1, 2]), min_size=m, max_size=m)),
                      np.uint8),
        horizon=np.array(draw(st.lists(st.sampled_from([0.0, np.nan]), min_size=m,
                                       max_size=m))))


@settings(max_examples=300, deadline=None)
@given(rows_of_every_defect(), st.sampled_from(list(Kind)))
def test_each_row_gets_the_cause_of_the_per_measurement_check(rows, kind):
    got = validation.rows_problems(rows, kind)
    for i in range(len(rows)):
        m = validation.row_measurement(rows, i)
        if m.kind == Kind.RA_DEC:
            m.z, m.R = m.z[:2], m.R[:2, :2]
        assert got[i] == validation.measurement_problem(m, kind)[0], i


def test_covariances_ok_is_is_covariance_of_each():
    rng = np.random.default_rng(3)
    A = rng.normal(size=(200, 3, 3))
    R = np.concatenate([A @ A.transpose(0, 2, 1), A, -A @ A.transpose(0, 2, 1),
                        np.zeros((1, 3, 3)), np.full((1, 3, 3), np.nan)])
    want = [validation.is_covariance(r) for r in R]
    assert validation.covariances_ok(R).tolist() == want
    assert any(want) and not all(want)


def test_covariances_ok_without_decomposing_dominant_diagonals():
    """Diagonally dominant matrices (no eigenvalue below 0) and their neighbours just outside
    (a diagonal entry a hair below 0, an off-diagonal a hair too large) get `is_covariance`'s
    answer whether decomposed or not."""
    rng = np.random.default_rng(5)
    d = rng.uniform(0.1, 10.0, size=(100, 3))
    diagonal = np.stack([np.diag(v) for v in d])
    singular = np.tile([[1.0, 1.0, 0.0], [1.0, 1.0, 0.0], [0.0, 0.0, 1.0]], (1, 1, 1))
    tiny_negative = np.stack([np.diag([1.0, 1.0, -x]) for x in (1e-14, 1e-12, 1e-10, 1e-3)])
    beyond = np.stack([[[1.0, e, 0.0], [e, 1.0, 0.0], [0.0, 0.0, 1.0]]
                       for e in (1.0 + 1e-15, 1.0 + 1e-9, 1.5)])
    R = np.concatenate([diagonal, singular, tiny_negative, beyond])
    want = [validation.is_covariance(r) for r in R]
    assert validation.covariances_ok(R).tolist() == want
    assert want[:101] == [True] * 101 and not all(want)


def test_states_problems_is_state_problem_of_each():
    # healthy, singular, asymmetric, indefinite, enormous, zero, non-finite state or
    # covariance, and an enormous indefinite one (the covariance cause comes first)
    rng = np.random.default_rng(4)
    A = rng.normal(size=(60, 6, 6))
    good = A @ A.transpose(0, 2, 1)
    singular = good.copy()
    singular[:, 0, :] = singular[:, :, 0] = 0.0
    asym = good + np.triu(np.full((6, 6), 1e-3), 1)
    P = np.concatenate([good, singular, asym, -good, good * 1e13, np.zeros((3, 6, 6)),
                        good[:3], np.where(np.eye(6) > 0, np.nan, good[:3]), -good[:3] * 1e13])
    x = rng.normal(size=(len(P), 6)) * 7000.0
    x[len(P) - 12] = np.inf  # a non-finite state with a sound covariance
    got = validation.states_problems(x, P)
    want = [validation.state_problem(x[i], P[i])[0] for i in range(len(P))]
    assert got.tolist() == want
    assert len(set(want)) == 4  # "", nonfinite, covariance, implausible: each exercised

"""Tests for ssa_fusion.evaluation.object_states: batches of many objects' rows split per
object, against the per-row dictionary of lists it replaces."""

from collections import defaultdict

import numpy as np

from ssa_fusion.evaluation.object_states import ObjectStates, StatesByObject, merge, states_of


def test_batches_split_per_object_in_epoch_order_ties_as_they_came():
    rng = np.random.default_rng(7)
    gather = StatesByObject()
    naive: dict[str, list[tuple[float, np.ndarray]]] = defaultdict(list)
    for _ in range(40):  # batches of rows of 25 objects, epochs out of order, ties included
        k = int(rng.integers(0, 30))
        ids = [f"obj{int(i)}" for i in rng.integers(0, 25, k)]
        t = rng.integers(0, 50, k).astype(float)
        x = rng.normal(size=(k, 6))
        gather.add(ids, t, x)
        for oid, ti, xi in zip(ids, t.tolist(), x, strict=True):
            naive[oid].append((ti, xi))
    assert gather.rows == sum(len(v) for v in naive.values())
    got = gather.done()
    assert set(got) == set(naive)
    for oid, rows in naive.items():
        rows.sort(key=lambda r: r[0])  # stable: ties keep the order they came in
        np.testing.assert_array_equal(got[oid].t, [r[0] for r in rows])
        np.testing.assert_array_equal(got[oid].x, np.array([r[1] for r in rows]))


def test_nothing_gathered_is_no_object_and_an_empty_list_no_state():
    assert StatesByObject().done() == {}
    empty = states_of({"a": []})["a"]
    assert empty.t.shape == (0,) and empty.x.shape == (0, 6)


def test_merge_keeps_epoch_order_and_the_parts_order_at_ties():
    a = ObjectStates(np.array([1.0, 3.0]), np.array([[1.0] * 6, [3.0] * 6]))
    b = ObjectStates(np.array([1.0, 2.0]), np.array([[10.0] * 6, [2.0] * 6]))
    m = merge([a, b])
    np.testing.assert_array_equal(m.t, [1.0, 1.0, 2.0, 3.0])
    np.testing.assert_array_equal(m.x[:, 0], [1.0, 10.0, 2.0, 3.0])

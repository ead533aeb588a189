"""Shards of a catalog graph: which objects a catalog node process owns.

A `catalog_filter` or `catalog_surrogate` process owns objects by the ``shard_key`` (CRC-32
of ``object_id``) of its messages.

Shard k of K owns the keys of the k-th of K equal ranges of the uint32 key space, and
subscribes with a DDS content filter on that range, so it never receives the others'
traffic; K processes with shard 0..K-1 cover every object exactly once, on one host or
several in one ROS domain. (The ``shards`` and ``shard`` parameters and their rule:
`ssa_fusion.params.shared`.)
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray
from rclpy.subscription_content_filter_options import ContentFilterOptions

from ssa_fusion.core.base.rows import EstimateRows
from ssa_fusion.core.base.types import Cause, UpdateSource
from ssa_fusion.nodes.kit.diagnostics import Diagnostics, NodeCause
from ssa_fusion.ros import messages
from ssa_fusion.ros.interfaces import Message
from ssa_fusion.ros.messages import shard_range
from ssa_fusion.ros.topics import TOPIC_ESTIMATE_BATCH

LIST_OBJECTS = 200
"""Up to this many objects, a shard lists their ids on /diagnostics (``object_ids``)."""


def shard_problem(key: int, object_id: str, shard: int,
                  shards: int) -> tuple[NodeCause, str] | None:
    """Return why shard `shard` of `shards` does not take a message, or None.

    The message is of `object_id` and carries `key`; the answer is (cause, reason). One
    shard takes everything (a publisher that does not set ``shard_key`` included); with
    several, a key that is not the CRC-32 of the id is ``rejected_shard_key`` (its
    publisher did not set it: every shard would refuse it), and one of another shard's
    range ``ignored_other_shard`` (a DDS without content filters).
    """
    if shards <= 1:
        return None
    want = messages.shard_key(object_id)
    if key != want:
        return (NodeCause.REJECTED_SHARD_KEY, f"object {object_id!r}: shard_key {key} is not the "
                f"CRC-32 of its id ({want}); the publisher must set it (ros.messages."
                "shard_key) for a sharded graph")
    lo, hi = shard_range(shard, shards)
    if not lo <= key <= hi:
        return (NodeCause.IGNORED_OTHER_SHARD, f"object {object_id!r}, shard_key {key}: not in "
                f"[{lo}, {hi}]")
    return None


def rows_shard_problems(keys: NDArray[np.uint32], object_ids: list[str], shard: int,
                        shards: int) -> tuple[NDArray[np.bool_], NDArray[np.bool_]]:
    """Return which rows shard `shard` of `shards` refuses and which it ignores.

    `shard_problem` of each row (its `keys` and `object_ids`), vectorised: (the rows whose
    key is not the CRC-32 of their id: ``rejected_shard_key``, the rows of another shard's
    range: ``ignored_other_shard``). One shard refuses and ignores none.
    """
    m = len(object_ids)
    if shards <= 1:
        return np.zeros(m, bool), np.zeros(m, bool)
    bad = keys != messages.shard_keys(object_ids)
    lo, hi = shard_range(shard, shards)
    return bad, ~bad & ((keys < lo) | (keys > hi))


def content_filter(shard: int, shards: int, condition: str = "",
                   parameters: tuple[str, ...] = (),
                   batches: bool = False) -> ContentFilterOptions | None:
    """Return the DDS content filter of shard `shard` of `shards`, or None.

    Its key range, AND `condition` (an expression whose parameters %0.. are `parameters`)
    when given; None when there is nothing to filter (one shard, no condition). With
    `batches` (MeasurementBatch, EstimateBatch), the batches whose key range
    [``key_lo``, ``key_hi``] meets the shard's.
    """
    terms, params = [], list(parameters)
    if condition:
        terms.append(condition)
    if shards > 1:
        lo, hi = shard_range(shard, shards)
        n = len(params)
        terms.append(f"key_hi >= %{n} AND key_lo <= %{n + 1}" if batches
                     else f"shard_key BETWEEN %{n} AND %{n + 1}")
        params += [str(lo), str(hi)]
    if not terms:
        return None
    return ContentFilterOptions(" AND ".join(terms), params)


def sensor_estimates(diag: Diagnostics, msg: Message) -> tuple[int, EstimateRows | None]:
    """Return (rows taken, their rows) of an EstimateBatch of the catalog's estimates.

    A batch of forecasts (any source but SENSOR) is counted ``ignored_not_sensor``:
    (0, None); a SENSOR batch is taken whole (its row count, for lockstep), and one whose
    columns disagree is refused whole (``rejected_malformed``): (rows, None).
    """
    m = len(msg.object_id)
    if msg.update_source != UpdateSource.SENSOR:
        diag.counts[NodeCause.IGNORED_NOT_SENSOR] += m
        return 0, None
    try:
        return m, messages.estimate_batch_from_msg(msg)
    except ValueError as exc:
        diag.count(Cause.REJECTED_MALFORMED, f"{TOPIC_ESTIMATE_BATCH}: {exc}", n=m)
        return m, None

"""catalog_filter: IOD + EKF of every object of a catalog in one process, batched.

Subscribes to ``/ssa/measurement`` (range/az/el of any object from the stations of
`station`), collects what arrives, and every `batch_period` wall s fuses it all at once in a
`core.track_bank.TrackBank` (one track per ``object_id``, vectorised over objects). Publishes
``/ssa/estimate`` (``object_id`` set, update source SENSOR) for every fused measurement and
for every track an IOD starts. Rejected input is counted by cause on ``/diagnostics``;
``consumed`` counts every measurement the bank took (fused, pending in an IOD batch, or
rejected by it), so that published = consumed + refused at the door.

Sharding: with ``shards`` = K > 1 the node owns the objects whose
``Measurement.shard_key`` (CRC-32 of ``object_id``) lies in the ``shard``-th of K equal
ranges, and subscribes with a DDS content filter (``shard_key BETWEEN lo AND hi``): the
other shards' measurements never reach it. K processes with shard 0..K-1 cover every object
exactly once, on one host or several in one ROS domain.

    ros2 run ssa_fusion catalog_filter --ros-args -p use_sim_time:=true \\
        -p station:=radar_network -p shards:=2 -p shard:=0 -r __node:=catalog_filter_0
"""

from __future__ import annotations

from typing import Any

import numpy as np
from rclpy.clock import JumpThreshold
from rclpy.duration import Duration
from rclpy.node import Node
from ssa_fusion_msgs.msg import Measurement as MeasurementMsg
from ssa_fusion_msgs.msg import StateEstimate as StateEstimateMsg

from ssa_fusion.core.batch_ekf import BatchEKFConfig
from ssa_fusion.core.stations import network_stations
from ssa_fusion.core.track_bank import TrackBank, TrackBankConfig
from ssa_fusion.core.types import Cause, Kind, Source, StateEstimate, UpdateSource
from ssa_fusion.core.validation import ahead_of_clock, measurement_problem
from ssa_fusion.nodes import start_process
from ssa_fusion.nodes.common import (
    Diagnostics,
    all_non_negative,
    at_least,
    clock_lead,
    declare,
    non_negative,
    one_of,
    positive,
    run,
    wall_timer,
)
from ssa_fusion.nodes.defaults import CATALOG_FILTER
from ssa_fusion.nodes.shards import (
    LIST_OBJECTS,
    content_filter,
    declare_shard,
    shard_problem,
    shard_range,
)
from ssa_fusion.ros import messages
from ssa_fusion.ros.topics import CATALOG_QOS, TOPIC_ESTIMATE, TOPIC_MEASUREMENT


def _network(value: Any) -> str | None:
    try:
        network_stations(value)
    except ValueError as exc:
        return str(exc)
    return None


def _p0_check(v: list) -> str | None:
    if len(v) == 6 and all_non_negative(v):
        return None
    return "needs 6 standard deviations, each a finite number >= 0"


class CatalogFilterNode(Node):
    def __init__(self) -> None:
        super().__init__("catalog_filter")
        d = CATALOG_FILTER
        station = declare(self, "station", d.station,
                          "stations of the measurements: a network id, a station id, or ids "
                          "separated by commas", _network)
        model = declare(self, "motion_model", d.motion_model,
                        "motion model of every track: kepler | j2", one_of("kepler", "j2"))
        q = declare(self, "q", d.q, "process noise: white-noise acceleration spectral "
                    "density, m^2/s^3", non_negative)
        gate = declare(self, "gate", d.gate, "NIS beyond which an update is rejected "
                       "(0 = no gate)", non_negative)
        p0 = declare(self, "p0_sigma", list(d.p0_sigma), "std floor added to the IOD "
                     "covariance: 3 x m, 3 x m/s", _p0_check)
        iod_samples = declare(self, "iod_samples", d.iod_samples,
                              "measurements per initial orbit determination (3..1000)",
                              lambda v: None if isinstance(v, int) and 3 <= v <= 1000
                              else "must be an integer in 3..1000")
        span = declare(self, "iod_max_span", d.iod_max_span,
                       "s one IOD batch may span (one pass of one station)", positive)
        reinit = declare(self, "reinit_after", d.reinit_after,
                         "measurements of an object in a row beyond the gate after which its "
                         "track is dropped and its IOD starts again (0 = never)", at_least(0))
        bound = declare(self, "sigma_bound", d.sigma_bound,
                        "position/velocity sigmas limited to sigma_bound x |r| / |v| after "
                        "each prediction (0 = no limit)", non_negative)
        self.shard, self.shards = declare_shard(self, d.shards, d.shard)
        period = declare(self, "batch_period", d.batch_period,
                         "wall s between batches: what arrived meanwhile is fused at once",
                         positive)
        self.max_lead = clock_lead(self, d.max_clock_lead)
        ekf = BatchEKFConfig(motion_model=model, q=q * 1e-6, gate=gate or None,
                             sigma_bound=bound)
        self.stations = network_stations(station)
        self.bank_config = TrackBankConfig(ekf=ekf, iod_samples=iod_samples,
                                           iod_max_span_s=span,
                                           p0_sigma=tuple(v / 1000.0 for v in p0),
                                           reinit_after=reinit)
        self.bank = TrackBank(self.bank_config, self.stations)
        self.lo, self.hi = shard_range(self.shard, self.shards)
        self.diag = Diagnostics(self)
        self.diag.status["shard"] = f"{self.shard}/{self.shards} keys [{self.lo}, {self.hi}]"
        self.pub = self.create_publisher(StateEstimateMsg, TOPIC_ESTIMATE, CATALOG_QOS)
        cft = content_filter(self.shard, self.shards)
        self.sub = self.diag.subscribe(MeasurementMsg, TOPIC_MEASUREMENT,
                                       self.diag.guard(self.on_measurement), CATALOG_QOS,
                                       content_filter=cft)
        if cft is not None and not self.sub.is_cft_enabled:
            self.diag.count("content_filter_unavailable",
                            "the DDS implementation does not filter by content: every "
                            "measurement arrives and those of other shards are ignored here")
        self._pending: list[tuple[float, str, str, np.ndarray, np.ndarray]] = []
        wall_timer(self, float(period), self.diag.guard(self.fuse))
        self._jump = self.get_clock().create_jump_callback(
            JumpThreshold(min_forward=None, min_backward=Duration(nanoseconds=-1),
                          on_clock_change=False),
            post_callback=self.on_jump)
        self.activity = 0

    def on_jump(self, _jump: Any) -> None:
        self.bank = TrackBank(self.bank_config, self.stations)
        self.diag.counts["dropped"] += len(self._pending)
        self._pending.clear()
        self.diag.count(Cause.RESET_CLOCK_JUMP, "sim time jumped backwards: every track "
                        "forgotten", warn=False)

    def on_measurement(self, msg: MeasurementMsg) -> None:
        """Check one message and keep it for the next batch. Every received message ends
        counted once: ``ignored_other_shard``, ``refused`` (with its cause), ``consumed`` by
        the bank, or ``dropped`` (by a clock jump or a failed batch)."""
        self.activity += 1
        self.diag.counts["received"] += 1
        if not self._admit(msg):
            self.diag.counts["refused"] += 1

    def _admit(self, msg: MeasurementMsg) -> bool:
        """Keep `msg` for the next batch and return True, or count why not and return False
        (refused); a measurement of another shard is counted as ``ignored_other_shard``
        only, not as received (True)."""
        if msg.source != Source.SENSOR:
            self.diag.count(Cause.REJECTED_SOURCE, f"source {msg.source} on "
                            f"{TOPIC_MEASUREMENT}, which carries only sensor data")
            return False
        why = shard_problem(msg.shard_key, msg.object_id, self.shard, self.shards)
        if why:
            other = why[0] == "ignored_other_shard"
            self.diag.count(why[0], why[1], warn=not other)
            if other:
                self.diag.counts["received"] -= 1  # never this shard's: not received here
            return other
        try:
            m = messages.measurement_from_msg(msg)
        except ValueError as exc:
            self.diag.count(Cause.REJECTED_KIND, str(exc))
            return False
        cause, reason = measurement_problem(m, Kind.RANGE_AZ_EL)
        if not cause:
            if m.frame_id not in self.stations:
                cause, reason = (Cause.REJECTED_FRAME, f"station {m.frame_id!r} is not in the "
                                 f"network ({', '.join(self.stations)})")
            else:
                cause, reason = ahead_of_clock(m.t, self.get_clock().now().nanoseconds * 1e-9,
                                               self.max_lead)
        if cause:
            self.diag.count(cause, reason)
            return False
        self._pending.append((m.t, m.object_id, m.frame_id, m.z, m.R))
        return True

    def fuse(self) -> None:
        """Fuse what arrived since the last batch (in epoch order) and publish the estimates."""
        if not self._pending:
            return
        batch = sorted(self._pending, key=lambda p: p[0])  # stable: arrival order at a tie
        self._pending = []
        t = np.array([p[0] for p in batch])
        try:
            res = self.bank.process(t, [p[1] for p in batch], [p[2] for p in batch],
                                    np.array([p[3] for p in batch]),
                                    np.array([p[4] for p in batch]))
        except Exception:  # counted, then the guard logs the traceback as internal_error
            self.diag.counts["dropped"] += len(batch)
            raise
        self.diag.counts["consumed"] += len(batch)
        for i, cause in enumerate(res.cause):
            if cause == Cause.IOD_PENDING:
                self.diag.counts[cause] += 1
            elif cause:
                self.diag.count(cause, f"object {batch[i][1]!r} at t={batch[i][0]} from "
                                f"{batch[i][2]!r}", warn=cause.startswith("rej"))
        for j, i in enumerate(res.fused.tolist()):
            e = StateEstimate(t=float(t[i]), x=res.x[j], P=res.P[j], object_id=batch[i][1],
                              update_source=UpdateSource.SENSOR, nis=float(res.nis[j]))
            self.pub.publish(messages.estimate_to_msg(e))
        self.diag.counts["published_sensor"] += int(res.fused.size)
        self.diag.status["objects"] = str(len(self.bank))
        if len(self.bank) <= LIST_OBJECTS:
            self.diag.status["object_ids"] = ",".join(self.bank.object_ids)
        self.diag.status["tracks"] = str(int(self.bank.tracking.sum()))
        n = max(len(self.bank), 1)
        arrays = (self.bank.x.nbytes + self.bank.P.nbytes + self.bank.t.nbytes
                  + self.bank.tracking.nbytes)
        self.diag.status["bank_bytes_per_object"] = f"{arrays / n:.0f}"
        self.diag.status["max_batch"] = str(max(int(self.diag.status.get("max_batch", 0)),
                                                len(batch)))


def main(args: list[str] | None = None) -> int:
    start_process()
    return run(CatalogFilterNode, args)


if __name__ == "__main__":
    raise SystemExit(main())

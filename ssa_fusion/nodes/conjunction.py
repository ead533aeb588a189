r"""conjunction: the catalog's close approaches, re-screened as its estimates change.

Subscribes to ``/ssa/estimate_batch`` (ssa_fusion_msgs/EstimateBatch) for the estimates the
catalog_filter shards made from real measurements (update source SENSOR, every shard; a
DDS content filter keeps the forecasts away) and keeps each object's newest
(`core.conjunction.watch.ConjunctionWatch`). Every `rescreen_period` of sim time it screens
the objects whose estimates changed against every object it knows over the next `horizon`
(`core.conjunction.screening`: the estimates flown with `motion_model`, their covariances
carried to TCA by the state transition matrix) and publishes what it found on
``/ssa/conjunctions`` (ssa_fusion_msgs/ConjunctionBatch: the objects re-screened, and each of
their approaches closer than `distance`: TCA, miss, RTN relative state, both states and
covariances, the 2D Pc of Foster with `hard_body_radius`). With `cdm_dir` it writes a CCSDS
CDM (KVN) of every approach whose Pc is at least `cdm_min_pc` (`formats.ccsds.cdm_out`).

A re-screening runs in a thread of its own: the node keeps taking estimates and ends at a
signal meanwhile. In lockstep it reports on ``/lockstep`` the estimates it took
(`TAKEN_ALL_ESTIMATES`) and the sim time it last acted on (a re-screening's start until it is
published): the simulator's next step waits for its re-screenings.

    ros2 run ssa_fusion conjunction --ros-args -p use_sim_time:=true -p cdm_dir:=out/cdm
"""

from __future__ import annotations

import math
import threading
from pathlib import Path

import numpy as np

from ssa_fusion.core.base.types import Cause, MotionModel, UpdateSource
from ssa_fusion.core.conjunction.probability import collision_probability
from ssa_fusion.core.conjunction.screening import ScreeningConfig
from ssa_fusion.core.conjunction.watch import (
    ConjunctionWatch,
    Rescreening,
    WatchConfig,
    WatchUpdate,
)
from ssa_fusion.core.earth.timescales import iso
from ssa_fusion.core.measure.validation import states_problems
from ssa_fusion.formats.ccsds.cdm_out import Conjunction, write_cdm
from ssa_fusion.nodes.kit.base import SsaNode
from ssa_fusion.nodes.kit.diagnostics import Count, NodeCause
from ssa_fusion.nodes.kit.progress import TAKEN_ALL_ESTIMATES, ProgressReporter
from ssa_fusion.nodes.kit.shards import content_filter, sensor_estimates
from ssa_fusion.params.tables.conjunction import PARAMETERS
from ssa_fusion.params.units import Units, convert
from ssa_fusion.ros import messages
from ssa_fusion.ros.interfaces import ConjunctionBatch, EstimateBatch, Message
from ssa_fusion.ros.qos import CATALOG_QOS, CATALOG_WRITER_QOS
from ssa_fusion.ros.topics import TOPIC_CONJUNCTIONS, TOPIC_ESTIMATE_BATCH

FLOWN_WITH = {"kepler": MotionModel.TWO_BODY, "j2": MotionModel.J2}
"""What the estimates of each filter motion model are flown with (the integrated models)."""

TICK_S = 0.01
"""Wall s between two looks at the clock (in lockstep the simulator's next step waits for
the re-screening due at its clock)."""

APPROACHES = "approaches"
"""/diagnostics counter: approaches published."""
RESCREENINGS = "rescreenings"
"""/diagnostics counter: re-screenings done."""
CDMS = "cdms_written"
"""/diagnostics counter: CDMs written."""


class ConjunctionNode(SsaNode):
    """The conjunction node: SENSOR estimates in, a `ConjunctionWatch`, ConjunctionBatch out."""

    PARAMETERS = PARAMETERS

    def __init__(self) -> None:
        super().__init__()
        p = self.params
        core = convert(PARAMETERS, {"distance": p.number("distance"),
                                    "hard_body_radius": p.number("hard_body_radius")},
                       Units.CORE)
        self.config = WatchConfig(ScreeningConfig(distance_km=core["distance"]),
                                  horizon_s=p.number("horizon"),
                                  hbr_km=core["hard_body_radius"],
                                  model=FLOWN_WITH[p.text("motion_model")])
        self.watch = ConjunctionWatch(self.config)
        self.cdm_dir = Path(p.text("cdm_dir")) if p.text("cdm_dir") else None
        if self.cdm_dir is not None:
            self.cdm_dir.mkdir(parents=True, exist_ok=True)
        self.pub = self.advertise(ConjunctionBatch, TOPIC_CONJUNCTIONS, CATALOG_WRITER_QOS)
        cft = content_filter(0, 1, "update_source = %0", (str(UpdateSource.SENSOR.value),),
                             batches=True)
        self.sub = self.subscribe(EstimateBatch, TOPIC_ESTIMATE_BATCH, self.on_message,
                                  CATALOG_QOS, content_filter=cft)
        if not self.sub.is_cft_enabled:
            self.diag.count(NodeCause.CONTENT_FILTER_UNAVAILABLE,
                            "the DDS implementation does not filter by content: every "
                            "estimate arrives and the forecasts are ignored here")
        self.job: threading.Thread | None = None  # the re-screening running
        self.done: tuple[WatchUpdate, float] | None = None  # its result, not yet published
        self.cdms = 0  # CDMs written (by the re-screening's thread)
        self.taken = 0  # SENSOR estimate rows arrived (used or refused): lockstep progress
        self.next_s = -math.inf  # sim time of the next re-screening
        self.stepped_ns = 0  # the sim time (ns) acted on last: lockstep
        self.wakeup(TICK_S, self.tick)
        self.progress = ProgressReporter(self, lambda: {TAKEN_ALL_ESTIMATES: self.taken},
                                         clock=lambda: self.stepped_ns)
        self.diag.counts[CDMS] = 0
        self.reset_on_backward_jump(self.reset, "every estimate and approach forgotten")

    def reset(self) -> None:
        """Forget every estimate (a re-screening running is published when it ends)."""
        self.watch = ConjunctionWatch(self.config)
        self.next_s = -math.inf

    def on_message(self, msg: Message) -> None:
        """Take one EstimateBatch: SENSOR rows are each an object's newest estimate.

        Forecasts are ignored; a batch whose columns disagree is refused whole, and rows
        with a state or covariance the filter would refuse are counted by cause.
        """
        taken, rows = sensor_estimates(self.diag, msg)
        self.taken += taken
        if rows is None:
            return
        problems = states_problems(rows.x, rows.P)
        for k in np.flatnonzero(problems != ""):
            self.diag.count(Cause(problems[k]), f"object {rows.object_id[k]!r} at "
                            f"t={float(rows.t[k])}: its estimate is refused")
        low = self.watch.too_low(rows.x)
        for k in np.flatnonzero(np.isfinite(low) & (problems == "")):
            problems[k] = Cause.REJECTED_IMPLAUSIBLE
            self.diag.count(Cause.REJECTED_IMPLAUSIBLE,
                            f"object {rows.object_id[k]!r} at t={float(rows.t[k])}: its "
                            f"estimate's perigee is at {low[k]:.0f} km altitude (below "
                            f"{self.config.min_perigee_km:g} km: it re-enters within a "
                            "revolution); not screened until a later estimate")
        ok = np.flatnonzero((problems == "") & np.array([bool(o) for o in rows.object_id]))
        self.diag.counts[Count.RECEIVED] += ok.size
        self.watch.update([rows.object_id[k] for k in ok], rows.t[ok], rows.x[ok], rows.P[ok])

    def tick(self) -> bool:
        """Start the re-screening due at the clock; publish a finished one; report the clock.

        A re-screening starts only at the first look at a new clock, never later at the same
        one: in lockstep, what the node took before that clock was published, whatever the
        estimates of the next step that arrive meanwhile (the same re-screenings on any
        machine). It runs in a thread of its own (the node keeps taking estimates and
        answering signals meanwhile); the clock reported for lockstep stays at the epoch it
        started from until it is published. Return whether there is work (`SsaNode.wakeup`):
        a re-screening running, or a new clock.
        """
        now_ns = int(self.get_clock().now().nanoseconds)
        before = self.stepped_ns
        if self.job is not None:
            if self.job.is_alive():
                return True
            self.job = None
            if self.done is not None:
                update, at = self.done
                self.done = None
                self.publish(update, at)
        elif (now_ns and now_ns != before and now_ns * 1e-9 >= self.next_s
              and self.watch.pending):  # at a new clock only: what was taken before it
            now = now_ns * 1e-9
            self.next_s = now + self.params.number("rescreen_period")
            self.start(self.watch.snapshot(now), now)
            self.stepped_ns = now_ns
            return True
        self.stepped_ns = now_ns
        self.diag.status["objects"] = str(self.watch.objects)
        self.diag.status["pending"] = str(self.watch.pending)
        return self.stepped_ns != before

    def start(self, job: Rescreening, now: float) -> None:
        """Run `job` and its CDMs in a daemon thread (the process may end while it runs)."""
        def work() -> None:
            update = job.run()
            self.write_cdms(update)
            self.done = (update, now)

        self.job = threading.Thread(target=self.diag.guard(work), name="rescreening",
                                    daemon=True)
        self.job.start()

    def publish(self, update: WatchUpdate, now: float) -> None:
        """Publish a re-screening."""
        self.pub.publish(messages.conjunction_batch_to_msg(update, now))
        self.diag.counts[RESCREENINGS] += 1
        self.diag.counts[APPROACHES] += len(update.approaches)
        self.diag.counts[CDMS] = self.cdms

    def write_cdms(self, update: WatchUpdate) -> None:
        """Write a CDM of every approach of `update` whose Pc is at least ``cdm_min_pc``.

        Nothing without ``cdm_dir``.
        """
        a = update.approaches
        floor = self.params.number("cdm_min_pc")
        if a.p1 is None or a.p2 is None or self.cdm_dir is None:
            return
        for k in np.flatnonzero(update.log10_pc >= (math.log10(floor) if floor > 0 else -np.inf)):
            ids = (a.object_ids[int(a.primary[k])], a.object_ids[int(a.secondary[k])])
            result = collision_probability(a.x1[k], a.p1[k], a.x2[k], a.p2[k], update.hbr_km)
            stamp = iso(float(a.tca[k])).replace(":", "").replace("-", "")
            message_id = f"{ids[0]}_conj_{ids[1]}_{stamp}"
            write_cdm(Conjunction(float(a.tca[k]), a.x1[k], a.x2[k], a.p1[k], a.p2[k],
                                  update.hbr_km, result, ids, message_id=message_id),
                      self.cdm_dir / f"{message_id}.cdm")
            self.cdms += 1


def main(args: list[str] | None = None) -> int:
    """Run the conjunction node (``ros2 run ssa_fusion conjunction``)."""
    return ConjunctionNode.main(args)


if __name__ == "__main__":
    raise SystemExit(main())

"""`visual.mcap` of a bag: the Foxglove visual topics the `foxglove_bridge` would serve.

The topics the `foxglove_bridge` node would have served for the bag, written with
foxglove-sdk's MCAP writer, so that opening the file in Foxglove with
``config/foxglove_layout.json`` shows the scene, the ground tracks and the plots.

The bag itself is rosbag2 (CDR messages of ``ssa_fusion_msgs``), which Foxglove cannot draw
as a scene; this file holds, in Foxglove's own schemas:

* ``/ssa/foxglove/scene`` (`foxglove.SceneUpdate`): the Earth, true and estimated positions
  with their trails, the estimate's 3σ ellipsoid, the run's stations, forecast and
  measurement points, GCRF, one scene unit = 1 km; one update per `scene_period_s` of sim time
  (the bridge sends one per wall-clock period instead);
* ``/ssa/foxglove/ground_track`` / ``/ssa/foxglove/ground_track_truth``
  (`foxglove.LocationFix`): one per estimate / truth state, WGS-84 latitude and longitude in
  deg, height in m;
* ``/ssa/foxglove/metrics`` (JSON): one per estimate, its position error against the truth
  of the same epoch and its σ, km.

Every message is logged at its sim-time stamp (Unix ns). The messages are built by the same
`ssa_fusion.ros.foxglove_scene.VisualTopics` as the live bridge's.
"""

from __future__ import annotations

from collections import Counter
from pathlib import Path
from typing import Any

from ssa_fusion.apps import evaluate
from ssa_fusion.core.base.types import Source
from ssa_fusion.core.earth.frames import Station
from ssa_fusion.ros import foxglove_scene as scene

SCENE_PERIOD_S = 300.0
"""Sim seconds between scene updates in the file (58 h of sim time: ~700 updates)."""

# what is handled first at one epoch: measurements and forecasts, then the truth, then the
# estimates (scored against the truth of their epoch, as the bridge scores them when the
# truth came first)
_MEASUREMENT, _TRUTH, _ESTIMATE = 0, 1, 2


def _events(data: evaluate.BagData) -> list[tuple[float, int, int, Any]]:
    """Return the bag's truth states, estimates, measurements and forecasts in epoch order.

    Each as (t Unix s, what, index in its list, the item).
    """
    ev: list[tuple[float, int, int, Any]] = []
    for i, m in enumerate([*data.measurements, *data.forecasts]):
        ev.append((m.t, _MEASUREMENT, i, m))
    ev += [(e.t, _TRUTH, i, e) for i, e in enumerate(data.truth)]
    ev += [(e.t, _ESTIMATE, i, e) for i, e in enumerate(data.estimates)]
    ev.sort(key=lambda e: (e[0], e[1], e[2]))
    return ev


def write(data: evaluate.BagData, path: Path, stations: dict[str, Station],
          scene_period_s: float = SCENE_PERIOD_S) -> dict[str, int]:
    """Write the visual topics of `data` to the MCAP file `path`; return counts per topic.

    `data` is a bag read by `evaluate.load`; `path` is replaced if it exists; `stations`
    (id -> site) are drawn in the scene and used to place range/az/el measurements.
    """
    import foxglove
    from foxglove.channels import LocationFixChannel, SceneUpdateChannel

    ctx = foxglove.Context()  # its own context: nothing goes to a live server or other file
    channels: dict[str, Any] = {
        scene.SCENE_TOPIC: SceneUpdateChannel(scene.SCENE_TOPIC, context=ctx),
        scene.TRACK_TOPIC: LocationFixChannel(scene.TRACK_TOPIC, context=ctx),
        scene.TRUTH_TRACK_TOPIC: LocationFixChannel(scene.TRUTH_TRACK_TOPIC, context=ctx),
        scene.METRICS_TOPIC: foxglove.Channel(scene.METRICS_TOPIC, schema=scene.METRICS_SCHEMA,
                                              context=ctx),
    }
    counts: Counter[str] = Counter()
    visual = scene.VisualTopics(stations)

    def log(items: list[scene.Logged]) -> None:
        for item in items:
            channels[item.topic].log(item.message, log_time=item.log_time)
            counts[item.topic] += 1

    next_scene = float("-inf")
    path.parent.mkdir(parents=True, exist_ok=True)
    with foxglove.open_mcap(path, allow_overwrite=True, context=ctx):
        for t, what, _, item in _events(data):
            if visual.scene_due and t >= next_scene:  # the scene as it was before this epoch
                log([visual.scene()])
                next_scene = (visual.state.t or t) + scene_period_s
            try:
                if what == _MEASUREMENT:
                    visual.measurement(item.kind, item.z, item.frame_id, item.t,
                                       item.source == Source.FORECAST)
                elif what == _TRUTH:
                    log(visual.truth(item.t, item.x))
                else:
                    log(visual.estimate(item.t, item.x, item.P, item.update_source, item.nis))
            except scene.NotShownError:
                counts["not shown"] += 1
        if visual.scene_due:
            log([visual.scene()])
    return dict(counts)

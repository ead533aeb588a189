"""`ssa-fusion replay LASERBAG` over ROS 2: the bag's ranges through a live laser filter node.

As `replay.replay_live` does for other bags, without the surrogate (it does not forecast
laser ranges): a recorder and a filter process, the filter set for laser ranges by its
parameters (`filter_params`: ``kind`` laser_range, ``laser`` the bag's ``import crd``
set-up, ``apriori`` the reference orbit's first state, what it publishes between passes,
`laser_run.GAPS`), then the bag's ranges, meteorological records and reference orbit played
with a ``/clock`` from their stamps (``--rate``), the set-up published latched on
``/ssa/config`` for the recording. The recording holds what the node published
(``/ssa/estimate``: its orbit and covariance, the NIS of each range) beside the played topics:
`ssa-fusion report` reads it as it reads the offline replay's.
"""

from __future__ import annotations

import argparse
import sys
import time
from typing import Any

from ssa_fusion.apps import laser_run
from ssa_fusion.apps.replay import PLAYED, sibling
from ssa_fusion.core.gaps.estimator import EstimatorConfig
from ssa_fusion.ros import bagio
from ssa_fusion.ros.laser_bag import LaserBag
from ssa_fusion.ros.laser_config import NODE
from ssa_fusion.ros.topics import (
    TOPIC_CLOCK,
    TOPIC_CONFIG,
    TOPIC_ESTIMATE,
    TOPIC_MEASUREMENT,
    TOPIC_METEO,
    TOPIC_REFERENCE,
)

__all__ = ["filter_params", "run"]

M = 1000.0
"""m per km."""


def filter_params(bag: LaserBag, setup: str) -> dict[str, Any]:
    """Return the filter node's parameters for the bag (module docstring; SI)."""
    e = laser_run.apriori(bag)
    return {"use_sim_time": True, "kind": "laser_range", "object_id": bag.object_id,
            "laser": setup, "apriori": [e.t, *(float(v) * M for v in e.x[:6])],
            **laser_run.GAPS}


def _setup(stream: list[bagio.BagMessage]) -> str:
    """Return the bag's ``import crd`` /ssa/config text (the last one)."""
    texts = [str(m.msg.data) for m in stream
             if m.topic == TOPIC_CONFIG and f'"{NODE}"' in str(m.msg.data)]
    return texts[-1]


def run(args: argparse.Namespace, stream: list[bagio.BagMessage], bag: LaserBag,
        c: EstimatorConfig) -> int:
    """Play the laser bag into recorder + filter processes and record the run."""
    from ssa_fusion.ros.player import Player
    from ssa_fusion.ros.processes import Graph, ended_badly, recorded_short
    from ssa_fusion.ros.readiness import OUTPUT, ReadyNodes, readers_of

    record = args.record or sibling(args.bag, "_replay")
    if record.exists():
        print(f"error: {record} exists already; choose another --record", file=sys.stderr)
        return 2
    setup = _setup(stream)
    params = {"recorder": {"use_sim_time": True, "bag": str(record)},
              "filter": filter_params(bag, setup)}
    logs = record.with_name(record.name + "_logs")
    try:
        # no run of its own (`runs.replay_graph`): a node of a run spins rclpy's
        # SingleThreadedExecutor, and the laser filter's updates then differ from the
        # offline replay's
        graph = Graph(logs, args.domain_id)
    except OSError as exc:
        print(f"error: cannot use {record}: {exc}", file=sys.stderr)
        return 2
    print(f"replay: {args.bag} at rate {args.rate:g} into the laser filter "
          f"({c.filter.motion.motion_model}); ROS domain {graph.domain_id}; logs in {logs}",
          flush=True)
    t0 = time.monotonic()
    played = [m for m in stream if m.topic in (*PLAYED, TOPIC_METEO, TOPIC_REFERENCE)]
    try:
        for n in ("recorder", "filter"):  # the recorder first: it hears all
            graph.start_node(n, params=params[n])
        _publish_setup(graph.probe, setup)
        player = Player(graph.probe, played, args.rate)
        from ssa_fusion.ros.interfaces import StateEstimate

        seen = graph.collect(StateEstimate, TOPIC_ESTIMATE)
        graph.wait_for(player.subscribers_ready({TOPIC_MEASUREMENT: 2, TOPIC_METEO: 2}),
                       30.0, "filter and recorder to subscribe")
        graph.wait_for_subscriber(TOPIC_ESTIMATE, 2, timeout=30.0)
        published = {*player.pubs, TOPIC_CLOCK, TOPIC_ESTIMATE}
        needs = [*(r for r in readers_of(published) if not r.startswith("surrogate:")),
                 f"filter:{TOPIC_METEO}", f"filter:{OUTPUT}{TOPIC_ESTIMATE}=2"]
        readers = ReadyNodes(graph.probe, graph.subscribe)
        graph.play(player, lambda: readers.ready(needs),
                   "filter and recorder to match their publishers")
        graph.wait_quiet(lambda: len(seen), quiet_s=1.0, limit_s=60.0)
    finally:
        problems = graph.close()  # each stopped in turn, newest first
    if ended_badly(problems) or recorded_short(record, {TOPIC_ESTIMATE: len(seen)}):
        return 1
    print(f"replayed {player.published} messages of {args.bag} at rate {args.rate:g} in "
          f"{time.monotonic() - t0:.1f} s; recorded to {record}")
    return 0


def _publish_setup(node: Any, text: str) -> None:  # noqa: ANN401 (an rclpy node)
    """Publish the ``import crd`` set-up on /ssa/config, latched, from ``node``."""
    from ssa_fusion.ros.interfaces import String
    from ssa_fusion.ros.qos import CONFIG_QOS

    node.create_publisher(String, TOPIC_CONFIG, CONFIG_QOS).publish(String(data=text))

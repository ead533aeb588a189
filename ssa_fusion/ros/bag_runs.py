"""Which runs a bag holds: one, or a mix that no report or replay may score as one run.

A run's recorder takes its run's messages only and names the run once, on ``/ssa/run``
(`ros.run_identity`), so its bag holds one run. A bag can still hold two: two bags merged,
a recorder of an earlier version (or ``ros2 bag record``) in a ROS domain two runs shared.
`check_one_run` refuses such a bag in one line: it names two runs on ``/ssa/run``, its
``/clock`` goes back in time again and again (two simulators' clocks interleaved; one run's
clock never goes back, a looping playback's once a loop), or its ``/ssa/truth`` repeats
an object's epochs while new ones still come (two recordings of runs in lockstep, whose log
times are sim times: their clocks interleave without going back; one run's truth has each
epoch once, a looping playback's repeats only after its loop ended). `same_messages` says
whether two bags hold the same run's messages (a run in lockstep, repeated: the same bag on any
machine).
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

from ssa_fusion.ros import bagio, messages
from ssa_fusion.ros.topics import TOPIC_CLOCK, TOPIC_RUN, TOPIC_TRUTH

STATE_ESTIMATE = "ssa_fusion_msgs/msg/StateEstimate"
"""The type of one object's /ssa/truth (a catalog's truth goes in batches)."""
CLOCK_BACKS = 10
"""A bag whose /clock goes back more often than this (or whose /ssa/truth brings more new
epochs than this after repeating one) holds more than one run."""


class MixedBagError(ValueError):
    """The bag holds more than one run (the message says how it shows, in one line)."""


@dataclass(frozen=True)
class BagRuns:
    """What a bag says of its runs.

    The ids on /ssa/run, how often /clock went back, and how many new (object, epoch) pairs
    /ssa/truth brought after it had repeated one.
    """

    runs: tuple[str, ...]
    clock_backs: int
    truth_interleaved: int = 0


def runs_in(path: Path | str) -> BagRuns:
    """Return what bag `path` says of its runs (`BagRuns`).

    The runs it names, how often its /clock goes back (log-time order) and how many new
    object epochs its /ssa/truth brought after a repeated one.
    """
    ids: list[str] = []
    backs, last = 0, -1.0
    truths: set[tuple[str, int]] = set()
    repeated, interleaved = False, 0
    for m in bagio.read_bag(path, topics=[TOPIC_RUN, TOPIC_CLOCK, TOPIC_TRUTH]):
        if m.topic == TOPIC_TRUTH:
            if m.msgtype != STATE_ESTIMATE:  # a catalog's truth rows: its clock tells
                continue
            key = (m.msg.object_id, m.msg.header.stamp.sec * 10**9 + m.msg.header.stamp.nanosec)
            if key in truths:
                repeated = True
            else:
                interleaved += repeated
                truths.add(key)
            continue
        if m.topic == TOPIC_RUN:
            try:
                run = json.loads(m.msg.data).get("run")
            except (ValueError, AttributeError):
                run = None
            if isinstance(run, str) and run not in ids:
                ids.append(run)
            continue
        t = messages.stamp_to_seconds(m.msg.clock)
        backs += t < last
        last = t
    return BagRuns(tuple(ids), backs, interleaved)


def check_one_run(path: Path | str) -> None:
    """Raise `MixedBagError` (one line) when bag `path` holds more than one run."""
    found = runs_in(path)
    if len(found.runs) > 1:
        raise MixedBagError(f"{path} holds {len(found.runs)} runs ({', '.join(found.runs[:3])}) "
                            "on /ssa/run: a report or replay scores one run; record each "
                            "run in a bag of its own")
    if found.clock_backs > CLOCK_BACKS:
        raise MixedBagError(f"{path}: its /clock goes back {found.clock_backs} times: the "
                            "clocks of two runs interleaved (two runs recorded into one bag); "
                            "a report or replay scores one run")
    if found.truth_interleaved > CLOCK_BACKS:
        raise MixedBagError(f"{path}: its /ssa/truth repeats an object's epochs while "
                            f"{found.truth_interleaved} new ones still come: two runs "
                            "recorded into one bag; a report or replay scores one run")


def same_messages(a: Path | str, b: Path | str) -> bool:
    """Return whether bags `a` and `b` hold the same /ssa/* messages, /ssa/run left out.

    Topic, log time and content, in log-time order (messages at one log time in any order).
    The content is compared as CDR re-serialized by `rosbags` (zero padding): publishers
    leave the alignment padding after a string unset, so raw bytes differ from run to run
    where nothing does. /ssa/run says which run it is: every run its own.
    """
    from rosbags.rosbag2 import Reader

    store = bagio.typestore()

    def load(bag: Path | str) -> list[tuple[str, int, bytes]]:
        with Reader(Path(bag)) as r:
            return sorted((c.topic, t, bytes(store.serialize_cdr(
                store.deserialize_cdr(d, c.msgtype), c.msgtype)))
                for c, t, d in r.messages()
                if c.topic.startswith("/ssa/") and c.topic != TOPIC_RUN)

    return load(a) == load(b)

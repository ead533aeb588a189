"""Ground stations by id, and the clock their measurements are stamped on.

A range/azimuth/elevation measurement names its station in ``frame_id``; `STATIONS` maps
those ids to `frames.Station` (the nodes' ``station`` parameter takes its keys). Live and
recorded measurements are stamped in Unix seconds (UTC; ROS time under sim time too), so a
station's `measurement.RazelModel` has its reference epoch at `UNIX_EPOCH_JD`.
"""

from __future__ import annotations

from .frames import COLUMBUS, Station

UNIX_EPOCH_JD = 2440587.5
"""Julian date of 1970-01-01T00:00:00 UTC; jd = UNIX_EPOCH_JD + t_unix / 86400."""

STATIONS: dict[str, Station] = {"columbus": COLUMBUS}
"""Known stations by id (the ``frame_id`` of their measurements)."""


"""Rows and rules several nodes' tables share.

The measurement stream, a filter's settings, the clock lead, the object filter, and a
catalog node's shards. Each builder takes the node's defaults (`defaults`) and returns the
rows; docs/NODES.md's prose says more of each than its one-line description.
"""

from __future__ import annotations

from ssa_fusion.core.base.types import KIND_NAMES
from ssa_fusion.params.checks import (
    NON_NEGATIVE,
    POSITIVE,
    SITES,
    STATION_IDS,
    Values,
    at_least,
    integer_in,
    non_negative_numbers,
    one_of,
    sites_problem,
)
from ssa_fusion.params.defaults import KM, CatalogFilterDefaults, FilterDefaults
from ssa_fusion.params.rows import Param, Rule


def clock_lead(default: float) -> Param:
    """Return the row of ``max_clock_lead`` (s), which every node judging stamps has."""
    return Param("max_clock_lead", default,
                 "a measurement stamped further ahead of the node's clock is refused "
                 "(`rejected_future`): a wall-time stamp in a sim-time graph",
                 unit="s", check=POSITIVE, runtime=True)


def lockstep_row(default: bool, what: str) -> Param:
    """Return the row of ``lockstep``: `what` the node does only when the simulator says."""
    return Param("lockstep", default,
                 f"{what} only up to the time sensor_sim releases (`/lockstep/...`, naming it "
                 "in `lockstep`); false in any other graph (a replay, real sensors)")


def object_filter(default: str, what: str) -> Param:
    """Return the row of ``object_id``: the node `what`s only this object ('' = any)."""
    return Param("object_id", default, f"{what} only this object; `\"\"` = any")


KINDS = {name: kind for kind, name in KIND_NAMES.items()}
"""The `kind` parameter's values: measurement kind by name."""


def measurement_stream(kind: str, station: str, sites: str, verb: str,
                       kinds: tuple[str, ...] = tuple(KINDS)) -> tuple[Param, Param, Param]:
    """Return the rows of ``kind``, ``station`` and ``sites``: the measurements a node `verb`s.

    The station is the frame_id of range/az/el and ra/dec measurements ("gcrf" for
    positions, whatever the parameter says); it names built-in stations or those of the
    sites file ``sites`` (the rule `STATION_RULE` checks which).
    """
    return (Param("kind", kind, f"measurement kind it {verb} (sets the measurement model)",
                  check=one_of(*kinds)),
            Param("station", station,
                  "station (frame_id) of range/az/el or ra/dec measurements, or a network "
                  "of them, each measured with its station's model; ignored for position "
                  "(frame `gcrf`)", check=STATION_IDS),
            sites_row(sites))


def sites_row(default: str) -> Param:
    """Return the row of ``sites``: a sites file whose ids ``station`` may name too."""
    return Param("sites", default,
                 "sites file (YAML, docs/SITES.md) whose stations `station` may name besides "
                 "the built-in ones; `\"\"` = built-in stations only", unit="path", check=SITES)


STATION_RULE = Rule(("station", "sites"), sites_problem)
"""``station`` names stations built in or of ``sites`` (every table with a ``station``)."""

P0_SIGMA = non_negative_numbers(6, "needs 6 standard deviations, each a finite number >= 0")
"""The check of ``p0_sigma``: 3 position and 3 velocity standard deviations."""
MAX_IOD_SAMPLES = 1000
"""Most measurements one IOD batch may take (a pass of 10 s samples has at most ~100)."""
MOTION_MODELS = one_of("kepler", "j2")
"""The motion models a filter node offers (Earth orbits on the Unix clock)."""


def filter_rows(d: FilterDefaults | CatalogFilterDefaults, runtime: bool,
                unlimited_span: bool) -> tuple[Param, ...]:
    """Return the rows of a filter's settings (the object filter's and the catalog's).

    Defaults `d`; `runtime`: the tuning rows (all but ``motion_model``) can be set at run
    time; `unlimited_span`: ``iod_max_span`` 0 means no limit (else it must be > 0).
    ``p0_sigma`` and ``q`` scale to the core's km (`units.convert`).
    """
    span = "longest span of one IOD batch (one pass of one station)"
    return (
        Param("motion_model", d.motion_model,
              "the EKF's motion model: `kepler` (analytic two-body) or `j2` (two-body + J2, "
              "integrated with its state transition matrix)", check=MOTION_MODELS),
        Param("p0_sigma", d.p0_sigma,
              "standard deviations added (in quadrature) to the IOD covariance (take effect "
              "at the next IOD)", unit="3 × m, 3 × m/s", check=P0_SIGMA, runtime=runtime,
              scale=KM),
        Param("q", d.q, "process noise: white-noise acceleration spectral density",
              unit="m²/s³", check=NON_NEGATIVE, runtime=runtime, scale=KM * KM),
        Param("gate", d.gate, "normalized innovation squared beyond which an update is "
              "rejected; 0 = no gate", unit="NIS", check=NON_NEGATIVE, runtime=runtime),
        Param("iod_samples", d.iod_samples,
              "real measurements used by the initial orbit determination",
              check=integer_in(3, MAX_IOD_SAMPLES), runtime=runtime),
        Param("iod_max_span", d.iod_max_span, span + ("; 0 = no limit" if unlimited_span
                                                       else ""),
              unit="s", check=NON_NEGATIVE if unlimited_span else POSITIVE, runtime=runtime),
        Param("reinit_after", d.reinit_after,
              "real measurements of an object refused by the gate in a row after which the "
              "filter forgets its state and initialises again; 0 = never",
              unit="measurements", check=at_least(0), runtime=runtime),
        Param("sigma_bound", d.sigma_bound,
              "after each prediction, every position (velocity) standard deviation is at most "
              "`sigma_bound` × the position's (velocity's) norm; 0 = no limit",
              check=NON_NEGATIVE, runtime=runtime),
    )


def shard_rows(shards: int, shard: int) -> tuple[Param, Param]:
    """Return the rows of ``shards`` and ``shard`` (their defaults given); see `SHARD_RULE`."""
    return (Param("shards", shards, "number of shards", check=at_least(1)),
            Param("shard", shard, "this node's shard, 0..shards−1 (checked against `shards` "
                  "at start and on set)", check=at_least(0)))


def max_objects_row(default: int, holds: str, what: str) -> Param:
    """Return the ``max_objects`` row of a catalog node's parameters.

    The most objects the shard `holds` (a phrase: "tracks (~2 kB each)"); `what` of one
    more is refused.
    """
    return Param("max_objects", default,
                 f"the most objects the shard {holds}; {what} of one more is refused "
                 "(`rejected_bank_full`)", check=at_least(1))


def _shard_in_range(v: Values) -> str | None:
    shard, shards = v["shard"], v["shards"]
    assert isinstance(shard, int) and isinstance(shards, int)
    return None if shard < shards else f"must be < shards ({shards})"


SHARD_RULE = Rule(("shard", "shards"), _shard_in_range)
"""``shard`` must be below ``shards``."""

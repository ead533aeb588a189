"""The filter set-up your own data calls for: from its measurement kinds and its stations.

A bag without recorded settings (a TDM imported with `import tdm`, a bag written by another
tool) is estimated with the set-up its sensor measurements call for, said in one line and
overridable (``--filter NAME``, or ``--params-file``/``--scenario``):

* ``radar``: the range/azimuth/elevation of its radars;
* ``optical``: the right ascension/declination of its telescopes;
* ``network``: both, every station its own kind;
* ``position``: GCRF positions (the paper's position filter, scenario iss_j2_pos).

Data of the paper's radar alone (columbus) get the paper's filter (scenario iss_j2_rae), so
that a TDM of a run of it replays to the run's estimates; other radar, optical and network
data run the real sky's filter (`estimator.station_estimator`:
two-body + J2, initial orbit from one pass, light time) over the stations the data name that
are known (built in, or in the sites file ``--sites``); the others are said and left out.
"""

from __future__ import annotations

import enum
from collections import Counter
from collections.abc import Iterable, Mapping
from dataclasses import dataclass

from ssa_fusion.core.base.types import Kind, Measurement, Source
from ssa_fusion.core.earth.frames import Station
from ssa_fusion.core.earth.stations import find_station
from ssa_fusion.core.gaps import estimator as config
from ssa_fusion.core.gaps.estimator import EstimatorConfig
from ssa_fusion.sim import scenarios


class FilterSetup(enum.StrEnum):
    """A filter set-up for data of one's own (``--filter``)."""

    RADAR = "radar"
    OPTICAL = "optical"
    NETWORK = "network"
    POSITION = "position"


TAKES: dict[FilterSetup, tuple[Kind, ...]] = {
    FilterSetup.RADAR: (Kind.RANGE_AZ_EL,),
    FilterSetup.OPTICAL: (Kind.RA_DEC,),
    FilterSetup.NETWORK: (Kind.RANGE_AZ_EL, Kind.RA_DEC),
    FilterSetup.POSITION: (Kind.POSITION,),
}
"""The measurement kinds each set-up takes."""
WORDS = {Kind.POSITION: "position", Kind.RANGE_AZ_EL: "range/az/el", Kind.RA_DEC: "ra/dec",
         Kind.LASER_RANGE: "laser range"}
"""A measurement kind as the lines say it."""
POSITION_SCENARIO = "iss_j2_pos"
"""Whose filter takes GCRF positions."""


@dataclass(frozen=True)
class DataMix:
    """What a bag's sensor measurements are: how many of each kind from each station."""

    counts: Mapping[tuple[str, Kind], int]
    """Measurements by (station id, or the frame of positions; kind)."""

    @classmethod
    def of(cls, measurements: Iterable[Measurement]) -> DataMix:
        """Count the SENSOR measurements of `measurements` (forecasts are not data)."""
        return cls(Counter((m.frame_id, Kind(m.kind)) for m in measurements
                           if m.source == Source.SENSOR))

    def kinds(self) -> set[Kind]:
        """Return the measurement kinds present."""
        return {k for _, k in self.counts}

    def stations(self, kinds: Iterable[Kind]) -> list[str]:
        """Return the station ids of measurements of `kinds`, sorted."""
        wanted = set(kinds)
        return sorted({s for s, k in self.counts if k in wanted})

    def said(self) -> str:
        """Return the mix as words: "812 ra/dec from pampa-obs, 40 range/az/el from nordlys"."""
        by_kind: dict[Kind, Counter[str]] = {}
        for (station, kind), n in self.counts.items():
            by_kind.setdefault(kind, Counter())[station] += n
        return ", ".join(f"{sum(c.values())} {WORDS[k]} from {', '.join(sorted(c))}"
                         for k, c in sorted(by_kind.items())) or "no sensor measurement"


def data_setup(mix: DataMix) -> FilterSetup:
    """Return the set-up `mix` calls for (ValueError for data no set-up takes)."""
    kinds = mix.kinds()
    for setup in (FilterSetup.POSITION, FilterSetup.RADAR, FilterSetup.OPTICAL,
                  FilterSetup.NETWORK):
        if kinds and kinds <= set(TAKES[setup]):
            return setup
    raise ValueError(f"no filter set-up takes {mix.said()} (one takes position, or "
                     f"range/az/el and ra/dec)")


def chosen_estimator(mix: DataMix, setup: FilterSetup | None,
                     sites: tuple[Station, ...] = ()) -> tuple[EstimatorConfig, str]:
    """Return the estimator for `mix` under `setup` (None: the data's own) and why, in words.

    ValueError (one line, with the fix) when the set-up takes none of the data, or none of
    its stations is known (built in, or among `sites`).
    """
    asked = setup is not None
    setup = data_setup(mix) if setup is None else setup
    how = (f"--filter {setup}" if asked else
           f"{setup}, from the data ({mix.said()}; --filter "
           f"{'|'.join(FilterSetup)} or --params-file choose another)")
    kinds = TAKES[setup]
    if not mix.kinds() & set(kinds):
        raise ValueError(f"--filter {setup} takes {' and '.join(WORDS[k] for k in kinds)}; "
                         f"the bag has {mix.said()}: choose --filter {data_setup(mix)}")
    if setup == FilterSetup.POSITION:
        return scenarios.get(POSITION_SCENARIO).estimator(), \
            f"{how}: the paper's position filter (scenario {POSITION_SCENARIO})"
    ids = mix.stations(kinds)
    paper = scenarios.settings_for("", kinds[0])
    if len(kinds) == 1 and paper.kind == kinds[0] and ids == [paper.station]:
        return paper.estimator(), (f"{how}: the paper's filter of its station {paper.station} "
                                   f"(scenario {paper.name})")
    own = {s.name: s for s in sites}
    known = [i for i in ids if find_station(i, own) is not None]
    unknown = [i for i in ids if i not in known]
    if not known:
        raise ValueError(f"station id(s) {', '.join(unknown)} are neither built in nor in a "
                         f"sites file: define them in one (docs/SITES.md) and give it with "
                         f"--sites")
    network = len(known) > 1 or len({k for s, k in mix.counts if s in known}) > 1
    station = ",".join(known) + "," if network else known[0]
    c = config.station_estimator(kinds[0] if len(kinds) == 1 else _first_kind(mix, known),
                                 station, sites)
    left = (f"; station(s) {', '.join(unknown)} left out: neither built in nor in --sites"
            if unknown else "")
    return c, (f"{how}: the real-sky filter for the stations of its measurements "
               f"({', '.join(known)}){left}")


def _first_kind(mix: DataMix, stations: list[str]) -> Kind:
    """Return the kind of the most measurements of `stations` (a network's `kind` setting)."""
    counts: Counter[Kind] = Counter()
    for (station, kind), n in mix.counts.items():
        if station in stations:
            counts[kind] += n
    return counts.most_common(1)[0][0]

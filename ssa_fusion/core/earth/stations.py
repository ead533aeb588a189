"""Ground stations and their sensors by id, station networks, and the clock of measurements.

A station's measurement names it in ``frame_id``: range/azimuth/elevation from a radar,
topocentric right ascension/declination from an optical telescope. `STATIONS` maps station
ids to their sites (`frames.Station`; the nodes' ``station`` parameter takes these keys, or a
`NETWORKS` key); `SENSORS` maps sensor presets to what the sensor there measures, how well,
above which elevation and how often during a pass. Stations of one's own come from a sites
file (`site_file`) and are resolved beside these (`network_stations`' ``sites``). Live and
recorded measurements are stamped in Unix seconds (UTC; ROS time under sim time too), so a
station's measurement model has its reference epoch at `timescales.UNIX_EPOCH_JD`.

Sites of the network are real, publicly documented tracking sites; coordinates are rounded
to about 0.01 deg (~1 km) from the public descriptions cited with each, which is more than
enough for simulation (no claim is made that they are survey-grade). Noise levels are
reference values, not the sites' specifications: a tracking radar 20 m in range and
0.02 deg in angle (the values of Orekit's orbit-determination tutorial), an optical
telescope 1.5 arcsec.
"""

from __future__ import annotations

import enum
import math
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from ssa_fusion.core.base.constants import ARCSEC
from ssa_fusion.core.base.types import Kind
from ssa_fusion.core.earth.frames import COLUMBUS, Station
from ssa_fusion.core.earth.visibility import ASTRONOMICAL_DARK

DARK_BELOW_DEG = math.degrees(ASTRONOMICAL_DARK)
"""Default Sun elevation (deg) below which an optical site observes."""


class SensorType(enum.StrEnum):
    """What a station's sensor measures."""

    RADAR = "radar"
    """Range, azimuth, elevation (`Kind.RANGE_AZ_EL`), day and night."""
    OPTICAL = "optical"
    """Topocentric right ascension and declination (`Kind.RA_DEC`), only while the station is
    dark (sun below -12 deg) and the object sunlit."""


@dataclass(frozen=True)
class Sensor:
    """A sensor at a ground station.

    Attributes
    ----------
    station : Station
        The site; its ``name`` is the ``frame_id`` of the measurements.
    type : SensorType
        Radar or optical.
    sigma : tuple of float
        Noise standard deviation per channel: (km, rad, rad) for a radar, (rad, rad) for an
        optical sensor.
    min_elevation_deg : float
        Elevation mask, deg: the sensor measures only above it.
    mask_by_azimuth_deg : tuple of (float, float)
        Optional mask by azimuth: (azimuth deg, minimum elevation deg) points, interpolated
        linearly and periodically in azimuth; where given, the larger of it and
        `min_elevation_deg` applies.
    cadence_s : float
        Seconds between measurements during a pass.
    bias : tuple of float
        Constant bias added to every measurement, same units as `sigma` (empty: none).
    source : str
        Where the site's coordinates come from.
    max_range_km : float
        Farthest range a radar measures, km (inf: no limit; a sites file's
        ``max_range_km``).
    limiting_magnitude : float
        Faintest visual magnitude an optical sensor measures (inf: no limit; a sites file's
        ``limiting_magnitude``; `visibility.apparent_magnitude`).
    dark_below_deg : float
        Sun elevation below which an optical site observes, deg (nautical twilight's end,
        -12, by default; a sites file's ``dark_below_deg``).
    """

    station: Station
    type: SensorType
    sigma: tuple[float, ...]
    min_elevation_deg: float = 10.0
    mask_by_azimuth_deg: tuple[tuple[float, float], ...] = ()
    cadence_s: float = 10.0
    bias: tuple[float, ...] = ()
    source: str = ""
    max_range_km: float = math.inf
    limiting_magnitude: float = math.inf
    dark_below_deg: float = DARK_BELOW_DEG

    def __post_init__(self) -> None:
        """Check the channel count of `sigma` and `bias` against the type (ValueError)."""
        m = len(self.sigma)
        if m != (3 if self.type == SensorType.RADAR else 2):
            raise ValueError(f"{self.type} sensor needs {3 if m == 2 else 2} sigmas, got {m}")
        if self.bias and len(self.bias) != m:
            raise ValueError(f"bias needs {m} values, got {len(self.bias)}")

    @property
    def kind(self) -> Kind:
        """The measurement kind: RANGE_AZ_EL (radar) or RA_DEC (optical)."""
        return Kind.RANGE_AZ_EL if self.type == SensorType.RADAR else Kind.RA_DEC

    @property
    def R(self) -> NDArray[np.float64]:
        """Noise covariance (m, m) in the units of the measurement squared."""
        return np.diag(np.asarray(self.sigma, dtype=float) ** 2)

    def min_elevation(self, az_rad: NDArray[np.float64]) -> NDArray[np.float64]:
        """Return the elevation mask (rad) at azimuths `az_rad` (rad, any shape)."""
        floor = np.full(np.shape(az_rad), math.radians(self.min_elevation_deg))
        if not self.mask_by_azimuth_deg:
            return floor
        table = np.radians(np.array(sorted(self.mask_by_azimuth_deg), dtype=float))
        by_az = np.interp(np.mod(az_rad, 2 * math.pi), table[:, 0], table[:, 1],
                          period=2 * math.pi)
        out: NDArray[np.float64] = np.maximum(floor, by_az)
        return out

    def in_view(self, rae: NDArray[np.float64]) -> NDArray[np.bool_]:
        """Return where the sensor sees topocentric range/azimuth/elevation `rae`.

        `rae`: (..., 3), km, rad, rad. In view: above the mask and, for a radar, within
        ``max_range_km`` (NaN: not in view).
        """
        with np.errstate(invalid="ignore"):
            up = rae[..., 2] >= self.min_elevation(rae[..., 1])
            if self.type == SensorType.RADAR:
                up &= rae[..., 0] <= self.max_range_km
        return np.asarray(up, dtype=bool)


def _site(name: str, lat_deg: float, lon_deg: float, alt_km: float) -> Station:
    return Station(name, math.radians(lat_deg), math.radians(lon_deg), alt_km)


def _radar(name: str, lat_deg: float, lon_deg: float, alt_km: float, mask_deg: float,
           source: str) -> Sensor:
    """Return a tracking radar at a site (deg, deg, km): `RADAR_SIGMA`, its mask in deg."""
    return Sensor(_site(name, lat_deg, lon_deg, alt_km), SensorType.RADAR, RADAR_SIGMA,
                  mask_deg, source=source)


def _optical(name: str, lat_deg: float, lon_deg: float, alt_km: float, source: str) -> Sensor:
    """Return an optical site (deg, deg, km): `OPTICAL_SIGMA`, a 20 deg mask, every 10 s."""
    return Sensor(_site(name, lat_deg, lon_deg, alt_km), SensorType.OPTICAL, OPTICAL_SIGMA,
                  20.0, cadence_s=10.0, source=source)


RADAR_SIGMA = (0.020, math.radians(0.02), math.radians(0.02))
"""Tracking-radar noise: 20 m range, 0.02 deg azimuth and elevation."""
OPTICAL_SIGMA = (1.5 * ARCSEC, 1.5 * ARCSEC)
"""Optical noise: 1.5 arcsec in right ascension and declination."""
PAPER_SIGMA = (1.0, 0.01, 0.01)
"""The paper's idealised sensor: 1 km range, 0.01 rad (0.57 deg) angles."""

SENSORS: dict[str, Sensor] = {
    "columbus": Sensor(COLUMBUS, SensorType.RADAR, RADAR_SIGMA, 10.0, cadence_s=10.0,
                       source="the paper's observer, Columbus, Ohio"),
    "columbus_paper": Sensor(COLUMBUS, SensorType.RADAR, PAPER_SIGMA, -90.0, cadence_s=30.0,
                             source="the paper's idealised sensor: sees through the Earth"),
    "millstone": _radar("millstone", 42.62, -71.49, 0.13, 5.0,
        "Millstone Hill Radar, MIT Haystack Observatory, Westford MA "
        "(haystack.mit.edu; en.wikipedia.org/wiki/Millstone_Hill)"),
    "altair": _radar("altair", 9.40, 167.48, 0.01, 5.0,
        "ALTAIR, Reagan Test Site, Roi-Namur, Kwajalein Atoll "
        "(en.wikipedia.org/wiki/ALTAIR)"),
    "tira": _radar("tira", 50.62, 7.13, 0.30, 10.0,
        "TIRA, Fraunhofer FHR, Wachtberg, Germany "
        "(fhr.fraunhofer.de; en.wikipedia.org/wiki/TIRA_(radar))"),
    "socorro": _optical("socorro", 33.82, -106.66, 1.51,
        "GEODSS Socorro, White Sands Missile Range, New Mexico "
        "(en.wikipedia.org/wiki/GEODSS)"),
    "maui": _optical("maui", 20.71, -156.26, 3.06,
        "GEODSS Maui, Haleakala, Hawaii (en.wikipedia.org/wiki/GEODSS)"),
    "diego_garcia": _optical("diego_garcia", -7.41, 72.45, 0.01,
        "GEODSS Diego Garcia, British Indian Ocean Territory "
        "(en.wikipedia.org/wiki/GEODSS)"),
    "goldstone": _radar("goldstone", 35.43, -116.89, 0.90, 10.0,
        "Goldstone Deep Space Communications Complex, Fort Irwin, California "
        "(en.wikipedia.org/wiki/Goldstone_Deep_Space_Communications_Complex)"),
    "fylingdales": _radar("fylingdales", 54.36, -0.67, 0.30, 5.0,
        "RAF Fylingdales, North York Moors, England: a phased array with 360 deg "
        "coverage (en.wikipedia.org/wiki/RAF_Fylingdales)"),
    "ogs_tenerife": _optical("ogs_tenerife", 28.30, -16.51, 2.39,
        "ESA Optical Ground Station, Teide Observatory, Tenerife "
        "(en.wikipedia.org/wiki/ESA_Optical_Ground_Station)"),
    "zimmerwald": _optical("zimmerwald", 46.88, 7.47, 0.95,
        "Zimmerwald Observatory (ZIMLAT), University of Bern, Switzerland "
        "(aiub.unibe.ch; en.wikipedia.org/wiki/Zimmerwald_Observatory)"),
    "siding_spring": _optical("siding_spring", -31.27, 149.06, 1.16,
        "Siding Spring Observatory, New South Wales, Australia "
        "(en.wikipedia.org/wiki/Siding_Spring_Observatory)"),
    "xinglong": _optical("xinglong", 40.40, 117.58, 0.96,
        "Xinglong Observatory, National Astronomical Observatories of China, Hebei "
        "(english.nao.cas.cn)"),
    "calar_alto": _optical("calar_alto", 37.22, -2.55, 2.17,
        "Calar Alto Observatory, Almeria, Spain "
        "(en.wikipedia.org/wiki/Calar_Alto_Observatory)"),
    "la_silla": _optical("la_silla", -29.26, -70.73, 2.40,
        "ESO La Silla Observatory, Coquimbo, Chile "
        "(en.wikipedia.org/wiki/La_Silla_Observatory)"),
}
"""Sensor presets by id. ``columbus`` and ``columbus_paper`` are two sensors at one site
(frame_id "columbus"): a real radar with a 10 deg mask, and the paper's idealised one. Beyond
the sites of `NETWORKS`, two radars and six optical sites the real-sky study's evaluation
cases draw their networks from (`sim.sky.SITE_POOL`); each is modelled like the others of
its type (a steerable sensor above its mask; noise the reference values above)."""

NETWORKS: dict[str, tuple[str, ...]] = {
    "network": ("millstone", "tira", "altair", "socorro", "maui", "diego_garcia"),
    "radar_network": ("millstone", "tira", "altair"),
    "optical_network": ("socorro", "maui", "diego_garcia"),
}
"""Station networks by id: sensor preset ids, spread in longitude (radar and optical mixed,
radar only, optical only)."""

STATIONS: dict[str, Station] = {s.station.name: s.station for s in SENSORS.values()}
"""Known stations by id (the ``frame_id`` of their measurements)."""


def station_ids(name: str) -> tuple[str, ...]:
    """Return the ids a ``station`` setting names: a network's, or those of "a,b,c"."""
    return NETWORKS.get(name) or tuple(x.strip() for x in name.split(",") if x.strip())


def find_station(station_id: str, sites: Mapping[str, Station] | None = None) -> Station | None:
    """Return the station of a station id or sensor preset id, built in or of `sites`.

    `sites`: stations of one's own by id (`site_file`), which may not reuse a built-in id.
    None when the id is unknown.
    """
    if station_id in STATIONS:
        return STATIONS[station_id]
    if station_id in SENSORS:
        return SENSORS[station_id].station
    return (sites or {}).get(station_id)


def network_stations(name: str,
                     sites: Mapping[str, Station] | None = None) -> dict[str, Station]:
    """Return the stations (id -> Station) of a network id, a station id, or "a,b,c" ids.

    Ids are built-in (`STATIONS`, `SENSORS`) or of `sites` (stations of one's own by id,
    `site_file`). ValueError naming the known ids for an unknown one.
    """
    out = {}
    for i in station_ids(name):
        station = find_station(i, sites)
        if station is None:
            own = f"; your sites: {', '.join(sites)}" if sites else ""
            raise ValueError(f"station {i!r} unknown; known stations: {', '.join(STATIONS)}"
                             f"{own}; networks: {', '.join(NETWORKS)}")
        out[station.name] = station
    return out

"""A sites file: the user's own ground stations and sensors, read from YAML (`load_sites`).

The built-in stations are `stations.SENSORS`; a sites file adds stations of one's own,
which every place that takes a station id then knows: ``ssa-fusion import tdm --sites``
(TDM participants), ``ssa-fusion replay --sites`` and the filter and surrogate nodes'
``sites`` parameter (their ``station``). The format (docs/SITES.md, and
``config/sites/example.yaml`` with every field explained)::

    sites:
      - id: my_radar            # lowercase letters, digits, '_' or '-'; the measurements' frame_id
        latitude_deg: 47.25     # WGS-84 geodetic latitude, deg, north positive, -90..90
        longitude_deg: -122.5   # WGS-84 longitude, deg, east positive, -180..180
        height_m: 120.0         # height above the WGS-84 ellipsoid, m, -1000..10000
        type: radar             # radar (range, azimuth, elevation) | optical (RA, Dec)
        noise: {range_m: 25.0, azimuth_deg: 0.03, elevation_deg: 0.03}   # 1 sigma, each > 0
        cadence_s: 10.0         # s between measurements during a pass, > 0
        min_elevation_deg: 10.0 # elevation mask, deg, -90..90
        mask_by_azimuth: [[0, 15.0], [90, 10.0], [180, 20.0]]   # optional: [az deg, min el deg]
        max_range_km: 3000.0    # optional, radar only: farthest range it measures, km, > 0
        # optical only, optional: limiting_magnitude: 14.0 (faintest visual magnitude seen),
        # dark_below_deg: -12.0 (it observes while the Sun is below this elevation)

Optical noise is ``{ra_arcsec: ..., dec_arcsec: ...}``. Every value is a finite number
(YAML ``.nan``/``.inf`` and booleans are refused); unknown keys, missing keys, values out
of range, a bad ``type``, an id given twice or one that is a built-in station, sensor or
network id (`RESERVED_IDS`) are refused with one line naming the file, the site (its id,
else its position in the list) and the field (`SiteFileError`). A mapping that gives a key
twice is refused too (YAML itself keeps the last). The line is bounded whatever the file
holds: values are quoted to `quoting.MAX_QUOTE` characters without walking all of them (a
YAML alias bomb of a few hundred bytes loads as 10^8 items), and a file over
`MAX_FILE_BYTES` is refused before it is parsed (a site is a few hundred bytes; YAML is
parsed whole, at ~3 MB/s and ~200 bytes of memory per byte).

Units out: a site becomes a `stations.Sensor` at a `frames.Station` (latitude and longitude
in rad, height in km above the WGS-84 ellipsoid, so its ITRF position is
`frames.site_itrs`); noise in the core's units (radar: km, rad, rad; optical: rad, rad),
azimuth mask in deg as `Sensor.mask_by_azimuth_deg`.
"""

from __future__ import annotations

import math
import re
from collections.abc import Mapping
from pathlib import Path
from typing import Any, NoReturn

from ssa_fusion.core.base.constants import ARCSEC
from ssa_fusion.core.base.quoting import one_line, quote, shown
from ssa_fusion.core.earth.frames import Station
from ssa_fusion.core.earth.stations import (
    DARK_BELOW_DEG,
    NETWORKS,
    SENSORS,
    STATIONS,
    Sensor,
    SensorType,
)
from ssa_fusion.core.measure.validation import MAX_ID_CHARS
from ssa_fusion.formats.files import read_bounded

RESERVED_IDS = frozenset({*STATIONS, *SENSORS, *NETWORKS, "gcrf"})
"""Ids a site may not take: the built-in stations, sensor presets, networks, and ``gcrf``
(the frame_id of positions)."""

ID_PATTERN = re.compile(rf"[a-z0-9][a-z0-9_-]{{0,{MAX_ID_CHARS - 1}}}")
"""What a site id looks like: a TDM participant name in lowercase (participants are matched
case-insensitively), without commas (which separate the ids of a network)."""

MAX_FILE_BYTES = 1_000_000
"""Largest sites file read (thousands of sites; the example's three are 3 kB)."""

HEIGHT_RANGE_M = (-1000.0, 10000.0)
"""Heights a ground site may have, m above the WGS-84 ellipsoid."""

NOISE_FIELDS: dict[SensorType, tuple[tuple[str, float], ...]] = {
    SensorType.RADAR: (("range_m", 1e-3), ("azimuth_deg", math.pi / 180.0),
                       ("elevation_deg", math.pi / 180.0)),
    SensorType.OPTICAL: (("ra_arcsec", ARCSEC), ("dec_arcsec", ARCSEC)),
}
"""The ``noise`` keys per sensor type, in channel order, with the factor to core units
(km, rad)."""

_REQUIRED = ("id", "latitude_deg", "longitude_deg", "height_m", "type", "noise", "cadence_s",
             "min_elevation_deg")
_OPTIONAL = ("mask_by_azimuth", "max_range_km", "limiting_magnitude", "dark_below_deg")


class SiteFileError(ValueError):
    """A sites file cannot be read or is invalid.

    The message is one line naming the file, the site and the field.
    """


DECIMAL_INT = re.compile(r"[-+]?(0|[1-9][0-9_]*)")
"""An integer as a sites file may write it: decimal, no leading zero."""


def _loader() -> type:
    """Return a `yaml.SafeLoader` that refuses a key given twice and ambiguous integers.

    YAML 1.1, which PyYAML speaks, reads ``0110`` as octal 72, ``1:30`` as 90 (base 60),
    ``0x1f`` and ``0b101`` as hexadecimal and binary: a height or a cadence written so would
    be taken silently as another number. Only decimal integers are taken; the others raise.
    """
    import yaml

    class Loader(yaml.SafeLoader):
        def construct_yaml_int(self, node: Any) -> int:  # noqa: ANN401
            text = str(self.construct_scalar(node))
            if not DECIMAL_INT.fullmatch(text):
                raise yaml.constructor.ConstructorError(
                    None, None, f"integer {quote(text)} is not decimal (YAML 1.1 reads a "
                    "leading 0 as octal, 0x as hexadecimal, a colon as base 60): write it "
                    "in decimal, without a leading zero", node.start_mark)
            return int(text.replace("_", ""))

        def construct_mapping(self, node: Any, deep: bool = False) -> Any:  # noqa: ANN401
            seen: set[object] = set()
            for key_node, _ in node.value:
                key = self.construct_object(key_node, deep=deep)
                try:
                    hash(key)
                except TypeError:  # a list or mapping as a key
                    raise yaml.constructor.ConstructorError(
                        None, None, "found unhashable key", key_node.start_mark) from None
                if key in seen:
                    raise yaml.constructor.ConstructorError(
                        None, None, f"key {quote(key)} given twice", key_node.start_mark)
                seen.add(key)
            return super().construct_mapping(node, deep=deep)

    Loader.add_constructor("tag:yaml.org,2002:int", Loader.construct_yaml_int)
    return Loader


class _Site:
    """Reads one site's fields, raising `SiteFileError` naming the file, site and field."""

    def __init__(self, path: Path | str, index: int, raw: object) -> None:
        self.path, self.index = path, index
        self.name = f"site #{index + 1}"
        if not isinstance(raw, Mapping):
            self.fail("", f"must be a mapping of fields, got {type(raw).__name__}")
        self.raw: Mapping[str, Any] = raw
        site_id = raw.get("id")
        if isinstance(site_id, str) and site_id:
            self.name = f"site {quote(site_id)}"

    def fail(self, field: str, why: str) -> NoReturn:
        """Raise the one-line error of `field` (of this site)."""
        where = f"{self.name}: {shown(field, 80)}" if field else self.name
        raise SiteFileError(f"{self.path}: {where}: {why}")

    def number(self, key: str, low: float = -math.inf, high: float = math.inf,
               positive: bool = False, within: Mapping[str, Any] | None = None,
               field: str | None = None) -> float:
        """Return the finite number at `key` (of `within`, default the site) in its range."""
        v = (self.raw if within is None else within).get(key)
        name = field or key
        if isinstance(v, bool) or not isinstance(v, int | float):
            self.fail(name, f"must be a number, got {quote(v)}")
        try:
            x = float(v)
        except OverflowError:  # an integer beyond a float's range
            x = math.inf
        if not math.isfinite(x):
            self.fail(name, f"must be a finite number, got {quote(v)}")
        if positive and not x > 0:
            self.fail(name, f"must be > 0, got {quote(v)}")
        if not low <= x <= high:
            self.fail(name, f"must be in {low:g}..{high:g}, got {quote(v)}")
        return x

    def sensor(self, source: str) -> Sensor:
        """Return the site as a `stations.Sensor` (its `frames.Station` in ``station``)."""
        raw = self.raw
        unknown = sorted(str(k) for k in raw if k not in (*_REQUIRED, *_OPTIONAL))
        if unknown:
            self.fail(unknown[0], f"unknown field (known: "
                                       f"{', '.join((*_REQUIRED, *_OPTIONAL))})")
        for key in _REQUIRED:
            if key not in raw:
                self.fail(key, "missing")
        site_id = raw["id"]
        if not isinstance(site_id, str) or not ID_PATTERN.fullmatch(site_id):
            self.fail("id", f"must be at most {MAX_ID_CHARS} lowercase letters, digits, '_' or "
                            f"'-' (starting with a letter or digit), got {quote(site_id)}")
        if site_id in RESERVED_IDS:
            self.fail("id", "is a built-in station, sensor or network id "
                            f"({', '.join(sorted(RESERVED_IDS))}); choose another")
        lat = self.number("latitude_deg", -90.0, 90.0)
        lon = self.number("longitude_deg", -180.0, 180.0)
        height = self.number("height_m", *HEIGHT_RANGE_M)
        kind = raw["type"]
        if kind not in tuple(SensorType):
            self.fail("type", f"must be one of {', '.join(SensorType)}, got {quote(kind)}")
        sensor_type = SensorType(kind)
        sigma = self.noise(sensor_type)
        cadence = self.number("cadence_s", positive=True)
        min_el = self.number("min_elevation_deg", -90.0, 90.0)
        mask = self.mask() if "mask_by_azimuth" in raw else ()
        max_range = math.inf
        if "max_range_km" in raw:
            if sensor_type != SensorType.RADAR:
                self.fail("max_range_km", "is for a radar only (an optical sensor measures "
                                          "no range)")
            max_range = self.number("max_range_km", positive=True)
        limit = math.inf
        if "limiting_magnitude" in raw:
            if sensor_type != SensorType.OPTICAL:
                self.fail("limiting_magnitude", "is for an optical sensor only")
            limit = self.number("limiting_magnitude", -30.0, 30.0)
        dark = DARK_BELOW_DEG
        if "dark_below_deg" in raw:
            if sensor_type != SensorType.OPTICAL:
                self.fail("dark_below_deg", "is for an optical sensor only (a radar works "
                                            "day and night)")
            dark = self.number("dark_below_deg", -90.0, 0.0)
        station = Station(site_id, math.radians(lat), math.radians(lon), height / 1000.0)
        return Sensor(station, sensor_type, sigma, min_el, mask_by_azimuth_deg=mask,
                      cadence_s=cadence, source=source, max_range_km=max_range,
                      limiting_magnitude=limit, dark_below_deg=dark)

    def noise(self, sensor_type: SensorType) -> tuple[float, ...]:
        """Return the ``noise`` mapping as 1-sigma values in core units (km, rad)."""
        raw = self.raw["noise"]
        fields = NOISE_FIELDS[sensor_type]
        names = [k for k, _ in fields]
        if not isinstance(raw, Mapping):
            self.fail("noise", f"must be a mapping of {', '.join(names)}, got {quote(raw)}")
        extra = sorted(str(k) for k in raw if k not in names)
        if extra:
            self.fail(f"noise.{extra[0]}", f"unknown for a {sensor_type} (a "
                                                f"{sensor_type} has {', '.join(names)})")
        for k in names:
            if k not in raw:
                self.fail(f"noise.{k}", "missing")
        return tuple(self.number(k, positive=True, within=raw, field=f"noise.{k}") * factor
                     for k, factor in fields)

    def mask(self) -> tuple[tuple[float, float], ...]:
        """Return ``mask_by_azimuth`` as (azimuth deg, minimum elevation deg) points."""
        raw = self.raw["mask_by_azimuth"]
        if not isinstance(raw, list) or not raw:
            self.fail("mask_by_azimuth", f"must be a non-empty list of [azimuth_deg, "
                                         f"min_elevation_deg], got {quote(raw)}")
        out: list[tuple[float, float]] = []
        for i, point in enumerate(raw):
            field = f"mask_by_azimuth[{i}]"
            if not isinstance(point, list) or len(point) != 2:
                self.fail(field, f"must be [azimuth_deg, min_elevation_deg], got "
                                 f"{quote(point)}")
            pair = dict(zip(("az", "el"), point, strict=True))
            az = self.number("az", 0.0, 360.0, within=pair, field=f"{field} azimuth")
            el = self.number("el", -90.0, 90.0, within=pair, field=f"{field} elevation")
            if any(math.isclose(az % 360.0, a % 360.0) for a, _ in out):
                self.fail(field, f"azimuth {az:g} deg given twice")
            out.append((az, el))
        return tuple(out)


def parse_sites(data: object, path: Path | str = "<sites>") -> dict[str, Sensor]:
    """Return the sensors (by id, in file order) of a loaded sites document.

    `data` is what ``yaml.safe_load`` gives for the file: a mapping with one key, ``sites``,
    a list of site mappings (module docstring). SiteFileError (one line naming `path`, the
    site and the field) for anything invalid.
    """
    if not isinstance(data, Mapping) or set(data) != {"sites"}:
        keys = quote(sorted(map(str, data))) if isinstance(data, Mapping) else \
            type(data).__name__
        raise SiteFileError(f"{path}: must be a mapping with one key, 'sites' (a list of "
                            f"sites), got {keys}")
    raw = data["sites"]
    if not isinstance(raw, list) or not raw:
        raise SiteFileError(f"{path}: sites: must be a non-empty list of sites, got "
                            f"{quote(raw)}")
    out: dict[str, Sensor] = {}
    for i, item in enumerate(raw):
        site = _Site(path, i, item)
        sensor = site.sensor(source=f"{path}, site #{i + 1}")
        if sensor.station.name in out:
            site.fail("id", "given twice (ids must be unique)")
        out[sensor.station.name] = sensor
    return out


def load_sites(path: Path | str) -> dict[str, Sensor]:
    """Return the sensors (by id, in file order) of the sites file at `path`.

    SiteFileError (one line naming the file, and the site and field where one is at
    fault) if it cannot be read, is not YAML, or is invalid (`parse_sites`).
    """
    import yaml

    try:
        raw = read_bounded(path, MAX_FILE_BYTES)
        if raw is None:
            raise SiteFileError(f"{path}: larger than {MAX_FILE_BYTES} bytes; a sites file "
                                "holds a few hundred bytes per site")
        text = raw.decode("utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise SiteFileError(f"cannot read sites file {path}: {one_line(exc, 120)}") from None
    try:
        data = yaml.load(text, Loader=_loader())  # a SafeLoader subclass
    except yaml.YAMLError as exc:
        raise SiteFileError(f"{path}: not valid YAML: {one_line(exc, 240)}") from None
    except Exception as exc:  # PyYAML's own on odd input (RecursionError, MemoryError too):
        # ValueError (an int of 5000 digits), IndexError ('!!float' of nothing), ...
        raise SiteFileError(f"{path}: not a sites file PyYAML can load: "
                            f"{type(exc).__name__}: {one_line(exc, 120)}") from None
    return parse_sites(data, path)


def site_stations(sensors: Mapping[str, Sensor]) -> tuple[Station, ...]:
    """Return the stations of `sensors` (file order).

    What `config.EstimatorConfig.sites` takes.
    """
    return tuple(s.station for s in sensors.values())


def load_stations(path: Path | str) -> tuple[Station, ...]:
    """Return the stations of the sites file at `path` ('' = none; `load_sites`)."""
    return site_stations(load_sites(path)) if str(path) else ()


def load_station_map(path: Path | str) -> dict[str, Station]:
    """Return the stations of the sites file at `path` by id ('' = none)."""
    return {st.name: st for st in load_stations(path)}

"""`formats.sites`: the example sites file loads as written, sites land where astropy puts
them, and every bad input is refused with one line naming the file, the site and the field:
bounded, whatever the file holds (an alias bomb, a 3 MB line, an integer of 5000 digits),
and nothing but that error for mutated and random text (hypothesis)."""

from __future__ import annotations

import math
import time
from pathlib import Path

import numpy as np
import pytest
import yaml
from astropy import units as u
from astropy.coordinates import EarthLocation
from fuzz_text import error_of, mutated
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from ssa_fusion.core.base.constants import ARCSEC
from ssa_fusion.core.base.quoting import MAX_MESSAGE
from ssa_fusion.core.base.types import Kind
from ssa_fusion.core.earth import frames
from ssa_fusion.core.earth.stations import SensorType, network_stations
from ssa_fusion.core.gaps import estimator as config
from ssa_fusion.formats.sites import SiteFileError, load_sites, load_stations, parse_sites

EXAMPLE = Path(__file__).resolve().parents[2] / "config" / "sites" / "example.yaml"
RADAR = {"id": "my_radar", "latitude_deg": 47.25, "longitude_deg": -122.5, "height_m": 120.0,
         "type": "radar", "noise": {"range_m": 25.0, "azimuth_deg": 0.03,
                                    "elevation_deg": 0.03},
         "cadence_s": 10.0, "min_elevation_deg": 10.0}
OPTICAL = {"id": "my_scope", "latitude_deg": -30.0, "longitude_deg": 70.0, "height_m": 2000.0,
           "type": "optical", "noise": {"ra_arcsec": 1.0, "dec_arcsec": 2.0},
           "cadence_s": 20.0, "min_elevation_deg": 20.0}


def test_the_example_loads_as_its_comments_say():
    sites = load_sites(EXAMPLE)
    assert list(sites) == ["nordlys", "kestrel", "pampa-obs"]
    n = sites["nordlys"]
    assert n.type == SensorType.RADAR and n.kind == Kind.RANGE_AZ_EL
    assert n.station == frames.Station("nordlys", math.radians(69.60), math.radians(19.20),
                                       0.110)
    assert n.sigma == pytest.approx((0.025, math.radians(0.03), math.radians(0.03)),
                                    rel=1e-15)
    assert (n.cadence_s, n.min_elevation_deg, n.max_range_km) == (10.0, 8.0, 3500.0)
    k = sites["kestrel"]
    assert k.mask_by_azimuth_deg == ((0.0, 5.0), (90.0, 18.0), (180.0, 12.0), (270.0, 5.0))
    assert k.max_range_km == math.inf
    # the mask: 18 deg due east, halfway to south 15 deg, the 5 deg floor due west
    mask = np.degrees(k.min_elevation(np.radians([90.0, 135.0, 270.0])))
    np.testing.assert_allclose(mask, [18.0, 15.0, 5.0], atol=1e-12)
    p = sites["pampa-obs"]
    assert p.type == SensorType.OPTICAL and p.kind == Kind.RA_DEC
    assert p.sigma == pytest.approx((ARCSEC, ARCSEC), rel=1e-15)
    assert p.station.alt_km == pytest.approx(2.635, rel=1e-15)


@pytest.mark.parametrize("name", ["nordlys", "kestrel", "pampa-obs"])
def test_sites_are_where_astropy_puts_them(name):
    """ITRF position of each example site against astropy's WGS-84 geodetic -> geocentric
    (ERFA's gd2gc), to 1 mm."""
    raw = {s["id"]: s for s in yaml.safe_load(EXAMPLE.read_text())["sites"]}[name]
    ref = EarthLocation.from_geodetic(raw["longitude_deg"] * u.deg, raw["latitude_deg"] * u.deg,
                                      raw["height_m"] * u.m, ellipsoid="WGS84")
    want = np.array([ref.x.to_value(u.km), ref.y.to_value(u.km), ref.z.to_value(u.km)])
    got = load_sites(EXAMPLE)[name].station.itrs
    assert np.abs(got - want).max() < 1e-6  # km: 1 mm


def test_stations_of_a_sites_file_resolve_beside_the_built_in_ones():
    own = {s.name: s for s in load_stations(EXAMPLE)}
    assert set(network_stations("nordlys,millstone,", own)) == {"nordlys", "millstone"}
    with pytest.raises(ValueError, match="station 'nordlys' unknown"):
        network_stations("nordlys")
    c = config.EstimatorConfig(station="kestrel", sites=tuple(own.values()))
    assert config.measurement_model(c).station == own["kestrel"]
    assert config.from_dict(config.to_dict(c)) == c  # recorded with the settings
    assert load_stations("") == ()


def test_for_stations_takes_the_stations_measurements_name():
    own = load_stations(EXAMPLE)
    c = config.EstimatorConfig(station="columbus", sites=own)
    assert config.for_stations(c, ["columbus"]) is c
    assert config.for_stations(c, ["nordlys"]).station == "nordlys"
    assert config.for_stations(c, ["tira", "kestrel", "nowhere"]).station == "kestrel,tira,"
    assert config.uncovered_stations(c, ["tira", "columbus"]) == ["tira"]


def write(tmp_path: Path, sites: object) -> Path:
    path = tmp_path / "sites.yaml"
    path.write_text(yaml.safe_dump({"sites": sites}))
    return path


def edited(base: dict, **changes: object) -> dict:
    """`base` with `changes` (a value of None removes the key; "noise__x" edits noise.x)."""
    out = {**base, "noise": dict(base["noise"])}
    for key, value in changes.items():
        target, k = (out["noise"], key[7:]) if key.startswith("noise__") else (out, key)
        if value is None:
            target.pop(k)
        else:
            target[k] = value
    return out


BAD = [
    (edited(RADAR, colour="red"), "site 'my_radar': colour: unknown field"),
    (edited(RADAR, cadence_s=None), "site 'my_radar': cadence_s: missing"),
    (edited(RADAR, id=None), "site #2: id: missing"),  # by its place in the list
    (edited(RADAR, latitude_deg=90.5), "site 'my_radar': latitude_deg: must be in -90..90"),
    (edited(RADAR, latitude_deg=float("nan")),
     "site 'my_radar': latitude_deg: must be a finite number"),
    (edited(RADAR, longitude_deg=float("inf")),
     "site 'my_radar': longitude_deg: must be a finite number"),
    (edited(RADAR, longitude_deg=181.0), "site 'my_radar': longitude_deg: must be in -180..180"),
    (edited(RADAR, height_m="120"), "site 'my_radar': height_m: must be a number, got '120'"),
    (edited(RADAR, height_m=True), "site 'my_radar': height_m: must be a number, got True"),
    (edited(RADAR, height_m=20000.0), "site 'my_radar': height_m: must be in -1000..10000"),
    (edited(RADAR, type="lidar"), "site 'my_radar': type: must be one of radar, optical"),
    (edited(RADAR, noise__range_m=-1.0), "site 'my_radar': noise.range_m: must be > 0"),
    (edited(RADAR, noise__azimuth_deg=0.0), "site 'my_radar': noise.azimuth_deg: must be > 0"),
    (edited(RADAR, noise__elevation_deg=None), "site 'my_radar': noise.elevation_deg: missing"),
    (edited(RADAR, noise__ra_arcsec=1.0),
     "site 'my_radar': noise.ra_arcsec: unknown for a radar"),
    (edited(OPTICAL, noise__dec_arcsec=-0.5), "site 'my_scope': noise.dec_arcsec: must be > 0"),
    (edited(OPTICAL, max_range_km=1000.0),
     "site 'my_scope': max_range_km: is for a radar only"),
    (edited(RADAR, max_range_km=0.0), "site 'my_radar': max_range_km: must be > 0"),
    (edited(RADAR, dark_below_deg=-12.0),
     "site 'my_radar': dark_below_deg: is for an optical sensor only"),
    (edited(OPTICAL, dark_below_deg=5.0), "site 'my_scope': dark_below_deg: must be in -90..0"),
    (edited(RADAR, limiting_magnitude=12.0),
     "site 'my_radar': limiting_magnitude: is for an optical sensor only"),
    (edited(OPTICAL, limiting_magnitude=float("nan")),
     "site 'my_scope': limiting_magnitude: must be a finite number"),
    (edited(RADAR, cadence_s=0.0), "site 'my_radar': cadence_s: must be > 0"),
    (edited(RADAR, min_elevation_deg=95.0),
     "site 'my_radar': min_elevation_deg: must be in -90..90"),
    (edited(RADAR, mask_by_azimuth=[[0.0, 5.0], [400.0, 5.0]]),
     "site 'my_radar': mask_by_azimuth[1] azimuth: must be in 0..360"),
    (edited(RADAR, mask_by_azimuth=[[0.0, 5.0, 1.0]]),
     "site 'my_radar': mask_by_azimuth[0]: must be [azimuth_deg, min_elevation_deg]"),
    (edited(RADAR, mask_by_azimuth=[[10.0, 5.0], [10.0, 7.0]]),
     "site 'my_radar': mask_by_azimuth[1]: azimuth 10 deg given twice"),
    (edited(RADAR, id="tira"), "site 'tira': id: is a built-in station, sensor or network id"),
    (edited(RADAR, id="radar_network"), "site 'radar_network': id: is a built-in station"),
    (edited(RADAR, id="My Radar"), "site 'My Radar': id: must be at most 128 lowercase letters"),
    (edited(RADAR, id="a,b"), "site 'a,b': id: must be at most 128 lowercase letters"),
]


@pytest.mark.parametrize(("site", "says"), BAD)
def test_a_bad_site_is_one_line_naming_the_file_site_and_field(tmp_path, site, says):
    path = write(tmp_path, [OPTICAL, site])
    with pytest.raises(SiteFileError) as exc:
        load_sites(path)
    text = str(exc.value)
    assert text.startswith(f"{path}: ") and says in text and "\n" not in text, text


def test_duplicate_ids_and_bad_files_are_refused(tmp_path):
    dup = write(tmp_path, [RADAR, edited(OPTICAL, id="my_radar")])
    with pytest.raises(SiteFileError, match=r"site 'my_radar': id: given twice"):
        load_sites(dup)
    twice = tmp_path / "twice.yaml"
    twice.write_text("sites:\n  - id: a\n    id: b\n")
    with pytest.raises(SiteFileError, match=r"twice\.yaml: not valid YAML: .*'id' given twice"):
        load_sites(twice)
    for data, says in (({"stations": [RADAR]}, "one key, 'sites'"),
                       ({"sites": []}, "sites: must be a non-empty list"),
                       ({"sites": ["x"]}, "site #1: must be a mapping"),
                       ([RADAR], "one key, 'sites'")):
        with pytest.raises(SiteFileError, match=says):
            parse_sites(data, "f.yaml")
    with pytest.raises(SiteFileError, match="cannot read sites file"):
        load_sites(tmp_path / "missing.yaml")
    broken = tmp_path / "broken.yaml"
    broken.write_text("sites: [\n")
    with pytest.raises(SiteFileError, match=r"broken\.yaml: not valid YAML") as exc:
        load_sites(broken)
    assert "\n" not in str(exc.value)
    assert issubclass(SiteFileError, ValueError)


# ------------------------------------------------------------------------------------------
# hostile files: bounded time, memory and message (named cases), and fuzzing
# ------------------------------------------------------------------------------------------
BOMB = "&l0 [lol, lol, lol, lol, lol, lol, lol, lol, lol], " + ", ".join(
    f"&l{i} [{', '.join([f'*l{i - 1}'] * 9)}]" for i in range(1, 12))
"""YAML flow items whose last list holds 9^11 (3e10) items by aliases: 500 bytes of text."""


def refused(path: Path, text: str | bytes) -> str:
    """The bounded one-line SiteFileError `load_sites` gives for `text` (written to `path`)."""
    said = error_of(load_sites, SiteFileError, path, text)
    assert "\n" not in said and len(said) <= MAX_MESSAGE and str(path) in said, said[:300]
    return said


def radar(mask: str = "[[0, 1]]") -> str:
    """A sites file of one radar site whose mask_by_azimuth is the YAML `mask`."""
    return ("sites:\n  - {id: x, latitude_deg: 1, longitude_deg: 1, height_m: 1, type: radar,\n"
            "     noise: {range_m: 1, azimuth_deg: 1, elevation_deg: 1}, cadence_s: 1,\n"
            f"     min_elevation_deg: 1, mask_by_azimuth: {mask}}}\n")


@pytest.mark.parametrize(("name", "text", "says"), [
    # the repr of an alias bomb in the message was gigabytes (39 MB for 9^7 items)
    ("mask_bomb.yaml", radar(f"[[{BOMB}]]"),
     "mask_by_azimuth[0]: must be [azimuth_deg, min_elevation_deg], got [['lol', 'lol', "),
    ("sites_bomb.yaml", f"sites: {{a: [{BOMB}], b: *l11}}\n",
     "sites: must be a non-empty list of sites, got {'a': [['lol', 'lol',"),
    ("long_key.yaml", radar().replace("type: radar", f"type: radar, {'k' * 1000}: 1"),
     "site 'x': kkkkkkkkkk"),
    # a 3 MB one-line file: refused before YAML parses it (20 s and 700 MB at 3 MB)
    ("oneline.yaml", "sites: [" + "1, " * 1_000_000 + "]\n", "larger than 1000000 bytes"),
    # an integer of 5000 digits: PyYAML's int() raised a bare ValueError without the file
    ("digits.yaml", "sites: " + "9" * 5000 + "\n", "not a sites file PyYAML can load"),
    # an integer beyond a float: float() raised OverflowError
    ("big_int.yaml", radar().replace("latitude_deg: 1", f"latitude_deg: {10**400}"),
     "latitude_deg: must be a finite number, got <integer of 1329 bits>"),
    ("latin1.yaml", "sites: [caf\xe9]\n".encode("latin-1"), "cannot read sites file"),
    # a mapping as a key: the check for keys given twice hashed it (TypeError)
    ("dict_key.yaml", "? {a: 1}\n: 0\n", "not valid YAML: found unhashable key"),
    # PyYAML's float constructor indexes the empty string (IndexError)
    ("empty_float.yaml", "!!float", "not a sites file PyYAML can load: IndexError"),
    # YAML 1.1 integers that are not what they look like: 0110 was taken as 72 m
    ("octal.yaml", radar().replace("height_m: 1", "height_m: 0110"),
     "integer '0110' is not decimal"),
    ("base60.yaml", radar().replace("cadence_s: 1", "cadence_s: 1:30"),
     "integer '1:30' is not decimal"),
    ("hex.yaml", radar().replace("height_m: 1", "height_m: 0x1f"), "integer '0x1f'"),
    # a 100 kB site id was taken
    ("long_id.yaml", radar().replace("id: x", "id: " + "x" * 100_000),
     "id: must be at most 128 lowercase"),
])
def test_a_hostile_sites_file_is_refused_in_one_bounded_line(tmp_path, name, text, says):
    t0 = time.perf_counter()
    said = refused(tmp_path / name, text)
    assert says in said, said
    assert time.perf_counter() - t0 < 5.0


FUZZ = settings(max_examples=150, deadline=None, derandomize=True,
                suppress_health_check=[HealthCheck.too_slow])
TOKENS = [": ", "- ", "\n", "  ", "[", "]", "{", "}", ",", "&a ", "*a", "!!binary ", "!!float ",
          ".nan", ".inf", "-.inf", "1e400", "9" * 400, "true", "~", "id: ", "type: optical",
          "noise: ", "mask_by_azimuth: [[0, 1], [0, 2]]", "max_range_km: ", "'", '"', "#", "\t",
          "\x00", "é", "? ", "<<: "]


@pytest.fixture(scope="module")
def fuzz_dir(tmp_path_factory):
    return tmp_path_factory.mktemp("sites_fuzz")


def _only_site_file_errors(path: Path, text: str) -> None:
    """`load_sites` gives sensors within their domains or a bounded SiteFileError."""
    path.write_text(text, encoding="utf-8", errors="surrogatepass")
    try:
        sites = load_sites(path)
    except SiteFileError as exc:
        said = str(exc)
        assert "\n" not in said and len(said) <= MAX_MESSAGE and str(path) in said, said[:300]
        return
    for s in sites.values():
        assert abs(s.station.lat_rad) <= math.pi / 2 and all(v > 0 for v in s.sigma)


@FUZZ
@given(mutated(EXAMPLE.read_text(), TOKENS))
def test_a_mutated_sites_file_gives_sites_or_one_site_file_error(fuzz_dir, text):
    _only_site_file_errors(fuzz_dir / "m.yaml", text)


@FUZZ
@given(st.one_of(st.text(max_size=300),
                 st.lists(st.sampled_from(TOKENS), max_size=40).map("".join)))
def test_random_text_gives_sites_or_one_site_file_error(fuzz_dir, text):
    _only_site_file_errors(fuzz_dir / "r.yaml", text)

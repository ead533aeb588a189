"""Catalog input (TLE/3LE, OMM XML/CSV) and its vectorised SGP4 truth (formats.element_sets)."""

from __future__ import annotations

import datetime as dt
from pathlib import Path

import numpy as np
import pytest
from sgp4.api import Satrec, SatrecArray, jday

from ssa_fusion.core.earth import frames, timescales
from ssa_fusion.core.motion.element_sets import catalog_states
from ssa_fusion.formats import element_sets as catalog

ROOT = Path(__file__).resolve().parents[2]
SAMPLE = ROOT / "config" / "catalogs" / "sample.tle"
OMM_XML = ROOT / "config" / "catalogs" / "sample_omm.xml"
OMM_CSV = ROOT / "config" / "catalogs" / "sample_omm.csv"

L1 = "1 28057U 03049A   06177.78615833  .00000060  00000-0  35940-4 0  1836"
L2 = "2 28057  98.4283 247.6961 0000884  88.1964 271.9322 14.35478080140550"


def sample_lines() -> list[tuple[str, str, str]]:
    """(name, line 1, line 2) of the sample file, read without the module under test."""
    lines = [s for s in SAMPLE.read_text().splitlines() if s and not s.startswith("#")]
    return [(lines[i], lines[i + 1], lines[i + 2]) for i in range(0, len(lines), 3)]


def test_sample_catalog_has_every_regime():
    entries = catalog.read_catalog(SAMPLE)
    assert [e.object_id for e in entries] == ["28057", "6251", "29238", "28129", "24208", "8195"]
    assert [e.name for e in entries] == [n for n, _, _ in sample_lines()]
    rev_per_day = {e.object_id: e.satrec.no_kozai * 1440 / (2 * np.pi) for e in entries}
    ecc = {e.object_id: e.satrec.ecco for e in entries}
    assert rev_per_day["28057"] > 14 and ecc["28057"] < 1e-3  # LEO
    assert rev_per_day["29238"] > 15 and entries[2].satrec.ndot > 0  # high-drag LEO
    assert 1.9 < rev_per_day["28129"] < 2.1 and ecc["28129"] < 0.01  # MEO, GPS
    assert 0.99 < rev_per_day["24208"] < 1.01  # GEO
    assert 1.9 < rev_per_day["8195"] < 2.1 and ecc["8195"] > 0.6  # Molniya
    assert entries[0].source.endswith("sample.tle:15")


def test_catalog_truth_equals_sgp4_vectorised_and_per_object():
    entries = catalog.read_catalog(SAMPLE)
    start = dt.datetime(2006, 6, 27, 0, 0, 0, tzinfo=dt.UTC)
    t = start.timestamp() + np.arange(0.0, 2 * 86400.0, 300.0)
    states = catalog_states(entries, t)
    assert states.x.shape == (6, t.size, 6) and states.object_ids[1] == "6251"
    assert np.array_equal(states.t, t) and not states.error.any()

    # sgp4's own vectorised output, from the sample's lines and sgp4's own calendar dates
    stamps = [start + dt.timedelta(seconds=float(s - t[0])) for s in t]
    jd_fr = [jday(d.year, d.month, d.day, d.hour, d.minute, d.second) for d in stamps]
    jd, fr = (np.array(c) for c in zip(*jd_fr, strict=True))
    sats = [Satrec.twoline2rv(a, b) for _, a, b in sample_lines()]
    err, r, v = SatrecArray(sats).sgp4(jd, fr)
    assert not err.any()
    teme = frames.gcrs_to_teme(states.x, t)  # the catalog's states are GCRF: back to TEME
    np.testing.assert_allclose(teme[..., :3], r, rtol=0, atol=1e-6)  # km: 1 mm
    np.testing.assert_allclose(teme[..., 3:], v, rtol=0, atol=1e-9)  # km/s
    for i, sat in enumerate(sats):  # and object by object, epoch by epoch
        for k in range(0, t.size, 41):
            e1, r1, v1 = sat.sgp4(jd[k], fr[k])
            assert e1 == 0
            np.testing.assert_allclose(teme[i, k, :3], r1, rtol=0, atol=1e-6)
            np.testing.assert_allclose(teme[i, k, 3:], v1, rtol=0, atol=1e-9)
    np.testing.assert_allclose(states.x[0, 0], frames.teme_to_gcrs([*r[0, 0], *v[0, 0]], t[0]),
                               rtol=0, atol=1e-9)


def test_epoch_in_unix_seconds():
    entry = catalog.parse_tle(f"{L1}\n{L2}\n")[0]
    # 2006 day 177.78615833 = 2006-06-26 18:52:04.08 UTC
    expected = dt.datetime(2006, 6, 26, tzinfo=dt.UTC).timestamp() + 0.78615833 * 86400
    assert entry.epoch_unix == pytest.approx(expected, abs=1e-4)
    jd, fr = timescales.jd_utc([entry.epoch_unix])
    assert jd[0] == entry.satrec.jdsatepoch
    assert fr[0] == pytest.approx(entry.satrec.jdsatepochF, abs=1e-11)


@pytest.mark.parametrize("path", [OMM_XML, OMM_CSV], ids=["xml", "csv"])
def test_omm_sample_reads_as_the_same_element_set(path):
    (entry,) = catalog.read_catalog(path)
    (tle,) = [e for e in catalog.read_catalog(SAMPLE) if e.object_id == "28057"]
    assert (entry.object_id, entry.name) == ("28057", "CBERS 2")
    t = tle.epoch_unix + np.linspace(0.0, 86400.0, 7)
    x_omm = catalog_states([entry], t).x
    x_tle = catalog_states([tle], t).x
    np.testing.assert_allclose(x_omm, x_tle, rtol=0, atol=1e-3)  # OMM epoch to the us


def test_decayed_object_gives_nan_and_its_error_code():
    # MINOTAUR R/B of SGP4-VER.TLE: sub-orbital, lost within 60 min of its epoch
    text = ("1 28872U 05037B   05333.02012661  .25992681  00000-0  24476-3 0  1534\n"
            "2 28872  96.4736 157.9986 0303955 244.0492 110.6523 16.46015938 10708\n")
    (entry,) = catalog.parse_tle(text)
    states = catalog_states([entry], entry.epoch_unix + np.array([0.0, 86400.0]))
    assert states.error[0, 0] == 0 and np.isfinite(states.x[0, 0]).all()
    assert states.error[0, 1] != 0 and np.isnan(states.x[0, 1]).all()


def test_space_track_3le_name_line_and_comments():
    entries = catalog.parse_tle(f"# a comment\n\n0 CBERS 2\n{L1}\n{L2}\n")
    assert (entries[0].name, entries[0].source) == ("CBERS 2", "<string>:4")


MALFORMED = {
    "checksum": (f"{L1[:-1]}7\n{L2}\n", r"f\.tle:1: TLE line 1 fails its checksum"),
    "short": (f"{L1[:40]}\n{L2}\n", r"f\.tle:1: TLE line 1 has 40 columns"),
    "letter": (f"X\n{L1}\n{L2.replace('98.4283', '9x.4283')}\n",
               r"f\.tle:3: TLE line 2, column 11"),
    "no line 2": (f"X\n{L1}\nY\n", r"f\.tle:2: TLE line 1 is not followed by its line 2"),
    "line 2 alone": (f"{L2}\n", r"f\.tle:1: TLE line 2 without a line 1"),
    "dangling name": (f"{L1}\n{L2}\nLONELY\n", r"f\.tle:3: name line 'LONELY' at the end"),
    "numbers differ": (f"{L1[:68]}\n{L2.replace('2 28057', '2 28058')[:68]}\n",  # no checksum
                       r"f\.tle:1: catalogue numbers of lines 1 and 2 differ"),
    "twice": (f"{L1}\n{L2}\n\n{L1}\n{L2}\n", r"f\.tle:4: object 28057 is already .*f\.tle:1"),
    "empty": ("# nothing\n", r"f\.tle: no element sets"),
    "kvn": ("CCSDS_OMM_VERS = 2.0\n", r"f\.tle: OMM in KVN is not supported"),
    "csv lacks": ("OBJECT_NAME,NORAD_CAT_ID\nX,5\n", r"f\.tle:2: OMM lacks OBJECT_ID, EPOCH"),
    "csv frame": (OMM_CSV.read_text().replace(",TEME,", ",GCRF,"),
                  r"f\.tle:4: OMM REF_FRAME is GCRF"),
    "csv number": (OMM_CSV.read_text().replace(",14.3547808,", ",fast,"),
                   r"f\.tle:4: malformed OMM field"),
    "xml": ("<ndm>\n<omm>\n<body>\n</omm>", r"f\.tle:4: not well-formed XML"),
    "xml block": ("<ndm><omm><body><segment><metadata/></segment></body></omm></ndm>",
                  r"f\.tle: an OMM segment lacks"),
    "xml field": (OMM_XML.read_text().replace("<BSTAR>3.594e-05</BSTAR>", ""),
                  r"f\.tle:segment 1: OMM lacks BSTAR"),
}


@pytest.mark.parametrize("text,match", MALFORMED.values(), ids=MALFORMED.keys())
def test_malformed_catalog_is_one_value_error_naming_the_line(tmp_path, text, match):
    path = tmp_path / "f.tle"
    path.write_text(text)
    with pytest.raises(ValueError, match=match):
        catalog.read_catalog(path)


def test_missing_file_is_a_value_error(tmp_path):
    with pytest.raises(ValueError, match="cannot read catalog"):
        catalog.read_catalog(tmp_path / "none.tle")

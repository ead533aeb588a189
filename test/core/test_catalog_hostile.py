"""Hostile element-set files: every reader refuses a field outside its domain in one bounded
line naming file and line, and no input ends in anything but entries or that ValueError.

The named cases are those of a hostile-input probe of the catalog readers (NaN and infinite
angles, an infinite mean motion, B* = 1e9, an inclination of 999 deg, a misread Alpha-5
number, a two-letter classification, a huge ELEMENT_SET_NO, a CSV field over csv's limit,
an OMM with empty blocks, an epoch in 2100); the property tests throw mutated and random
text at each reader (hypothesis).
"""

from __future__ import annotations

from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from sgp4.io import compute_checksum

from ssa_fusion.formats import element_sets as catalog

L1 = "1 25544U 98067A   20001.82137887  .00016717  00000-0  10270-3 0  9127"
L2 = "2 25544  51.6392  96.6358 0005156  88.7140 271.4601 15.49497216  6061"
HEADER = ("OBJECT_NAME,OBJECT_ID,EPOCH,MEAN_MOTION,ECCENTRICITY,INCLINATION,RA_OF_ASC_NODE,"
          "ARG_OF_PERICENTER,MEAN_ANOMALY,EPHEMERIS_TYPE,CLASSIFICATION_TYPE,NORAD_CAT_ID,"
          "ELEMENT_SET_NO,REV_AT_EPOCH,BSTAR,MEAN_MOTION_DOT,MEAN_MOTION_DDOT")
ROW = ("ISS,1998-067A,2019-12-31T19:42:47.134368,15.49497216,.0005156,51.6392,96.6358,"
       "88.7140,271.4601,0,U,25544,912,606,.1027e-3,.00016717,0")
OMM_XML = ("<ndm><omm><body><segment><metadata><OBJECT_NAME>ISS</OBJECT_NAME>"
           "<OBJECT_ID>1998-067A</OBJECT_ID><CENTER_NAME>EARTH</CENTER_NAME><REF_FRAME>TEME"
           "</REF_FRAME><TIME_SYSTEM>UTC</TIME_SYSTEM></metadata><data><meanElements>"
           "<EPOCH>2019-12-31T19:42:47.134368</EPOCH><MEAN_MOTION>15.49497216</MEAN_MOTION>"
           "<ECCENTRICITY>.0005156</ECCENTRICITY><INCLINATION>51.6392</INCLINATION>"
           "<RA_OF_ASC_NODE>96.6358</RA_OF_ASC_NODE><ARG_OF_PERICENTER>88.7140"
           "</ARG_OF_PERICENTER><MEAN_ANOMALY>271.4601</MEAN_ANOMALY></meanElements>"
           "<tleParameters><EPHEMERIS_TYPE>0</EPHEMERIS_TYPE><CLASSIFICATION_TYPE>U"
           "</CLASSIFICATION_TYPE><NORAD_CAT_ID>25544</NORAD_CAT_ID><ELEMENT_SET_NO>912"
           "</ELEMENT_SET_NO><REV_AT_EPOCH>606</REV_AT_EPOCH><BSTAR>.1027e-3</BSTAR>"
           "<MEAN_MOTION_DOT>.00016717</MEAN_MOTION_DOT><MEAN_MOTION_DDOT>0</MEAN_MOTION_DDOT>"
           "</tleParameters></data></segment></body></omm></ndm>\n")
MAX_MESSAGE = 400
"""Longest error message allowed (one line a user can read)."""


def checked(line: str) -> str:
    """`line` (68 columns of a TLE line) with its checksum column."""
    return line[:68] + str(compute_checksum(line[:68]))


def tle(line1: str = L1, line2: str = L2) -> str:
    return f"{checked(line1)}\n{checked(line2)}\n"


def csv_of(*rows: str) -> str:
    return "\n".join([HEADER, *rows]) + "\n"


def refused(tmp_path: Path, name: str, text: str) -> str:
    """The one-line ValueError `read_catalog` gives for `text`, written to file `name`."""
    path = tmp_path / name
    path.write_text(text)
    with pytest.raises(ValueError) as err:
        catalog.read_catalog(path)
    message = str(err.value)
    assert "\n" not in message and len(message) <= MAX_MESSAGE, message
    assert message.startswith(str(path)), message
    return message


@pytest.mark.parametrize(("name", "text", "expected"), [
    ("alpha.tle", tle(L1.replace("25544", "1A2B3"), L2.replace("25544", "1A2B3")),
     "neither digits nor Alpha-5"),
    ("incl.tle", tle(L1, L2[:8] + "999.0000" + L2[16:]),
     "inclination 999 deg outside [0, 180]"),
    ("bstar.tle", tle(L1[:53] + " 10000+9" + L1[61:]), "B* 1e+08"),
    # SGP4 reads day 999 of 2019 as a day in 2022 and day 000 as 31 December 2018
    ("day999.tle", tle(L1[:20] + "999" + L1[23:]), "day 999.821 of 2020 is not in 1-366"),
    ("day000.tle", tle(L1[:20] + "000" + L1[23:]), "day 0.821379 of 2020 is not in 1-366"),
    ("nan.csv", csv_of(ROW.replace("51.6392", "nan")), "inclination not finite"),
    ("inf.csv", csv_of(ROW.replace("15.49497216", "inf")), "mean motion"),
    ("fast.csv", csv_of(ROW.replace("15.49497216", "25.0")), "decayed"),  # SGP4's own
    ("uu.csv", csv_of(ROW.replace(",U,", ",UU,")), "CLASSIFICATION_TYPE 'UU'"),
    ("elset.csv", csv_of(ROW.replace(",912,", ",99999999999999999999,")),
     "ELEMENT_SET_NO '99999999999999999999' is not an integer in 0..9999"),
    ("norad.csv", csv_of(ROW.replace(",25544,", ",-5,")), "NORAD_CAT_ID"),
    ("epoch.csv", csv_of(ROW.replace("2019-12-31", "2100-06-01")),
     "epoch 2100-06-01T19:42:47.134Z is outside the range ssa_fusion represents"),
    ("big.csv", csv_of(ROW.replace("ISS", "X" * 200_000)), "unreadable CSV row"),
    # one-line files of 3 MB ("a 100 MB one-line catalog's error line is 100 MB long")
    ("oneline.tle", "1 " + "x" * 3_000_000, ":1: TLE line 1 is not followed by its line 2"),
    ("oneline.csv", "NORAD_CAT_ID," + "x" * 3_000_000, "field larger than field limit"),
    ("oneline.xml", "<ndm>" + "x" * 3_000_000, ":1: not well-formed XML"),
    # a 3 MB name line was taken as the name, or quoted whole when no TLE followed it
    ("longname.tle", "x" * 3_000_000 + "\n" + tle(), ":1: name line: an object name of "
                                                    "3000000 characters (at most 128)"),
    ("longname.csv", csv_of(ROW.replace("ISS", "X" * 100_000)),
     ":2: OMM OBJECT_NAME: an object name of 100000 characters"),
    ("empty.xml", '<?xml version="1.0"?><ndm><omm><body><segment><metadata></metadata>'
                  "<data></data></segment></body></omm></ndm>", "lacks (or has empty)"),
    # SGP4 reads day 366 of a common year as the next 1 January
    ("day366.tle", tle(L1[:18] + "19366" + L1[23:]), "day 366.821 of 2019 is not in 1-365"),
    # control characters in names were stored in bags and echoed raw to terminals
    ("nul.tle", "ISS\x00 (ZARYA)\n" + tle(), ":1: name line: an object name with control"),
    ("escape.csv", csv_of(ROW.replace("ISS", "ISS\x1b[31mRED")), "with control characters"),
    # catalogue number 00000 became object "0"
    ("zero.tle", tle(L1.replace("25544", "00000"), L2.replace("25544", "00000")),
     "catalogue number 0 is no object's"),
    ("zero.csv", csv_of(ROW.replace(",25544,", ",0,")), "NORAD_CAT_ID '0' is not an integer"),
    # full-width digits are digits to Python's int() and float()
    ("fullwidth.csv", csv_of(ROW.replace(",25544,", ",２５５４４,")), "NORAD_CAT_ID"),
    ("fullwidth_mm.csv", csv_of(ROW.replace("15.49497216", "１５.49497216")),
     "MEAN_MOTION '１５.49497216' is not ASCII"),
    # an XInclude (never processed) in OBJECT_NAME gave an empty name
    ("xinclude.xml", OMM_XML.replace("<OBJECT_NAME>ISS</OBJECT_NAME>",
                                     '<OBJECT_NAME><xi:include xmlns:xi="http://www.w3.org/2001/'
                                     'XInclude" href="/etc/hostname"/></OBJECT_NAME>'),
     "OMM OBJECT_NAME holds XML elements"),
])
def test_a_field_outside_its_domain_is_refused_in_one_line(tmp_path, name, text, expected):
    assert expected in refused(tmp_path, name, text)


def test_the_same_element_sets_within_their_domains_are_read(tmp_path):
    (tmp_path / "ok.tle").write_text(tle())
    (tmp_path / "ok.csv").write_text(csv_of(ROW))
    (tmp_path / "alpha5.tle").write_text(tle(L1.replace("25544", "A0001"),
                                             L2.replace("25544", "A0001")))
    assert [e.object_id for e in catalog.read_catalog(tmp_path / "ok.tle")] == ["25544"]
    assert [e.object_id for e in catalog.read_catalog(tmp_path / "ok.csv")] == ["25544"]
    assert [e.object_id for e in catalog.read_catalog(tmp_path / "alpha5.tle")] == ["100001"]
    (tmp_path / "ok.xml").write_text(OMM_XML)
    (tmp_path / "leap.tle").write_text(tle(L1[:18] + "20366" + L1[23:]))  # 2020 is a leap year
    assert [e.name for e in catalog.read_catalog(tmp_path / "ok.xml")] == ["ISS"]
    assert len(catalog.read_catalog(tmp_path / "leap.tle")) == 1


def _only_value_errors(parse, text: str) -> None:
    """`parse(text)` gives entries or a bounded one-line ValueError, nothing else."""
    try:
        entries = parse(text, "fuzz")
    except ValueError as exc:
        assert "\n" not in str(exc) and len(str(exc)) <= MAX_MESSAGE, str(exc)[:200]
        return
    for e in entries:  # what is taken is within its domain
        assert 0.0 <= e.satrec.inclo <= 3.1416 and 0.0 <= e.satrec.ecco < 1.0


FUZZ = settings(max_examples=150, deadline=None, derandomize=True,
                suppress_health_check=[HealthCheck.too_slow])


@FUZZ
@given(st.lists(st.tuples(st.integers(0, 68), st.characters(min_codepoint=32,
                                                            max_codepoint=126)),
                max_size=6), st.booleans())
def test_mutated_tle_lines_give_entries_or_one_valueerror(edits, second):
    lines = [L1, L2]
    k = 1 if second else 0
    line = list(lines[k])
    for col, c in edits:
        line[col] = c
    lines[k] = "".join(line)
    _only_value_errors(catalog.parse_tle, "\n".join(lines) + "\n")


@FUZZ
@given(st.integers(0, 16), st.text(max_size=40))
def test_mutated_omm_csv_fields_give_entries_or_one_valueerror(field, value):
    row = ROW.split(",")
    row[field] = value.replace(",", ";").replace("\n", " ").replace("\r", " ")
    _only_value_errors(catalog.parse_omm_csv, csv_of(",".join(row)))


@FUZZ
@given(st.text(max_size=300))
def test_random_text_gives_entries_or_one_valueerror(text):
    for parse in (catalog.parse_tle, catalog.parse_omm_csv, catalog.parse_omm_xml):
        _only_value_errors(parse, text)

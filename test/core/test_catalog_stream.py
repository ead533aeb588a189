"""Catalogs read as a stream (formats.element_sets.read_catalog): the same entries and errors as the
whole text parsed at once, a progress callback, memory that does not grow with the file.

The references are the readers that parsed the whole text at once (`whole_read`, with
`whole_csv` and `whole_xml`: `sgp4.omm.parse_xml`, expat's tree of the whole document),
kept here as they were, and element sets made by `sgp4` itself from the same lines or
fields.
"""

from __future__ import annotations

import contextlib
import csv
import io
import itertools
import re
import tracemalloc
import xml.etree.ElementTree as ET
from collections.abc import Callable, Iterator
from pathlib import Path
from unittest import mock

import pytest
from fuzz_text import mutated
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from sgp4 import omm
from sgp4.api import Satrec
from sgp4.io import compute_checksum

from ssa_fusion.core.motion.element_sets import CatalogEntry
from ssa_fusion.formats import element_set_checks, tle
from ssa_fusion.formats import element_sets as catalog
from ssa_fusion.formats import omm as omm_reader

ROOT = Path(__file__).resolve().parents[2]
CATALOGS = sorted(p for p in (ROOT / "config" / "catalogs").iterdir()
                  if p.name != "bad_sets.tle")  # refused whole here: test_skipped_sets
L1 = "1 25544U 98067A   20001.82137887  .00016717  00000-0  10270-3 0  9127"
L2 = "2 25544  51.6392  96.6358 0005156  88.7140 271.4601 15.49497216  6061"
HEADER = ("OBJECT_NAME,OBJECT_ID,EPOCH,MEAN_MOTION,ECCENTRICITY,INCLINATION,RA_OF_ASC_NODE,"
          "ARG_OF_PERICENTER,MEAN_ANOMALY,EPHEMERIS_TYPE,CLASSIFICATION_TYPE,NORAD_CAT_ID,"
          "ELEMENT_SET_NO,REV_AT_EPOCH,BSTAR,MEAN_MOTION_DOT,MEAN_MOTION_DDOT")
ALPHA5 = "ABCDEFGHJKLMNPQRSTUVWXYZ"
SATREC = ("satnum", "jdsatepoch", "jdsatepochF", "no_kozai", "ecco", "inclo", "nodeo", "argpo",
          "mo", "bstar", "ndot", "nddot", "classification", "intldesg", "elnum", "revnum",
          "ephtype")
"""What an element set is made of (`sgp4.api.Satrec` attributes)."""


# ------------------------------------------------------------------------------------------
# the readers that parsed the whole text at once
# ------------------------------------------------------------------------------------------
def whole_read(path: Path) -> list[CatalogEntry]:
    """`read_catalog` as it read a file: its whole text at once."""
    try:
        text = path.read_text()
    except (OSError, UnicodeDecodeError) as exc:
        raise ValueError(f"{path}: cannot read catalog: {exc}") from None
    head = next((s.strip() for s in text.splitlines()
                 if s.strip() and not s.startswith("#")), "")
    if head.startswith("<"):
        entries = whole_xml(text, str(path))
    elif head.startswith("CCSDS_OMM_VERS"):
        raise ValueError(f"{path}: OMM in KVN is not supported (sgp4 reads OMM as XML or "
                         f"CSV); convert it to one of those")
    elif "NORAD_CAT_ID" in head.split(","):
        entries = whole_csv(text, str(path))
    else:
        entries = catalog.parse_tle(text, str(path))
    if not entries:
        raise ValueError(f"{path}: no element sets in the file")
    return entries


def whole_xml(text: str, source: str) -> list[CatalogEntry]:
    """`parse_omm_xml` as it was: `sgp4.omm.parse_xml` of the whole document, then each."""
    try:
        segments = list(omm.parse_xml(io.StringIO(text)))
    except ET.ParseError as exc:
        line, col = exc.position
        raise ValueError(f"{source}:{line}: not well-formed XML (column {col + 1})") from None
    except (AttributeError, TypeError, KeyError):
        raise ValueError(f"{source}: an OMM segment lacks (or has empty) metadata, data, "
                         f"meanElements or tleParameters") from None
    seen: dict[str, str] = {}
    out = []
    for k, fields in enumerate(segments, 1):
        entry = omm_reader.omm_entry(fields, f"{source}:segment {k}")
        element_set_checks.check_new(entry, seen)
        out.append(entry)
    return out


def whole_csv(text: str, source: str) -> list[CatalogEntry]:
    """`parse_omm_csv` as it was: every line in a list, then csv over them."""
    numbered = list(element_set_checks.numbered(text.splitlines()))
    rows = csv.DictReader(line for _, line in numbered)
    seen: dict[str, str] = {}
    out = []
    k = 0
    try:
        for k, fields in enumerate(rows, 1):
            where = f"{source}:{numbered[k][0]}"
            if None in fields:
                raise ValueError(f"{where}: more values than the header has columns")
            entry = omm_reader.omm_entry(dict(fields), where)
            element_set_checks.check_new(entry, seen)
            out.append(entry)
    except csv.Error as exc:
        line = numbered[min(k + 1, len(numbered) - 1)][0] if numbered else 0
        raise ValueError(f"{source}:{line}: unreadable CSV row: {exc}") from None
    return out


# ------------------------------------------------------------------------------------------
# comparing
# ------------------------------------------------------------------------------------------
def key(e: CatalogEntry) -> tuple[object, ...]:
    """What makes an entry: id, name, where it was read and its element set, exactly."""
    return (e.object_id, e.name, e.source, *(getattr(e.satrec, a) for a in SATREC))


def outcome(read: Callable[[], list[CatalogEntry]]) -> tuple[str, object]:
    """("entries", their keys) or ("error", its message) of `read()`.

    XML that is not well formed is said without its line and column: the stream is read by
    lxml (libxml2), the whole text was by expat, and the two may see the fault at
    different places.
    """
    try:
        return "entries", [key(e) for e in read()]
    except ValueError as exc:
        return "error", re.sub(r":\d+: not well-formed XML \(column \d+\)$",
                               ": not well-formed XML", str(exc))


@contextlib.contextmanager
def chunks_of(n: int) -> Iterator[None]:
    """Read files `n` bytes at a time: lines, characters and elements cut by chunks."""
    with mock.patch.object(catalog, "CHUNK_BYTES", n):
        yield


# ------------------------------------------------------------------------------------------
# generated catalogs
# ------------------------------------------------------------------------------------------
def checked(line: str) -> str:
    """`line` (68 columns of a TLE line) with its checksum column."""
    return line[:68] + str(compute_checksum(line[:68]))


def tle_lines(i: int) -> tuple[str, str]:
    """TLE lines of object `i` (NORAD number `i`, Alpha-5 from 100000): the ISS's element set
    with its node and mean anomaly turned."""
    num = f"{i:05d}" if i < 100_000 else ALPHA5[i // 10_000 - 10] + f"{i % 10_000:04d}"
    raan, anomaly = (96.6358 + 0.37 * i) % 360.0, (271.4601 + 7.1 * i) % 360.0
    line2 = f"{L2[:2]}{num}{L2[7:17]}{raan:8.4f}{L2[25:43]}{anomaly:8.4f}{L2[51:]}"
    return checked(f"{L1[:2]}{num}{L1[7:]}"), checked(line2)


def three_le(n: int, newline: str = "\n") -> str:
    """A 3LE of `n` objects (names with a character of two UTF-8 bytes), comments between."""
    out = ["# generated", ""]
    for i in range(1, n + 1):
        a, b = tle_lines(i)
        out += [f"OBJECT {i} Ω", a, b] + (["# a comment", ""] if i % 7 == 3 else [])
    return newline.join(out) + newline


def csv_rows(n: int) -> str:
    """An OMM CSV of `n` objects."""
    rows = [f"OBJECT {i} Ω,1998-067A,2019-12-31T19:42:47.134368,15.49497216,.0005156,"
            f"51.6392,{(96.6358 + 0.37 * i) % 360.0:.4f},88.7140,"
            f"{(271.4601 + 7.1 * i) % 360.0:.4f},0,U,{i},912,606,.1027e-3,.00016717,0"
            for i in range(1, n + 1)]
    return "\n".join(["# generated", HEADER, *rows]) + "\n"


def segment(i: int) -> str:
    """One OMM XML segment of object `i`."""
    return (f"<segment><metadata><OBJECT_NAME>OBJECT {i} Ω</OBJECT_NAME>"
            f"<OBJECT_ID>1998-067A</OBJECT_ID><CENTER_NAME>EARTH</CENTER_NAME>"
            f"<REF_FRAME>TEME</REF_FRAME><TIME_SYSTEM>UTC</TIME_SYSTEM></metadata>\n<data>"
            f"<meanElements><EPOCH>2019-12-31T19:42:47.134368</EPOCH>"
            f"<MEAN_MOTION>15.49497216</MEAN_MOTION><ECCENTRICITY>.0005156</ECCENTRICITY>"
            f"<INCLINATION>51.6392</INCLINATION>"
            f"<RA_OF_ASC_NODE>{(96.6358 + 0.37 * i) % 360.0:.4f}</RA_OF_ASC_NODE>"
            f"<ARG_OF_PERICENTER>88.7140</ARG_OF_PERICENTER>"
            f"<MEAN_ANOMALY>{(271.4601 + 7.1 * i) % 360.0:.4f}</MEAN_ANOMALY></meanElements>\n"
            f"<tleParameters><EPHEMERIS_TYPE>0</EPHEMERIS_TYPE>"
            f"<CLASSIFICATION_TYPE>U</CLASSIFICATION_TYPE><NORAD_CAT_ID>{i}</NORAD_CAT_ID>"
            f"<ELEMENT_SET_NO>912</ELEMENT_SET_NO><REV_AT_EPOCH>606</REV_AT_EPOCH>"
            f"<BSTAR>.1027e-3</BSTAR><MEAN_MOTION_DOT>.00016717</MEAN_MOTION_DOT>"
            f"<MEAN_MOTION_DDOT>0</MEAN_MOTION_DDOT></tleParameters></data></segment>\n")


def xml_doc(n: int) -> str:
    """An OMM XML (NDM) of `n` objects."""
    return ('<?xml version="1.0" encoding="UTF-8"?>\n<ndm><omm><header><ORIGINATOR>test'
            '</ORIGINATOR></header><body>\n' + "".join(segment(i) for i in range(1, n + 1)) +
            "</body></omm></ndm>\n")


GENERATED = {"3le": three_le, "3le_crlf": lambda n: three_le(n, "\r\n"),
             "3le_cr": lambda n: three_le(n, "\r"), "csv": csv_rows, "xml": xml_doc,
             "xml_junk": lambda n: xml_doc(n).replace(
                 "</segment>\n", "</segment>\n" + "<x><y>not OMM</y><z/></x>" * 20)}
"""Generated catalogs of n objects, by kind."""


# ------------------------------------------------------------------------------------------
# the same entries and errors as the whole text
# ------------------------------------------------------------------------------------------
def sgp4_reference(path: Path) -> list[tuple[str, str, Satrec]]:
    """(object id, name, element set) of every object of a catalog, made by `sgp4` alone."""
    text = path.read_text()
    lines = [s.strip() for s in text.splitlines() if s.strip() and not s.startswith("#")]
    if lines[0].startswith("<"):
        segments = list(omm.parse_xml(io.StringIO(text)))
    elif "NORAD_CAT_ID" in lines[0].split(","):
        segments = list(csv.DictReader(lines))
    else:
        out = []
        for k, line in enumerate(lines):
            if line.startswith("1 "):
                name = lines[k - 1] if k and not lines[k - 1].startswith("2 ") else ""
                sat = Satrec.twoline2rv(line, lines[k + 1])
                out.append((str(sat.satnum), name.removeprefix("0 ").strip(), sat))
        return out
    out = []
    for fields in segments:
        sat = Satrec()
        omm.initialize(sat, fields)
        out.append((fields["NORAD_CAT_ID"], fields["OBJECT_NAME"], sat))
    return out


@pytest.mark.parametrize("path", CATALOGS, ids=[p.name for p in CATALOGS])
def test_sample_catalogs_read_as_a_stream_give_the_entries_of_the_whole_text(path):
    got = catalog.read_catalog(path)
    assert outcome(lambda: got) == outcome(lambda: whole_read(path))
    want = sgp4_reference(path)
    assert len(got) == len(want) >= 1
    for e, (oid, name, sat) in zip(got, want, strict=True):
        assert (e.object_id, e.name) == (oid, name)
        assert [getattr(e.satrec, a) for a in SATREC] == [getattr(sat, a) for a in SATREC]
    with chunks_of(61):  # every line and segment cut by a chunk's end somewhere
        assert outcome(lambda: catalog.read_catalog(path)) == outcome(lambda: got)


@pytest.mark.parametrize("kind", GENERATED)
@pytest.mark.parametrize("chunk", [7, 4096, catalog.CHUNK_BYTES])
def test_generated_catalogs_read_as_a_stream_give_the_entries_of_the_whole_text(
        tmp_path, kind, chunk):
    path = tmp_path / f"gen.{kind}"
    path.write_bytes(GENERATED[kind](3000).encode())
    with chunks_of(chunk):
        got = outcome(lambda: catalog.read_catalog(path))
    assert got[0] == "entries" and len(got[1]) == 3000  # type: ignore[arg-type]
    assert got == outcome(lambda: whole_read(path))
    want = sgp4_reference(path)
    assert [k[3:] for k in got[1]] == [  # type: ignore[union-attr]
        tuple(getattr(sat, a) for a in SATREC) for _, _, sat in want]
    assert {k[1] for k in got[1]} == {f"OBJECT {i} Ω" for i in range(1, 3001)}  # type: ignore


FUZZ = settings(max_examples=200, deadline=None, derandomize=True,
                suppress_health_check=[HealthCheck.too_slow])
SMALL = {"3le": three_le(3), "csv": csv_rows(3), "xml": xml_doc(3)}
TOKENS = ["\n", "\r\n", "\r", "#", "0 ", "1 ", "2 ", ",", '"', "\u2028", "\x0c", "Ω",
          "<segment>", "</segment>", "<metadata/>", "<data>", "</data>", "<!-- c -->", "&amp;",
          "<segment><metadata/></segment>", "NORAD_CAT_ID", "CCSDS_OMM_VERS", "<", ">",
          "]]>", "<?xml version='1.0'?>"]


@FUZZ
@given(st.sampled_from(sorted(SMALL)).flatmap(lambda kind: mutated(SMALL[kind], TOKENS)),
       st.sampled_from([1, 5, 64]))
def test_mutated_files_read_as_a_stream_give_what_the_whole_text_gives(
        tmp_path_factory, text, chunk):
    """Any text (lines cut anywhere by chunks, every line break str.splitlines knows):
    the entries, or the error, of the reader that took the whole text at once."""
    path = tmp_path_factory.mktemp("fuzz") / "f.cat"
    path.write_bytes(text.encode("utf-8", "surrogatepass"))
    with chunks_of(chunk):
        got = outcome(lambda: catalog.read_catalog(path))
    assert got == outcome(lambda: whole_read(path))


@FUZZ
@given(mutated(xml_doc(3), TOKENS))
def test_mutated_xml_gives_the_entries_or_the_error_of_the_whole_document(text):
    """Errors in the order the whole document gave them: not well formed anywhere first,
    then a segment lacking a block (also inside another), then the first bad segment."""
    assert outcome(lambda: catalog.parse_omm_xml(text, "f")) == \
        outcome(lambda: whole_xml(text, "f"))


def doc(*segments: str, tail: str = "") -> str:
    """An OMM XML (NDM) of `segments`, `tail` after its root."""
    return "<ndm><omm><body>\n" + "".join(segments) + "</body></omm></ndm>\n" + tail


BAD_ID = segment(7).replace("<NORAD_CAT_ID>7<", "<NORAD_CAT_ID>x<")
LACKING = segment(1).replace("meanElements>", "x>")
NESTED = segment(7).replace("<metadata>", "<metadata>" + segment(5), 1)
"""Object 7, whose metadata holds a segment of object 5."""


@pytest.mark.parametrize("text,match", [
    (doc(BAD_ID, segment(1), tail="<junk/>"), r"^f:\d+: not well-formed XML"),
    (doc(BAD_ID, segment(2), LACKING), r"^f: an OMM segment lacks"),
    (doc(segment(2), BAD_ID, LACKING[:-20]), r"^f:\d+: not well-formed XML"),
    (doc(segment(2), NESTED.replace("<NORAD_CAT_ID>5<", "<NORAD_CAT_ID>2<")),
     r"^f:segment 3: object 2 is already in the catalog \(f:segment 1\)"),
    (doc(segment(2), NESTED.replace("<NORAD_CAT_ID>5<", "<NORAD_CAT_ID>x<", 1), LACKING),
     r"^f: an OMM segment lacks"),
], ids=["bad then not well formed", "bad then lacking", "lacking then not well formed",
        "nested twice", "nested bad then lacking"])
def test_xml_errors_come_in_the_order_of_the_whole_document(text, match):
    with pytest.raises(ValueError, match=match):
        catalog.parse_omm_xml(text, "f")
    assert outcome(lambda: catalog.parse_omm_xml(text, "f")) == \
        outcome(lambda: whole_xml(text, "f"))


def test_a_segment_inside_another_is_counted_in_document_order():
    entries = catalog.parse_omm_xml(doc(segment(2), NESTED, segment(1)), "f")
    assert [(e.object_id, e.source) for e in entries] == [
        ("2", "f:segment 1"), ("7", "f:segment 2"), ("5", "f:segment 3"), ("1", "f:segment 4")]


@pytest.mark.parametrize("at", [0, 100, 70_000, 200_000])
@pytest.mark.parametrize("bad", [b"\xff", b"\xe2\x82", b"\xc3"])
def test_bytes_that_are_not_text_are_said_as_the_whole_text_said_them(tmp_path, at, bad):
    """Wherever they are (even after a line the reader refuses), with their position in
    bytes from the start of the file."""
    data = three_le(1500).encode()
    data = data[:at] + bad + data[at:]
    refused = data.replace(b"2 00000  51", b"2 00000  5x", 1)  # the first object refused
    for i, content in enumerate((data, refused)):
        path = tmp_path / f"bytes{i}.tle"
        path.write_bytes(content)
        got = outcome(lambda p=path: catalog.read_catalog(p))
        assert got == outcome(lambda p=path: whole_read(p))
        assert got[0] == "error" and "cannot read catalog: 'utf-8' codec can't decode" in \
            str(got[1]) and f"position {at}" in str(got[1])


# ------------------------------------------------------------------------------------------
# progress, errors deep in a big file, memory
# ------------------------------------------------------------------------------------------
@pytest.mark.parametrize("kind", ["3le_crlf", "csv", "xml"])
def test_progress_is_called_with_monotone_bytes_ending_at_the_file_size(tmp_path, kind):
    n = 3 * catalog.PROGRESS_EVERY + 5
    path = tmp_path / f"big.{kind}"
    path.write_bytes(GENERATED[kind](n).encode())
    size = path.stat().st_size
    calls: list[tuple[int, int, int]] = []
    with chunks_of(8192):
        entries = catalog.read_catalog(path, progress=lambda *c: calls.append(c))
    assert len(entries) == n
    assert [c[2] for c in calls] == [catalog.PROGRESS_EVERY * k for k in (1, 2, 3)] + [n]
    assert all(c[1] == size for c in calls)
    done = [c[0] for c in calls]
    assert done[0] > 0 and all(a <= b for a, b in itertools.pairwise(done)) and done[-1] == size
    # and the bytes grow as the objects do (read as they are parsed, not all before)
    assert done[0] < 0.5 * size


@pytest.mark.parametrize("kind", ["3le", "csv"])
def test_an_error_in_object_50000_of_a_big_file_names_its_line(tmp_path, kind):
    n, bad = 50_001, 50_000  # object 50,000 (objects are numbered from 1)
    text = GENERATED[kind](n)
    if kind == "3le":
        good = tle_lines(bad)[1]
        wrong, what = good[:10] + "x" + good[11:], "TLE line 2, column 11"
    else:
        good = next(r for r in text.splitlines() if f",U,{bad}," in r)
        wrong, what = good.replace(",U,", ",UU,"), "OMM CLASSIFICATION_TYPE 'UU'"
    text = text.replace(good, wrong)
    line = text.splitlines().index(wrong) + 1
    path = tmp_path / f"big.{kind}"
    path.write_text(text)
    with pytest.raises(ValueError) as err:
        catalog.read_catalog(path)
    assert str(err.value).startswith(f"{path}:{line}: {what}"), str(err.value)
    # 3 lines an object and comments after every 7th; a header and a comment before the rows
    assert line == (3 * bad + 2 * ((bad - 1 - 3) // 7 + 1) + 2 if kind == "3le" else bad + 2)


def transient(path: Path, n: int) -> int:
    """Python memory a read of `path` (`n` objects) held at its peak beyond its entries."""
    tracemalloc.start()
    try:
        entries = catalog.read_catalog(path)
        held, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert len(entries) == n
    return peak - held


@pytest.mark.parametrize("kind", ["3le", "csv", "xml"])
def test_a_read_holds_its_entries_and_what_does_not_grow_with_the_file(tmp_path, kind):
    """Python memory at the peak of a read beyond what its entries hold at the end: a few
    chunks, about as much for a file four times as large (its text alone would grow as the
    file, its lines more)."""
    n = {"3le": 3000, "csv": 3000, "xml": 1000}[kind]
    sizes, extra = [], []
    for objects in (n, 4 * n):
        path = tmp_path / f"{objects}.{kind}"
        path.write_text(GENERATED[kind](objects))
        sizes.append(path.stat().st_size)
        extra.append(transient(path, objects))
    assert sizes[1] > 4 * catalog.CHUNK_BYTES
    # the ids seen (to refuse one twice) grow with the objects; no text does
    assert extra[1] - extra[0] < 0.35 * (sizes[1] - sizes[0]), (extra, sizes)


# ------------------------------------------------------------------------------------------
# the TLE layout checked by a pattern first
# ------------------------------------------------------------------------------------------
def columns_one_by_one(line: str, template: str, which: int, where: str) -> None:
    """`_check_columns` as it was: every column in turn, the checksum by `sgp4`."""
    if not line.isascii():
        raise ValueError(f"{where}: TLE line {which} has non-ASCII characters")
    if len(line) not in (68, 69):
        raise ValueError(f"{where}: TLE line {which} has {len(line)} columns, not 69")
    number = line[2:7]
    if not ((number.strip().isdigit() and number == number.strip().rjust(5))
            or (number[0] in ALPHA5 and number[1:].isdigit())):
        raise ValueError(f"{where}: TLE line {which}, columns 3-7: catalogue number "
                         f"{number!r} is neither digits nor Alpha-5 (a letter, 4 digits)")
    for col, (c, want) in enumerate(zip(line, template, strict=False), 1):
        if 3 <= col <= 7:
            ok = True
        elif want == "N":
            ok = c.isdigit() or c == " "
        elif want in "+-":
            ok = c in " +-" or (want == "-" and c.isdigit())
        elif want in " .12":
            ok = c == want
        else:
            ok = True
        if not ok:
            raise ValueError(f"{where}: TLE line {which}, column {col}: {c!r} does not fit "
                             f"the TLE layout ({template[col - 1]!r} there)")
    if len(line) == 69 and int(line[68]) != compute_checksum(line):
        raise ValueError(f"{where}: TLE line {which} fails its checksum (column 69 is "
                         f"{line[-1]!r}, the line sums to {compute_checksum(line)})")


def said(check: Callable[..., None], *args: object) -> str | None:
    try:
        check(*args)
    except ValueError as exc:
        return str(exc)
    return None


@settings(max_examples=1500, deadline=None, derandomize=True)
@given(st.sampled_from([1, 2]),
       st.lists(st.tuples(st.integers(0, 68), st.characters(max_codepoint=130)), max_size=4),
       st.booleans())
def test_the_layout_pattern_says_what_the_columns_one_by_one_say(which, edits, checksum):
    """Every character at every column (ASCII and a few beyond), with and without the
    checksum column: the same verdict and message."""
    from sgp4.io import LINE1, LINE2

    line = list(tle_lines(123)[which - 1])
    for col, c in edits:
        line[col] = c
    text = "".join(line) if checksum else "".join(line)[:68]
    template = LINE1 if which == 1 else LINE2
    assert said(tle.check_columns, text, template, which, "f:1") == \
        said(columns_one_by_one, text, template, which, "f:1")


PEAK = """
import sys
from pathlib import Path
from ssa_fusion.formats import element_sets as catalog
def kib(key):
    line = next(s for s in Path("/proc/self/status").read_text().splitlines()
                if s.startswith(key))
    return int(line.split()[1])
before = kib("VmRSS:")
entries = catalog.read_catalog(sys.argv[1])
print(len(entries), kib("VmHWM:") - before)
"""
"""A read in a process of its own: its objects and how far its peak resident memory rose
(KiB): lxml's tree is not Python's memory, tracemalloc does not see it."""


@pytest.mark.skipif(not Path("/proc/self/status").exists(), reason="needs Linux's /proc")
@pytest.mark.parametrize("kind", ["xml", "xml_junk"])
def test_an_xml_read_holds_no_tree_of_the_document(tmp_path, kind):
    """Resident memory rises with the objects (their entries, ~1.4 KiB each), not with the
    document's tree (~12 KiB an object here when what is read is kept), even when much
    else than segments is read between them."""
    import subprocess
    import sys

    rise = []
    for n in (2000, 8000):
        path = tmp_path / f"{n}.xml"
        path.write_text(GENERATED[kind](n))
        out = subprocess.run([sys.executable, "-c", PEAK, str(path)], capture_output=True,
                             text=True, check=True, cwd=ROOT, timeout=300).stdout.split()
        assert int(out[0]) == n
        rise.append(int(out[1]))
    assert (rise[1] - rise[0]) / 6000 < 3.0, rise  # KiB an object

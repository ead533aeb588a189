"""A real catalog with bad element sets loads: each bad set left out with one line naming
file, line, object and reason, and counted (`formats.skipped`); strict, the file is refused.

The catalog: the 306 real sets of ``config/catalogs/celestrak_active_2025-07.tle`` with
``config/catalogs/bad_sets.tle`` appended (a real published set whose B* is -6.6561 per
Earth radius, an object twice, a line 2 whose checksum fails). The expected lines are
written out by hand from that file, not from the reader."""

from pathlib import Path

import pytest

from ssa_fusion.formats.element_sets import parse_omm_csv, parse_omm_xml, parse_tle, read_catalog
from ssa_fusion.formats.skipped import MAX_LINES, Skipped
from ssa_fusion.sim.schedule import SimSettings, plan, resolve

CATALOGS = Path(__file__).resolve().parents[2] / "config" / "catalogs"
REAL = CATALOGS / "celestrak_active_2025-07.tle"
BAD = CATALOGS / "bad_sets.tle"


@pytest.fixture(scope="module")
def real_with_bad(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("catalog") / "active_with_bad.tle"
    path.write_text(REAL.read_text() + BAD.read_text())
    return path


def test_a_real_catalog_with_bad_sets_loads_and_names_each(real_with_bad: Path) -> None:
    real_lines = len(REAL.read_text().splitlines())
    skipped = Skipped()
    entries = read_catalog(real_with_bad, skip=skipped)
    assert len(entries) == 306 and skipped.count == 3
    assert [e.object_id for e in entries] == [e.object_id for e in read_catalog(REAL)]
    f = str(real_with_bad)
    assert skipped.lines == [
        f"{f}:{real_lines + 9}: object 44542 (BEIDOU-3 M23): B* -6.6561 per Earth radius "
        "beyond 1 (not a physical drag term); skipped",
        f"{f}:{real_lines + 14}: object 00900 (CALSPHERE 1): object 900 is already in the "
        f"catalog ({f}:16); one element set per object; skipped",
        f"{f}:{real_lines + 20}: object 28420 (COSMOS 2409): TLE line 2 fails its checksum "
        "(column 69 is '1', the line sums to 6); skipped"]


def test_strict_refuses_the_file_at_its_first_bad_set(real_with_bad: Path) -> None:
    with pytest.raises(ValueError, match=r"active_with_bad.tle:\d+: B\* -6.6561 per Earth"):
        read_catalog(real_with_bad)


def test_out_of_place_lines_are_left_out_and_the_read_resyncs() -> None:
    """A line 1 without its line 2, a line 2 alone, a name with control characters: each
    its own line; the sets around them are read."""
    good = REAL.read_text().splitlines()[14:20]  # CALSPHERE 1 and USA 115, 3LE
    text = "\n".join([good[1], *good[3:6], good[2], "BAD\x1bNAME", *good[1:3],
                      *good[0:3]]) + "\n"
    skipped = Skipped()
    entries = parse_tle(text, "t.tle", skip=skipped)
    assert [e.object_id for e in entries] == ["23712", "900"]
    assert [line.split(": ", 2)[:2] for line in skipped.lines] == [
        ["t.tle:1", "object 00900"], ["t.tle:5", "object 00900"], ["t.tle:6", "object 00900"]]
    assert "not followed by its line 2" in skipped.lines[0]
    assert "line 2 without a line 1" in skipped.lines[1]
    assert "control characters" in skipped.lines[2] and "\x1b" not in skipped.lines[2]


def test_an_omm_csv_row_with_a_bad_field_is_left_out() -> None:
    text = [x for x in (CATALOGS / "sample_omm.csv").read_text().splitlines()
            if not x.startswith("#")]
    header, rows = text[0], text[1:]
    bstar = header.split(",").index("BSTAR")
    broken = rows[0].split(",")
    broken[bstar] = "-6.6561"
    skipped = Skipped()
    entries = parse_omm_csv("\n".join([header, ",".join(broken), *rows[1:]]), "s.csv",
                            skip=skipped)
    assert len(entries) == len(rows) - 1 and skipped.count == 1
    assert skipped.lines[0].startswith("s.csv:2: object ") and "B* -6.6561" in skipped.lines[0]


def test_the_lines_kept_are_bounded_the_count_is_not() -> None:
    s = Skipped()
    for k in range(MAX_LINES + 5):
        s.add(f"f:{k}", str(k), "", "bad")
    assert s.count == MAX_LINES + 5 and len(s.lines) == MAX_LINES
    assert s.summary().endswith("... and 5 more")


def test_the_simulator_leaves_the_same_sets_out(real_with_bad: Path) -> None:
    base, real_sky = resolve("iss_network")
    run = plan("iss_network", base, real_sky,
               SimSettings(object_id="", cadence=60.0, duration=600.0,
                           catalog=str(real_with_bad), objects=5))
    assert run.catalog is not None and run.catalog.skipped.count == 3
    assert "(3 bad element sets left out)" in run.summary
    assert list(run.catalog.object_ids) == [e.object_id for e in read_catalog(REAL)[:5]]


def test_an_omm_xml_segment_that_is_bad_or_lacks_a_block_is_left_out() -> None:
    text = (CATALOGS / "sample_omm.xml").read_text()
    head, _, rest = text.partition("<segment>")
    segment, _, tail = rest.partition("</segment>")
    bad = segment.replace("<BSTAR>", "<BSTAR>-6.6561").replace(
        segment[segment.index("<BSTAR>") + 7:segment.index("</BSTAR>")], "", 1)
    lacking = segment.replace("<meanElements>", "<notMeanElements>").replace(
        "</meanElements>", "</notMeanElements>")
    doc = f"{head}<segment>{segment}</segment><segment>{bad}</segment>" \
          f"<segment>{lacking}</segment>{tail}"
    skipped = Skipped()
    entries = parse_omm_xml(doc, "s.xml", skip=skipped)
    assert len(entries) == 1 and skipped.count == 2
    assert skipped.lines[0].startswith("s.xml:segment 2: object ") and "B*" in skipped.lines[0]
    assert skipped.lines[1].startswith("s.xml:segment 3: object ?: an OMM segment lacks")

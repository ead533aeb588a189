"""CCSDS OMM element sets in XML (read as a stream) or CSV (`element_sets` module docstring).

NDM/XML as CelesTrak and Space-Track serve it (parsed by lxml's pull parser, segment by
segment) or CSV (one row per object, CelesTrak's columns; by `csv`, its field size limit
kept): the fields `sgp4.omm` reads, made element sets by `sgp4.omm.initialize`, with the
metadata an SGP4 element set must have, a one-letter classification and integer counters in
the TLE's ranges (`OMM_INTEGER_RANGES`).
"""

from __future__ import annotations

import csv
from collections.abc import Iterable, Iterator
from typing import TYPE_CHECKING, Any

from sgp4 import omm as sgp4_omm
from sgp4.api import Satrec

from ssa_fusion.core.motion.element_sets import CatalogEntry
from ssa_fusion.formats.element_set_checks import (
    MAX_NAME,
    check_name,
    check_new,
    check_satrec,
    numbered,
    quote,
)
from ssa_fusion.formats.skipped import Skipped, skip_or_raise

if TYPE_CHECKING:
    from lxml import etree

__all__ = ["NESTED", "OMM_INTEGER_RANGES", "omm_csv_entries", "omm_entry", "omm_xml_entries",
           "parse_omm_csv", "parse_omm_xml"]

CHUNK_CHARACTERS = 1 << 18
"""Characters of an OMM XML text fed to the parser at a time (`parse_omm_xml`)."""


OMM_INTEGER_RANGES = {"NORAD_CAT_ID": (1, 339999), "ELEMENT_SET_NO": (0, 9999),
                      "REV_AT_EPOCH": (0, 99999), "EPHEMERIS_TYPE": (0, 9)}
"""Integer OMM fields and the ranges a TLE can carry (NORAD numbers: Alpha-5)."""


NESTED = "<nested XML elements>"
"""What an OMM/XML field holding elements instead of text reads as (refused by identity)."""


_OMM_FIELDS = (
    "OBJECT_ID", "EPOCH", "MEAN_MOTION", "ECCENTRICITY", "INCLINATION", "RA_OF_ASC_NODE",
    "ARG_OF_PERICENTER", "MEAN_ANOMALY", "EPHEMERIS_TYPE", "CLASSIFICATION_TYPE",
    "NORAD_CAT_ID", "ELEMENT_SET_NO", "REV_AT_EPOCH", "BSTAR", "MEAN_MOTION_DOT",
    "MEAN_MOTION_DDOT",
)
"""OMM fields `sgp4.omm.initialize` needs."""


_OMM_EXPECTED = {"REF_FRAME": "TEME", "TIME_SYSTEM": "UTC", "CENTER_NAME": "EARTH"}
"""OMM metadata an SGP4 element set must have, when the file gives it."""


def parse_omm_xml(text: str, source: str = "<string>",
                  skip: Skipped | None = None) -> list[CatalogEntry]:
    """Entries of CCSDS OMM XML `text` (one per ``segment``, as `sgp4.omm.parse_xml` reads).

    `skip`: leave bad segments out and count them there (`formats.skipped`).
    """
    chunks = (text[i:i + CHUNK_CHARACTERS] for i in range(0, len(text), CHUNK_CHARACTERS))
    return list(omm_xml_entries(chunks, source, skip))


def omm_xml_entries(chunks: Iterable[str], source: str,
                    skip: Skipped | None = None) -> Iterator[CatalogEntry]:
    """Yield the entries of the OMM XML text that `chunks` make, read as a stream.

    lxml's pull parser (no network, no DTD loaded, its limits on text size and depth held;
    comments and processing instructions left out), telling of ``segment`` elements only.
    Each (any element so named below the root, in document order, as `sgp4.omm.parse_xml`
    finds them) is judged when it ends; then it, and whatever else was read outside the
    segments still open, is dropped. Errors are raised as a parse of the whole document
    raised them: XML that is not well formed anywhere first, then a segment lacking a
    block, then the first segment whose element set is wrong (the segments after it are
    only parsed). With `skip`, a segment lacking a block or whose element set is wrong is
    counted there and left out (XML that is not well formed still refuses the file).
    """
    from lxml import etree

    reader = _OmmXml(source, skip)
    parser = etree.XMLPullParser(events=("start", "end"), tag="segment", remove_comments=True,
                                 remove_pis=True, no_network=True, load_dtd=False,
                                 huge_tree=False)
    try:
        for chunk in chunks:
            parser.feed(chunk)
            yield from reader.read(parser.read_events())
            reader.drop_done()
        parser.close()
        yield from reader.read(parser.read_events())
    except etree.XMLSyntaxError as exc:
        line, col = exc.position if exc.position else (exc.lineno or 1, 1)
        raise ValueError(f"{source}:{max(line, 1)}: not well-formed XML (column "
                         f"{max(col, 1)})") from None
    if reader.failure is not None:
        raise reader.failure


class _OmmXml:
    """The segments of an OMM XML document, from its parser's events (`omm_xml_entries`)."""

    def __init__(self, source: str, skip: Skipped | None = None) -> None:
        self.source = source
        self.skip = skip
        self.root: etree._Element | None = None
        self.open: list[tuple[int, etree._Element]] = []
        """The segments started and not yet ended: (number from 1 in document order, it)."""
        self.started = 0
        self.ended: dict[int, dict[str, str | None] | None] = {}
        """Fields of ended segments not yet judged (a segment inside another ends first):
        by number; None for a segment lacking a block."""
        self.judged = 0
        self.seen: dict[str, str] = {}
        self.failure: ValueError | None = None
        self.lacking = False

    def read(self, events: Iterable[tuple[Any, ...]]) -> Iterator[CatalogEntry]:
        """Yield the entries of the segments that `events` (start, end of segments) complete."""
        for event, elem in events:
            if elem.getparent() is None:  # the root: not one of its segments
                continue
            if event == "start":
                if self.root is None:
                    self.root = elem.getroottree().getroot()
                self.started += 1
                self.open.append((self.started, elem))
                continue
            number, _ = self.open.pop()
            self.ended[number] = _segment_fields(elem)
            yield from self._judge()
            if not self.open:
                elem.clear()

    def drop_done(self) -> None:
        """Drop the elements read outside the open segments.

        All but the last child of each element on the way down from the root, along last
        children, to the first open segment (left whole) or a leaf.
        """
        node = self.root
        inside = {id(elem) for _, elem in self.open}
        while node is not None and id(node) not in inside:
            last = next(reversed(node), None)
            if last is not None:
                while last.getprevious() is not None:
                    del node[0]
            node = last

    def _judge(self) -> Iterator[CatalogEntry]:
        """Yield the entries of the ended segments next in document order."""
        while self.judged + 1 in self.ended:
            self.judged += 1
            fields = self.ended.pop(self.judged)
            if self.lacking:
                continue
            where = f"{self.source}:segment {self.judged}"
            if fields is None:
                lacks = ValueError(f"{self.source}: an OMM segment lacks (or has empty) "
                                   f"metadata, data, meanElements or tleParameters")
                if self.skip is not None:
                    skip_or_raise(self.skip, lacks, where, "")
                    continue
                self.lacking = True
                self.failure = lacks
            elif self.failure is None:
                try:
                    entry = omm_entry(fields, where)
                    check_new(entry, self.seen)
                except ValueError as exc:
                    if self.skip is None:
                        self.failure = exc
                    else:
                        skip_or_raise(self.skip, exc, where, _omm_id(fields),
                                      _omm_name(fields))
                else:
                    yield entry


def _segment_fields(segment: etree._Element) -> dict[str, str | None] | None:
    """Return the fields of an OMM ``segment``, None if it lacks one of its blocks.

    Tag -> text of the children of its ``metadata``, ``data/meanElements`` and
    ``data/tleParameters``.
    """
    data = segment.find("data")
    if data is None:
        return None
    blocks = (segment.find("metadata"), data.find("meanElements"), data.find("tleParameters"))
    fields: dict[str, str | None] = {}
    for block in blocks:
        if block is None:
            return None
        fields.update((field.tag, field.text if len(field) == 0 else NESTED)
                      for field in block)
    return fields


def parse_omm_csv(text: str, source: str = "<string>",
                  skip: Skipped | None = None) -> list[CatalogEntry]:
    """Entries of CCSDS OMM CSV `text`.

    A header row of OMM keywords, then one row per object; lines starting with ``#`` are
    comments. `skip`: leave bad rows out and count them there (`formats.skipped`).
    """
    return list(omm_csv_entries(numbered(text.splitlines()), source, skip))


def omm_csv_entries(lines: Iterator[tuple[int, str]], source: str,
                    skip: Skipped | None = None) -> Iterator[CatalogEntry]:
    """Yield the entries of OMM CSV `lines` (numbered, as `numbered` yields them).

    Row k is named by the number of the (k+1)-th line (the header being the first); a row
    csv cannot read by that of the line after the last row read. With `skip`, a row whose
    element set is bad is counted there and left out.
    """
    numbers: list[int] = []  # of the lines read, from the `first`-th (from 0) on
    first = 0

    def fed() -> Iterator[str]:
        for no, line in lines:
            numbers.append(no)
            yield line

    def number(k: int) -> int:
        """Return the number of the line k (from 0), or of the last line if fewer."""
        while k - first >= len(numbers) and (nxt := next(lines, None)) is not None:
            numbers.append(nxt[0])
        return numbers[min(k - first, len(numbers) - 1)] if numbers else 0

    seen: dict[str, str] = {}
    k = 0
    try:
        for k, fields in enumerate(csv.DictReader(fed()), 1):
            del numbers[:k - first]
            first = k
            where = f"{source}:{numbers[0]}"
            try:
                if None in fields:
                    raise ValueError(f"{where}: more values than the header has columns")
                entry = omm_entry(dict(fields), where)
                check_new(entry, seen)
            except ValueError as exc:
                skip_or_raise(skip, exc, where, _omm_id(fields), _omm_name(fields))
            else:
                yield entry
    except csv.Error as exc:  # e.g. a field beyond csv's size limit (131,072 characters)
        raise ValueError(f"{source}:{number(k + 1)}: unreadable CSV row: {exc}") from None


def _omm_id(fields: dict[str, Any]) -> str:
    """Return an OMM's NORAD_CAT_ID as given (stripped, bounded), for a line about it."""
    value = fields.get("NORAD_CAT_ID")
    return quote(value.strip())[1:-1] if isinstance(value, str) else ""


def _omm_name(fields: dict[str, Any]) -> str:
    """Return an OMM's OBJECT_NAME for a line about it ('' unless plain printable text)."""
    value = fields.get("OBJECT_NAME")
    if not isinstance(value, str) or len(value) > MAX_NAME or not value.isprintable():
        return ""
    return value.strip()


def omm_entry(fields: dict[str, Any], where: str) -> CatalogEntry:
    """Entry of one OMM (a dict of keyword -> text), or ValueError naming `where`."""
    nested = [k for k in (*_OMM_FIELDS, *_OMM_EXPECTED, "OBJECT_NAME", "MEAN_ELEMENT_THEORY")
              if fields.get(k) is NESTED]
    if nested:
        raise ValueError(f"{where}: OMM {nested[0]} holds XML elements (an XInclude or a "
                         f"nested element), not a value")
    missing = [k for k in _OMM_FIELDS if not (fields.get(k) or "").strip()]
    if missing:
        raise ValueError(f"{where}: OMM lacks {', '.join(missing)}")
    foreign = [k for k in _OMM_FIELDS if not str(fields[k]).isascii()]
    if foreign:
        raise ValueError(f"{where}: OMM {foreign[0]} {quote(fields[foreign[0]])} is not "
                         f"ASCII (numbers are written in ASCII digits)")
    for key, want in _OMM_EXPECTED.items():
        got = (fields.get(key) or want).strip().upper()
        if got != want:
            raise ValueError(f"{where}: OMM {key} is {got}; SGP4 element sets need {want}")
    theory = (fields.get("MEAN_ELEMENT_THEORY") or "SGP4").strip().upper()
    if theory not in ("SGP4", "SGP/SGP4"):
        raise ValueError(f"{where}: OMM MEAN_ELEMENT_THEORY is {theory}; only SGP4 element "
                         f"sets are supported")
    clean = {k: v.strip() for k, v in fields.items() if isinstance(v, str)}
    if len(clean["CLASSIFICATION_TYPE"]) != 1:
        raise ValueError(f"{where}: OMM CLASSIFICATION_TYPE "
                         f"{quote(clean['CLASSIFICATION_TYPE'])} is not one letter (U, C, S)")
    for key, (lo, hi) in OMM_INTEGER_RANGES.items():
        text = clean.get(key, "0") or "0"
        if not (text.isascii() and text.isdigit() and lo <= int(text) <= hi):
            raise ValueError(f"{where}: OMM {key} {quote(text)} is not an integer in "
                             f"{lo}..{hi}")
    if "." not in clean["EPOCH"]:  # whole seconds: sgp4.omm wants a fraction
        clean["EPOCH"] += ".0"
    sat = Satrec()
    try:
        sgp4_omm.initialize(sat, clean)
    except (ValueError, TypeError, OverflowError) as exc:
        raise ValueError(f"{where}: malformed OMM field: {quote(str(exc))}") from None
    check_satrec(sat, where)
    name = (fields.get("OBJECT_NAME") or "").strip()
    check_name(name, f"{where}: OMM OBJECT_NAME")
    return CatalogEntry(str(sat.satnum), name, sat, where)

"""Catalogs of element sets: TLE/3LE and CCSDS OMM files, and their SGP4/SDP4 truth.

A catalog is a list of `CatalogEntry` (object id, name, `sgp4.api.Satrec`), read by
:func:`read_catalog` from

* **TLE** (two lines per object) or **3LE** (a name line, then the two lines; a Space-Track
  ``0 NAME`` name line works too). Lines starting with ``#`` and blank lines are skipped.
  Every line is checked column by column against the TLE layout (`sgp4.io.LINE1`/`LINE2`)
  and by its checksum (column 69, when present), because ``Satrec.twoline2rv`` accepts
  malformed lines silently (zeros for what it cannot read).
* **CCSDS OMM** in XML (NDM/XML, as CelesTrak and Space-Track serve it; parsed by lxml) or
  CSV (one row per object, CelesTrak's columns; by `csv`, its field size limit kept), the
  fields `sgp4.omm` reads, made element sets by `sgp4.omm.initialize`. OMM in KVN is not
  supported (`sgp4` does not read it): the error says so.

The format is told from the content, not the file name. A file is read as a stream, never
whole: a TLE/3LE or OMM/CSV file line by line, an OMM/XML file element by element (each
segment dropped once read), so a read holds its entries (and the longest line) but not the
file's text, whatever its size; `read_catalog`'s ``progress(bytes read, file size, objects
so far)`` says how far it got, every `PROGRESS_EVERY` objects. Malformed input raises
ValueError naming the file and the line (the XML segment for OMM/XML) in one bounded line
(values are quoted to `MAX_QUOTE` characters), never an error from deep inside `sgp4`,
`csv` or lxml. Every
element set is checked against the domain of its fields before it is used: finite angles,
an inclination in [0, 180] deg, an eccentricity in [0, 1), a mean motion of a bound orbit
above the Earth's surface (0 < n <= `MAX_MEAN_MOTION_REV_DAY`), |B*| <= `MAX_BSTAR`, an
epoch ssa_fusion represents (`timescales.EPOCH_MIN` .. `EPOCH_MAX`), and for OMM a
one-letter classification and integer counters in the TLE's ranges, a name of at most
`MAX_NAME` characters. The object id is the
NORAD catalogue number as a decimal string (``"5"`` for ``00005``; Alpha-5 numbers as their
integer, ``A0001`` -> ``"100001"``), the same for a TLE and the OMM of the same object; an id
twice in one file is an error.

:func:`catalog_states` propagates every object to many epochs at once with
`sgp4.api.SatrecArray` (SGP4 near Earth, SDP4 for periods >= 225 min, WGS-72 as the element
sets assume). SGP4 speaks TEME: its states are turned to the GCRF, the project's inertial
frame, on the way out (`frames.teme_to_gcrs`; `dynamics.sgp4_ephemeris` does the same for
one object): km, km/s. Epochs are Unix seconds (UTC), as the measurement stamps.

The sample catalog ``config/catalogs/sample.tle`` holds real element sets of six objects of
different regimes (LEO, high-drag LEO, MEO/GPS, GEO, HEO/Molniya) from the SGP4 verification
file ``SGP4-VER.TLE`` shipped with `sgp4`: D. A. Vallado, P. Crawford, R. Hujsak and
T. S. Kelso, "Revisiting Spacetrack Report #3", AIAA 2006-6753 (2006).
"""

from __future__ import annotations

import calendar
import codecs
import csv
import io
import locale
import math
import os
import re
import unicodedata
from collections.abc import Callable, Iterable, Iterator
from pathlib import Path
from types import TracebackType
from typing import IO, TYPE_CHECKING, Any

from sgp4 import omm
from sgp4.api import SGP4_ERRORS, Satrec
from sgp4.io import LINE1, LINE2

from ssa_fusion.core.earth.timescales import DAY_S, UNIX_EPOCH_JD, check_epochs
from ssa_fusion.core.motion.element_sets import CatalogEntry
from ssa_fusion.formats.skipped import Skipped, skip_or_raise

if TYPE_CHECKING:
    from lxml import etree

MAX_QUOTE = 60
"""Characters of a value quoted in an error message (the rest is cut: '...')."""
MAX_NAME = 128
"""Longest object name taken (a 3LE name line is 24 characters, an OMM OBJECT_NAME as long;
`validation.MAX_ID_CHARS` is as long)."""
MAX_MEAN_MOTION_REV_DAY = 18.0
"""The largest mean motion taken, rev/day: 17 rev/day is an orbit at the Earth's surface."""
MAX_BSTAR = 1.0
"""The largest |B*| taken, 1/Earth radii (decaying debris reach ~0.1; 1 is implausible)."""
OMM_INTEGER_RANGES = {"NORAD_CAT_ID": (1, 339999), "ELEMENT_SET_NO": (0, 9999),
                      "REV_AT_EPOCH": (0, 99999), "EPHEMERIS_TYPE": (0, 9)}
"""Integer OMM fields and the ranges a TLE can carry (NORAD numbers: Alpha-5)."""
_ALPHA5 = "ABCDEFGHJKLMNPQRSTUVWXYZ"
"""Alpha-5's first characters (I and O are not used)."""
PROGRESS_EVERY = 4096
"""Objects between two calls of `read_catalog`'s progress callback."""
CHUNK_BYTES = 1 << 18
"""Bytes of a catalog file read at a time."""
_LINE_BREAKS = frozenset("\n\r\v\f\x1c\x1d\x1e\x85\u2028\u2029")
"""The characters `str.splitlines` ends a line at."""

NESTED = "<nested XML elements>"
"""What an OMM/XML field holding elements instead of text reads as (refused by identity)."""

Progress = Callable[[int, int, int], None]
"""``progress(bytes read, file size, objects so far)`` of `read_catalog`."""


def _quote(value: object) -> str:
    """``repr`` of `value`, cut to `MAX_QUOTE` characters."""
    text = repr(value)
    return text if len(text) <= MAX_QUOTE else text[:MAX_QUOTE] + "..."

_OMM_FIELDS = (
    "OBJECT_ID", "EPOCH", "MEAN_MOTION", "ECCENTRICITY", "INCLINATION", "RA_OF_ASC_NODE",
    "ARG_OF_PERICENTER", "MEAN_ANOMALY", "EPHEMERIS_TYPE", "CLASSIFICATION_TYPE",
    "NORAD_CAT_ID", "ELEMENT_SET_NO", "REV_AT_EPOCH", "BSTAR", "MEAN_MOTION_DOT",
    "MEAN_MOTION_DDOT",
)
"""OMM fields `sgp4.omm.initialize` needs."""
_OMM_EXPECTED = {"REF_FRAME": "TEME", "TIME_SYSTEM": "UTC", "CENTER_NAME": "EARTH"}
"""OMM metadata an SGP4 element set must have, when the file gives it."""


def read_catalog(path: Path | str, progress: Progress | None = None,
                 skip: Skipped | None = None) -> list[CatalogEntry]:
    """Element sets of a TLE, 3LE, OMM/XML or OMM/CSV file (told from its content).

    The file is read as a stream (module docstring), as text in the locale's encoding (as
    `Path.read_text` reads it); `progress(bytes read, file size, objects so far)` is called
    every `PROGRESS_EVERY` objects and once at the end (the bytes read are then the file's
    size).

    ValueError, naming the file and line: unreadable file, unknown or unsupported format
    (OMM/KVN), malformed line or field, an element set SGP4 refuses, an object id twice,
    no element set at all. Bytes that are not text in the encoding are said first, wherever
    they are in the file (their position counted in bytes from its start). With `skip`
    (`formats.skipped`), a malformed or refused element set, or an object's second one, is
    left out and counted there instead, and the read goes on; the file is still refused
    when it has no element set left.
    """
    path = Path(path)
    source = str(path)
    with _CatalogFile(path) as f:
        head = next((s.strip() for s in _lines(f.chunks())
                     if s.strip() and not s.startswith("#")), "")
        text = f.chunks()  # from the start again
        try:
            if head.startswith("<"):
                entries = _omm_xml_entries(text, source, skip)
            elif head.startswith("CCSDS_OMM_VERS"):
                raise ValueError(f"{path}: OMM in KVN is not supported (sgp4 reads OMM as XML "
                                 f"or CSV); convert it to one of those")
            elif "NORAD_CAT_ID" in head.split(","):
                entries = _omm_csv_entries(_numbered(_lines(text)), source, skip)
            else:
                entries = _tle_entries(_numbered(_lines(text)), source, skip)
            out = _collected(entries, f, progress)
            if not out:
                left = f" ({skip.count} left out: {skip.lines[0]})" if skip and skip.count else ""
                raise ValueError(f"{path}: no element sets in the file{left}")
        except ValueError:
            for _ in text:  # the rest of the file: bytes that are not text say so first
                pass
            raise
    return out


def _collected(entries: Iterable[CatalogEntry], f: _CatalogFile,
               progress: Progress | None) -> list[CatalogEntry]:
    """Return the list of `entries` (read from `f`), calling `progress` as `read_catalog` says."""
    out: list[CatalogEntry] = []
    for entry in entries:
        out.append(entry)
        if progress is not None and len(out) % PROGRESS_EVERY == 0:
            progress(f.bytes_read, f.size, len(out))
    if progress is not None:
        progress(f.bytes_read, f.size, len(out))
    return out


class _CatalogFile:
    """A catalog file read as text, a chunk of `CHUNK_BYTES` at a time.

    `size`: its size in bytes; `bytes_read`: how many `chunks` has read. A file that cannot
    seek (a pipe) is read whole once, to be read from its start again.
    """

    def __init__(self, path: Path) -> None:
        self.path = path
        self.bytes_read = 0
        self.encoding = locale.getpreferredencoding(False)  # as Path.read_text decodes
        try:
            self.file: IO[bytes] = path.open("rb")
            self.size = os.fstat(self.file.fileno()).st_size
            if not self.file.seekable():
                with self.file:
                    self.file = io.BytesIO(self.file.read())
                self.size = len(self.file.getbuffer())
        except OSError as exc:
            raise self.cannot(exc) from None

    def __enter__(self) -> _CatalogFile:
        return self

    def __exit__(self, kind: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> None:
        self.file.close()

    def cannot(self, why: object) -> ValueError:
        """Return the ValueError saying the file cannot be read, and `why`."""
        return ValueError(f"{self.path}: cannot read catalog: {why}")

    def chunks(self) -> Iterator[str]:
        """Yield the file's text from its start, every newline (CR LF, CR, LF) made LF.

        ValueError (`cannot`) for bytes that are not text, or a failing read.
        """
        decoder = io.IncrementalNewlineDecoder(codecs.getincrementaldecoder(self.encoding)(),
                                               translate=True)
        try:
            self.file.seek(0)
        except OSError as exc:
            raise self.cannot(exc) from None
        self.bytes_read = 0
        while True:
            try:
                data = self.file.read(CHUNK_BYTES)
            except OSError as exc:
                raise self.cannot(exc) from None
            held = len(decoder.getstate()[0])  # bytes of a character the last chunk cut
            try:
                text = decoder.decode(data, final=not data)
            except UnicodeDecodeError as exc:
                raise self.cannot(_decode_error(exc, self.bytes_read - held)) from None
            self.bytes_read += len(data)
            if text:
                yield text
            if not data:
                return


def _decode_error(exc: UnicodeDecodeError, offset: int) -> str:
    """Return what `exc` says, its positions `offset` bytes further on.

    As the decoding of the whole file at once says it.
    """
    start, end = exc.start + offset, exc.end + offset
    if exc.end == exc.start + 1:
        return (f"'{exc.encoding}' codec can't decode byte 0x{exc.object[exc.start]:02x} in "
                f"position {start}: {exc.reason}")
    return f"'{exc.encoding}' codec can't decode bytes in position {start}-{end - 1}: {exc.reason}"


def _lines(chunks: Iterable[str]) -> Iterator[str]:
    """Yield the lines of the text that `chunks` make, as `str.splitlines` splits it.

    The text's newlines are LF only (no CR LF: `_CatalogFile.chunks`).
    """
    cut: list[str] = []  # the start of a line that a chunk's end cut
    for chunk in chunks:
        parts = chunk.splitlines(keepends=True)
        rest = parts.pop() if parts[-1][-1] not in _LINE_BREAKS else ""
        if parts:
            if cut:
                parts[0] = "".join(cut) + parts[0]
                cut = []
            for line in parts:
                yield line[:-1]
        if rest:
            cut.append(rest)
    if cut:
        yield "".join(cut)


def parse_tle(text: str, source: str = "<string>",
              skip: Skipped | None = None) -> list[CatalogEntry]:
    """Entries of TLE/3LE `text` (see the module docstring); `source` names it in errors.

    `skip`: leave bad element sets out and count them there (`formats.skipped`).
    """
    return list(_tle_entries(_numbered(text.splitlines()), source, skip))


def _tle_entries(lines: Iterator[tuple[int, str]], source: str,
                 skip: Skipped | None = None) -> Iterator[CatalogEntry]:
    """Yield the entries of TLE/3LE `lines` (numbered, as `_numbered` yields them).

    A bad element set (its name line, its two lines, or a line out of place) raises, or
    with `skip` is counted there and left out: the read goes on at the next line that can
    start a set.
    """
    seen: dict[str, str] = {}
    name, name_no, bad_name = "", 0, None
    back: list[tuple[int, str]] = []  # a line read ahead, to be read again
    while (item := back.pop() if back else next(lines, None)) is not None:
        no, line = item
        where = f"{source}:{no}"
        if line.startswith("1 "):
            nxt = next(lines, None)
            try:
                if nxt is None or not nxt[1].startswith("2 "):
                    if nxt is not None:
                        back.append(nxt)
                    raise ValueError(f"{where}: TLE line 1 is not followed by its line 2")
                if bad_name is not None:
                    raise bad_name
                entry = _tle_entry(line, nxt[1], name, where, f"{source}:{nxt[0]}")
                _check_new(entry, seen)
            except ValueError as exc:
                skip_or_raise(skip, exc, where if bad_name is None else f"{source}:{name_no}",
                              line[2:7].strip(), name)
            else:
                yield entry
            name, name_no, bad_name = "", 0, None
        elif line.startswith("2 "):
            skip_or_raise(skip, ValueError(f"{where}: TLE line 2 without a line 1 before it"),
                          where, line[2:7].strip())
        elif name or bad_name is not None:
            skip_or_raise(skip, bad_name or ValueError(
                f"{source}:{name_no}: name line {_quote(name)} is not followed by TLE lines "
                f"(line {no} is neither)"), f"{source}:{name_no}", "", name)
            name, name_no, bad_name = "", 0, None
            back.append(item)
        else:
            name, name_no = (line[2:] if line.startswith("0 ") else line).strip(), no
            try:
                _check_name(name, f"{where}: name line")
            except ValueError as exc:
                if skip is None:
                    raise
                bad_name, name = exc, ""  # not echoed: its own error quotes it, bounded
    if name or bad_name is not None:
        skip_or_raise(skip, bad_name or ValueError(
            f"{source}:{name_no}: name line {_quote(name)} at the end of the file without "
            f"TLE lines"), f"{source}:{name_no}", "", name)


def _check_name(name: str, where: str) -> None:
    """Refuse an object name longer than `MAX_NAME` characters or with control characters.

    NUL, escape (terminal control sequences) and the other C0/C1 controls would be stored in
    bags and echoed raw to a user's terminal (ValueError naming `where`).
    """
    if len(name) > MAX_NAME:
        raise ValueError(f"{where}: an object name of {len(name)} characters (at most "
                         f"{MAX_NAME}): {_quote(name)}")
    if any(unicodedata.category(c) == "Cc" for c in name):
        raise ValueError(f"{where}: an object name with control characters (NUL, escape, "
                         f"...): {_quote(name)}")


def _numbered(lines: Iterable[str]) -> Iterator[tuple[int, str]]:
    """(1-based line number, line without trailing blanks), comments and blanks left out."""
    for no, raw in enumerate(lines, 1):
        line = raw.rstrip()
        if line and not line.startswith("#"):
            yield no, line


def _check_new(entry: CatalogEntry, seen: dict[str, str]) -> None:
    if entry.object_id in seen:
        raise ValueError(f"{entry.source}: object {entry.object_id} is already in the "
                         f"catalog ({seen[entry.object_id]}); one element set per object")
    seen[entry.object_id] = entry.source


def _check_columns(line: str, template: str, which: int, where: str) -> None:
    """ValueError unless `line` fits the TLE layout `template` (sgp4.io.LINE1/LINE2)."""
    if not line.isascii():
        raise ValueError(f"{where}: TLE line {which} has non-ASCII characters")
    if len(line) not in (68, 69):  # 68: without the checksum column
        raise ValueError(f"{where}: TLE line {which} has {len(line)} columns, not 69")
    number = line[2:7]
    if not ((number.strip().isdigit() and number == number.strip().rjust(5))
            or (number[0] in _ALPHA5 and number[1:].isdigit())):
        raise ValueError(f"{where}: TLE line {which}, columns 3-7: catalogue number "
                         f"{number!r} is neither digits nor Alpha-5 (a letter, 4 digits)")
    if _LAYOUTS[template].fullmatch(line) is None:  # then say which column, and why
        for col, (c, want) in enumerate(zip(line, template, strict=False), 1):
            if not _fits(c, want, col):
                raise ValueError(f"{where}: TLE line {which}, column {col}: {c!r} does not "
                                 f"fit the TLE layout ({want!r} there)")
    if len(line) == 69 and int(line[68]) != (total := _checksum(line)):
        raise ValueError(f"{where}: TLE line {which} fails its checksum (column 69 is "
                         f"{line[-1]!r}, the line sums to {total})")


def _fits(c: str, want: str, col: int) -> bool:
    """Whether character `c` fits column `col` (from 1) of a TLE layout, which has `want`."""
    if 3 <= col <= 7:  # the catalogue number, checked on its own
        return True
    if want == "N":
        return c.isdigit() or c == " "
    if want in "+-":
        return c in " +-" or (want == "-" and c.isdigit())
    if want in " .12":
        return c == want
    return True  # classification, international designator: free text


def _layout(template: str) -> re.Pattern[str]:
    """Return the pattern of the ASCII lines of 68 or 69 columns that `_fits` `template`."""
    ascii_chars = [chr(i) for i in range(128)]
    columns = []
    for col, want in enumerate(template, 1):
        fit = [c for c in ascii_chars if _fits(c, want, col)]
        columns.append("." if len(fit) == len(ascii_chars) else
                       "[" + "".join(re.escape(c) for c in fit) + "]")
    return re.compile("".join(columns[:68]) + f"(?:{columns[68]})?", re.DOTALL)


_LAYOUTS = {LINE1: _layout(LINE1), LINE2: _layout(LINE2)}
"""The TLE layouts' patterns (`_check_columns` says where a line that fails one fails)."""
_CHECKSUM_VALUES = bytes(i - 48 if 48 <= i <= 57 else int(i == 45) for i in range(256))
"""What an ASCII character adds to a TLE line's checksum: a digit its value, '-' one."""


def _checksum(line: str) -> int:
    """Return the checksum of an ASCII TLE line (as `sgp4.io.compute_checksum`)."""
    return sum(line[:68].encode("ascii").translate(_CHECKSUM_VALUES)) % 10


def _tle_entry(line1: str, line2: str, name: str, where: str, where2: str) -> CatalogEntry:
    """Entry of TLE lines `line1` (at `where`, ``file:line``) and `line2` (at `where2`)."""
    _check_columns(line1, LINE1, 1, where)
    _check_columns(line2, LINE2, 2, where2)
    if line1[2:7] != line2[2:7]:
        raise ValueError(f"{where}: catalogue numbers of lines 1 and 2 differ "
                         f"({line1[2:7]!r} and {line2[2:7]!r})")
    _check_epoch_day(line1, where)
    sat = Satrec.twoline2rv(line1, line2)
    _check_satrec(sat, where)
    return CatalogEntry(str(sat.satnum), name, sat, where)


def _check_epoch_day(line1: str, where: str) -> None:
    """ValueError unless line 1's epoch (columns 19-32, YYDDD.DDDDDDDD) has a day in 1-366.

    SGP4 reads day 999 or 000 of a year as days past or before it without a word, and day
    366 of a common year as the next 1 January: each is refused (days 1-365 of a common
    year, 1-366 of a leap year).
    """
    yy = int(line1[18:20])
    year = 1900 + yy if yy >= 57 else 2000 + yy  # the TLE convention
    days = 366 if calendar.isleap(year) else 365
    try:
        day = float(line1[20:32])
    except ValueError:
        raise ValueError(f"{where}: TLE line 1, columns 21-32: epoch day "
                         f"{line1[20:32]!r} is not a number") from None
    if not 1.0 <= day < days + 1.0:
        raise ValueError(f"{where}: TLE line 1, columns 19-32: day {day:g} of {year} is "
                         f"not in 1-{days}.999...")


def _check_satrec(sat: Satrec, where: str) -> None:
    """ValueError if SGP4 refused the element set, or a field is outside its domain.

    The domains are the module docstring's; the epoch must lie in the frames' range.
    """
    if sat.error:
        raise ValueError(f"{where}: SGP4 refuses the element set: "
                         f"{SGP4_ERRORS.get(sat.error, f'error {sat.error}')}")
    if sat.satnum < 1:
        raise ValueError(f"{where}: catalogue number 0 is no object's (NORAD catalogue "
                         f"numbers start at 1)")
    fields = {"inclination": sat.inclo, "right ascension of the node": sat.nodeo,
              "argument of perigee": sat.argpo, "mean anomaly": sat.mo,
              "eccentricity": sat.ecco, "mean motion": sat.no_kozai, "B*": sat.bstar,
              "mean motion derivative": sat.ndot, "its second derivative": sat.nddot}
    bad = [k for k, v in fields.items() if not math.isfinite(v)]
    if bad:
        raise ValueError(f"{where}: {', '.join(bad)} not finite")
    rev_day = sat.no_kozai * 1440.0 / (2.0 * math.pi)
    if not 0.0 <= sat.inclo <= math.pi:
        raise ValueError(f"{where}: inclination {math.degrees(sat.inclo):g} deg outside "
                         f"[0, 180]")
    if not (0.0 < rev_day <= MAX_MEAN_MOTION_REV_DAY and 0.0 <= sat.ecco < 1.0):
        raise ValueError(f"{where}: not a bound orbit above the Earth's surface (mean motion "
                         f"{rev_day:g} rev/day, eccentricity {sat.ecco:g})")
    if abs(sat.bstar) > MAX_BSTAR:
        raise ValueError(f"{where}: B* {sat.bstar:g} per Earth radius beyond "
                         f"{MAX_BSTAR:g} (not a physical drag term)")
    epoch = float((sat.jdsatepoch - UNIX_EPOCH_JD) * DAY_S + sat.jdsatepochF * DAY_S)
    check_epochs(epoch, f"{where}: epoch")


def parse_omm_xml(text: str, source: str = "<string>",
                  skip: Skipped | None = None) -> list[CatalogEntry]:
    """Entries of CCSDS OMM XML `text` (one per ``segment``, as `sgp4.omm.parse_xml` reads).

    `skip`: leave bad segments out and count them there (`formats.skipped`).
    """
    chunks = (text[i:i + CHUNK_BYTES] for i in range(0, len(text), CHUNK_BYTES))
    return list(_omm_xml_entries(chunks, source, skip))


def _omm_xml_entries(chunks: Iterable[str], source: str,
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
    """The segments of an OMM XML document, from its parser's events (`_omm_xml_entries`)."""

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
                    entry = _omm_entry(fields, where)
                    _check_new(entry, self.seen)
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
    return list(_omm_csv_entries(_numbered(text.splitlines()), source, skip))


def _omm_csv_entries(lines: Iterator[tuple[int, str]], source: str,
                     skip: Skipped | None = None) -> Iterator[CatalogEntry]:
    """Yield the entries of OMM CSV `lines` (numbered, as `_numbered` yields them).

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
                entry = _omm_entry(dict(fields), where)
                _check_new(entry, seen)
            except ValueError as exc:
                skip_or_raise(skip, exc, where, _omm_id(fields), _omm_name(fields))
            else:
                yield entry
    except csv.Error as exc:  # e.g. a field beyond csv's size limit (131,072 characters)
        raise ValueError(f"{source}:{number(k + 1)}: unreadable CSV row: {exc}") from None


def _omm_id(fields: dict[str, Any]) -> str:
    """Return an OMM's NORAD_CAT_ID as given (stripped, bounded), for a line about it."""
    value = fields.get("NORAD_CAT_ID")
    return _quote(value.strip())[1:-1] if isinstance(value, str) else ""


def _omm_name(fields: dict[str, Any]) -> str:
    """Return an OMM's OBJECT_NAME for a line about it ('' unless plain printable text)."""
    value = fields.get("OBJECT_NAME")
    if not isinstance(value, str) or len(value) > MAX_NAME or not value.isprintable():
        return ""
    return value.strip()


def _omm_entry(fields: dict[str, Any], where: str) -> CatalogEntry:
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
        raise ValueError(f"{where}: OMM {foreign[0]} {_quote(fields[foreign[0]])} is not "
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
                         f"{_quote(clean['CLASSIFICATION_TYPE'])} is not one letter (U, C, S)")
    for key, (lo, hi) in OMM_INTEGER_RANGES.items():
        text = clean.get(key, "0") or "0"
        if not (text.isascii() and text.isdigit() and lo <= int(text) <= hi):
            raise ValueError(f"{where}: OMM {key} {_quote(text)} is not an integer in "
                             f"{lo}..{hi}")
    if "." not in clean["EPOCH"]:  # whole seconds: sgp4.omm wants a fraction
        clean["EPOCH"] += ".0"
    sat = Satrec()
    try:
        omm.initialize(sat, clean)
    except (ValueError, TypeError, OverflowError) as exc:
        raise ValueError(f"{where}: malformed OMM field: {_quote(str(exc))}") from None
    _check_satrec(sat, where)
    name = (fields.get("OBJECT_NAME") or "").strip()
    _check_name(name, f"{where}: OMM OBJECT_NAME")
    return CatalogEntry(str(sat.satnum), name, sat, where)

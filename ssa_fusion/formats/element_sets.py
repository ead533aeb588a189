"""Catalogs of element sets: TLE/3LE and CCSDS OMM files, and their SGP4/SDP4 truth.

A catalog is a list of `CatalogEntry` (object id, name, `sgp4.api.Satrec`), read by
:func:`read_catalog` (here: the file read as a stream, its format told) from

* **TLE** (two lines per object, `tle`) or **3LE** (a name line, then the two lines; a Space-Track
  ``0 NAME`` name line works too). Lines starting with ``#`` and blank lines are skipped.
  Every line is checked column by column against the TLE layout (`sgp4.io.LINE1`/`LINE2`)
  and by its checksum (column 69, when present), because ``Satrec.twoline2rv`` accepts
  malformed lines silently (zeros for what it cannot read).
* **CCSDS OMM** (`omm`) in XML (NDM/XML, as CelesTrak and Space-Track serve it; parsed by lxml) or
  CSV (one row per object, CelesTrak's columns; by `csv`, its field size limit kept), the
  fields `sgp4.omm` reads, made element sets by `sgp4.omm.initialize`. OMM in KVN is not
  supported (`sgp4` does not read it): the error says so.

The format is told from the content, not the file name. A file is read as a stream, never
whole: a TLE/3LE or OMM/CSV file line by line, an OMM/XML file element by element (each
segment dropped once read), so a read holds its entries (and the longest line) but not the
file's text, whatever its size; `read_catalog`'s ``progress(bytes read, file size, objects
so far)`` says how far it got, every `PROGRESS_EVERY` objects. Malformed input raises
ValueError naming the file and the line (the XML segment for OMM/XML) in one bounded line
(values are quoted to `element_set_checks.MAX_QUOTE` characters), never an error from deep
inside `sgp4`, `csv` or lxml. Every element set is checked against the domain of its fields
before it is used (`element_set_checks`): finite angles, an inclination in [0, 180] deg, an
eccentricity in [0, 1), a mean motion of a bound orbit above the Earth's surface (0 < n <=
`MAX_MEAN_MOTION_REV_DAY`), |B*| <= `MAX_BSTAR`, an epoch ssa_fusion represents
(`timescales.EPOCH_MIN` .. `EPOCH_MAX`), and for OMM a one-letter classification and
integer counters in the TLE's ranges, a name of at most `MAX_NAME` characters. The object
id is the NORAD catalogue number as a decimal string (``"5"`` for ``00005``; Alpha-5
numbers as their integer, ``A0001`` -> ``"100001"``), the same for a TLE and the OMM of the
same object; an id twice in one file is an error.

`motion.element_sets.catalog_states` propagates every object to many epochs at once with
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

import codecs
import io
import locale
import os
from collections.abc import Callable, Iterable, Iterator
from pathlib import Path
from types import TracebackType
from typing import IO

from ssa_fusion.core.motion.element_sets import CatalogEntry
from ssa_fusion.formats.element_set_checks import numbered
from ssa_fusion.formats.omm import omm_csv_entries, omm_xml_entries, parse_omm_csv, parse_omm_xml
from ssa_fusion.formats.skipped import Skipped
from ssa_fusion.formats.tle import parse_tle, tle_entries

__all__ = ["CHUNK_BYTES", "PROGRESS_EVERY", "Progress", "parse_omm_csv", "parse_omm_xml",
           "parse_tle", "read_catalog"]

PROGRESS_EVERY = 4096
"""Objects between two calls of `read_catalog`'s progress callback."""
CHUNK_BYTES = 1 << 18
"""Bytes of a catalog file read at a time."""
_LINE_BREAKS = frozenset("\n\r\v\f\x1c\x1d\x1e\x85\u2028\u2029")
"""The characters `str.splitlines` ends a line at."""

Progress = Callable[[int, int, int], None]
"""``progress(bytes read, file size, objects so far)`` of `read_catalog`."""


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
                entries = omm_xml_entries(text, source, skip)
            elif head.startswith("CCSDS_OMM_VERS"):
                raise ValueError(f"{path}: OMM in KVN is not supported (sgp4 reads OMM as XML "
                                 f"or CSV); convert it to one of those")
            elif "NORAD_CAT_ID" in head.split(","):
                entries = omm_csv_entries(numbered(_lines(text)), source, skip)
            else:
                entries = tle_entries(numbered(_lines(text)), source, skip)
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



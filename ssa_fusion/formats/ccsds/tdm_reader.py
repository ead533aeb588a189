"""Reading a CCSDS TDM file as a stream of segments and observations (KVN or XML).

`ssa-fusion import tdm` takes files of any size: a KVN file is read line by line, an XML
file element by element (lxml ``iterparse``, each observation dropped once read), never
the whole file at once. `TdmReader` yields, in file order, a `SegmentMeta` when a segment's
metadata has been read, then one `Observation` per data keyword of that segment; its
`bytes_read` and `size` say how far it got (the importer's progress). The format is told
from the content: XML starts with ``<``.

What it checks, each a `CcsdsError` of one line naming the file, the line and the keyword
(values quoted to `quoting.MAX_QUOTE` characters):

* the file: readable, UTF-8, no KVN line longer than `MAX_LINE` bytes, XML well formed
  (no DTD, entity or network access is loaded; lxml's limits on text size and depth hold);
* the structure: KVN: ``CCSDS_TDM_VERS`` first, then segments of ``META_START`` ..
  ``META_STOP`` and ``DATA_START`` .. ``DATA_STOP``; XML: a ``<tdm>`` (alone, or in an
  ``<ndm>``) whose ``<body>`` holds ``<segment>``s of ``<metadata>`` and ``<data>`` of
  ``<observation>``s, each with an ``<EPOCH>``; at least one segment, and a file that
  ends inside one is truncated;
* keywords: those of TDM 2.0 (`HEADER_KEYWORDS`, `METADATA_KEYWORDS`, `DATA_KEYWORDS`; the
  names ccsds-ndm's TDM model has), a header or metadata keyword at most once;
* sizes: every value at most `MAX_VALUE` characters, at most `MAX_COMMENTS` comments kept
  per segment; a KVN data line is ``KEYWORD = EPOCH VALUE``, an optional ``[unit]`` after
  the value.

Values are not interpreted here: `tdm_in` parses the epochs and numbers and judges
what a segment says.
"""

from __future__ import annotations

import enum
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import IO, TYPE_CHECKING, Any, NamedTuple, NoReturn

from ssa_fusion.core.base.quoting import cut, one_line, quote, shown
from ssa_fusion.formats.ccsds.common import CcsdsError
from ssa_fusion.formats.files import raw_lines

if TYPE_CHECKING:
    from lxml import etree

MAX_LINE = 4096
"""Longest KVN line read, bytes (TDM lines are under 100; a longer one is not a TDM's)."""
MAX_VALUE = 256
"""Longest value of a keyword, characters (an epoch, a number, a participant's name)."""
MAX_COMMENTS = 1000
"""Comments kept per segment's metadata (the importer reads its own among them)."""

HEADER_KEYWORDS = frozenset({"CCSDS_TDM_VERS", "CREATION_DATE", "ORIGINATOR", "MESSAGE_ID"})
"""The keywords of a TDM header (XML: ``CCSDS_TDM_VERS`` is the root's ``version``)."""
METADATA_KEYWORDS = frozenset({
    "TRACK_ID", "DATA_TYPES", "TIME_SYSTEM", "START_TIME", "STOP_TIME",
    *(f"PARTICIPANT_{i}" for i in range(1, 6)), "MODE", "PATH", "PATH_1", "PATH_2",
    *(f"EPHEMERIS_NAME_{i}" for i in range(1, 6)), "TRANSMIT_BAND", "RECEIVE_BAND",
    "TURNAROUND_NUMERATOR", "TURNAROUND_DENOMINATOR", "TIMETAG_REF", "INTEGRATION_INTERVAL",
    "INTEGRATION_REF", "FREQ_OFFSET", "RANGE_MODE", "RANGE_MODULUS", "RANGE_UNITS",
    "ANGLE_TYPE", "REFERENCE_FRAME", "INTERPOLATION", "INTERPOLATION_DEGREE",
    "DOPPLER_COUNT_BIAS", "DOPPLER_COUNT_SCALE", "DOPPLER_COUNT_ROLLOVER",
    *(f"TRANSMIT_DELAY_{i}" for i in range(1, 6)), *(f"RECEIVE_DELAY_{i}" for i in range(1, 6)),
    "DATA_QUALITY", "CORRECTION_ANGLE_1", "CORRECTION_ANGLE_2", "CORRECTION_DOPPLER",
    "CORRECTION_MAG", "CORRECTION_RANGE", "CORRECTION_RCS", "CORRECTION_RECEIVE",
    "CORRECTION_TRANSMIT", "CORRECTION_ABERRATION_YEARLY", "CORRECTION_ABERRATION_DIURNAL",
    "CORRECTIONS_APPLIED"})
"""The keywords of a TDM 2.0 segment's metadata (COMMENT aside)."""
DATA_KEYWORDS = frozenset({
    "ANGLE_1", "ANGLE_2", "CARRIER_POWER", "CLOCK_BIAS", "CLOCK_DRIFT", "DOPPLER_COUNT",
    "DOPPLER_INSTANTANEOUS", "DOPPLER_INTEGRATED", "DOR", "MAG", "PC_N0", "PR_N0", "PRESSURE",
    "RANGE", "RCS", "RECEIVE_FREQ", *(f"RECEIVE_FREQ_{i}" for i in range(1, 6)),
    *(f"RECEIVE_PHASE_CT_{i}" for i in range(1, 6)), "RHUMIDITY", "STEC", "TEMPERATURE",
    *(f"TRANSMIT_FREQ_{i}" for i in range(1, 6)),
    *(f"TRANSMIT_FREQ_RATE_{i}" for i in range(1, 6)),
    *(f"TRANSMIT_PHASE_CT_{i}" for i in range(1, 6)), "TROPO_DRY", "TROPO_WET", "VLBI_DELAY"})
"""The observation keywords of TDM 2.0 (EPOCH and COMMENT aside)."""
_MARKERS = ("META_START", "META_STOP", "DATA_START", "DATA_STOP")
_HELD = frozenset({"observation", "metadata", "header"})
"""XML elements whose children are read when the element ends."""
_CHILDREN = {"tdm": {"header", "body"}, "body": {"segment"}, "segment": {"metadata", "data"},
             "data": {"observation", "COMMENT"}}
"""The elements a TDM's structural elements hold."""
_DEPTH = {"tdm": 0, "header": 1, "body": 1, "segment": 2, "metadata": 3, "data": 3}
"""How deep a TDM's elements are below its <tdm>."""


@dataclass
class SegmentMeta:
    """A segment's metadata as written: its keywords' values and comments, with their lines.

    Attributes
    ----------
    number : int
        The segment's number in the file, from 1.
    line : int
        The line it starts on (``META_START``, ``<segment>``).
    values : dict
        Keyword (capitals) -> (value as written, stripped; line).
    comments : list of (str, int)
        The metadata's comments (text, line), the first `MAX_COMMENTS`.
    """

    number: int
    line: int
    values: dict[str, tuple[str, int]] = field(default_factory=dict)
    comments: list[tuple[str, int]] = field(default_factory=list)

    def get(self, keyword: str) -> str | None:
        """Return the value of `keyword` ("" counts as absent: None)."""
        got = self.values.get(keyword)
        return got[0] if got and got[0] else None

    def line_of(self, keyword: str) -> int:
        """Return the line of `keyword` (the segment's first line if it is absent)."""
        got = self.values.get(keyword)
        return got[1] if got else self.line


class Observation(NamedTuple):
    """One data keyword of a segment at one epoch, as written."""

    keyword: str
    """The keyword (capitals), one of `DATA_KEYWORDS`."""
    epoch: str
    value: str
    unit: str
    """The unit written with the value ("" if none: KVN ``[unit]``, XML ``units=``)."""
    line: int


class _Kvn(enum.Enum):
    """Where a KVN reader is: what may come next."""

    HEADER = "the header"
    META = "META_START .. META_STOP"
    AFTER_META = "META_STOP .. DATA_START"
    DATA = "DATA_START .. DATA_STOP"
    BETWEEN = "DATA_STOP .. the next META_START"


class TdmReader:
    """The segments and observations of a TDM file, read as a stream (module docstring).

    Iterating it yields `SegmentMeta` and `Observation` items in file order; it can be
    iterated once. `bytes_read` / `size`: how far it has got.
    """

    def __init__(self, path: Path | str) -> None:
        self.path = Path(path)
        try:
            self.size = self.path.stat().st_size
        except OSError as exc:
            self._fail_file(exc)
        self.bytes_read = 0
        self.format = ""

    def _fail_file(self, exc: OSError) -> NoReturn:
        raise CcsdsError(f"{self.path}: cannot read: {exc.strerror or one_line(exc)}") \
            from None

    def fail(self, line: int, what: str) -> NoReturn:
        """Raise the one-line `CcsdsError` of `what` at `line` of the file (0: of the file)."""
        raise CcsdsError(f"{self.path}:{line}: {what}" if line > 0 else f"{self.path}: {what}")

    def __iter__(self) -> Iterator[SegmentMeta | Observation]:
        """Yield the file's segments' metadata and observations (module docstring)."""
        try:
            f = self.path.open("rb")
        except OSError as exc:
            self._fail_file(exc)
        with f:
            try:
                head = f.read(MAX_LINE).removeprefix(b"\xef\xbb\xbf").lstrip()
                f.seek(0)
            except OSError as exc:
                self._fail_file(exc)
            if not head:
                self.fail(1, "empty: not a CCSDS TDM")
            self.format = "xml" if head.startswith(b"<") else "kvn"
            yield from (self._xml(f) if self.format == "xml" else self._kvn(f))

    # --------------------------------------------------------------------------------------
    # KVN
    # --------------------------------------------------------------------------------------
    def _lines(self, f: IO[bytes]) -> Iterator[tuple[int, str]]:
        """Yield (line number, text stripped) of the non-blank lines, each checked."""
        for n, raw in enumerate(raw_lines(f, MAX_LINE, self._fail_file), 1):
            self.bytes_read += len(raw)
            body = raw.rstrip(b"\r\n")
            if len(body) > MAX_LINE:
                self.fail(n, f"line longer than {MAX_LINE} bytes (starts "
                             f"{quote(body[:MAX_LINE].decode('utf-8', 'replace'))}): "
                             f"not a TDM's")
            try:
                text = body.decode("utf-8")
            except UnicodeDecodeError as exc:
                self.fail(n, f"not UTF-8 text (byte {exc.start + 1} of the line)")
            if n == 1:
                text = text.removeprefix("\ufeff")
            text = text.strip()
            if text:
                yield n, text

    def _kvn(self, f: IO[bytes]) -> Iterator[SegmentMeta | Observation]:
        """Yield the segments and observations of a KVN TDM."""
        state = _Kvn.HEADER
        header: set[str] = set()
        seg: SegmentMeta | None = None
        segments = 0
        data_keywords = DATA_KEYWORDS
        n = 0
        for n, s in self._lines(f):
            if state is _Kvn.DATA:  # the hot path: KEYWORD = EPOCH VALUE
                key, eq, rest = s.partition("=")
                key = key.rstrip()
                if eq and key in data_keywords:
                    parts = rest.split()
                    if len(parts) == 2 and len(rest) <= MAX_VALUE:
                        yield Observation(key, parts[0], parts[1], "", n)
                        continue
                    yield self._data_line(n, key, rest)
                    continue
            if s in _MARKERS:
                if state is _Kvn.HEADER and not header:
                    self.fail(n, f"{s} before CCSDS_TDM_VERS: not a CCSDS TDM")
                state, seg, segments = self._marker(n, s, state, seg, segments)
                if s == "META_STOP" and seg is not None:
                    yield seg
                continue
            if s.startswith("COMMENT") and (len(s) == 7 or s[7] in " \t="):
                if state is _Kvn.META and seg is not None and \
                        len(seg.comments) < MAX_COMMENTS:
                    seg.comments.append((s[7:].strip().removeprefix("=").strip(), n))
                continue
            key, eq, rest = s.partition("=")
            key, rest = key.strip(), rest.strip()
            if state is _Kvn.HEADER and not header and (not eq or key != "CCSDS_TDM_VERS"):
                self._not_tdm(n, key if eq else s)
            if not eq:
                self.fail(n, f"neither KEYWORD = VALUE, COMMENT nor a block marker: "
                             f"{quote(s)}")
            if state is _Kvn.HEADER:
                self._header_line(n, key, rest, header)
            elif state is _Kvn.META and seg is not None:
                self._meta_line(n, key, rest, seg)
            else:  # DATA lines with an unknown keyword, or a keyword outside its block
                known = key in DATA_KEYWORDS or key in METADATA_KEYWORDS or \
                    key in HEADER_KEYWORDS
                self.fail(n, f"{shown(key)}: " + (f"not where it belongs ({state.value})"
                                                 if known else "not a TDM keyword"))
        if state is _Kvn.HEADER and not header:
            self.fail(max(n, 1), "no CCSDS_TDM_VERS line: not a CCSDS TDM")
        if state is not _Kvn.BETWEEN and segments:
            want = {_Kvn.META: "META_STOP", _Kvn.AFTER_META: "DATA_START",
                    _Kvn.DATA: "DATA_STOP"}[state]
            self.fail(n, f"the file ends inside segment {segments} (line "
                         f"{seg.line if seg else n}) without its {want}: truncated?")
        if not segments:
            self.fail(n, "no segment (META_START .. META_STOP, DATA_START .. DATA_STOP)")

    def _data_line(self, n: int, key: str, rest: str) -> Observation:
        """Return the observation of a data line that is not plain ``EPOCH VALUE``."""
        if len(rest) > MAX_VALUE:
            self.fail(n, f"{key}: value longer than {MAX_VALUE} characters: {quote(rest)}")
        unit = ""
        text = rest.strip()
        if text.endswith("]") and "[" in text:
            cut_at = text.rfind("[")
            text, unit = text[:cut_at].strip(), text[cut_at + 1:-1].strip()
        parts = text.split()
        if len(parts) != 2:
            self.fail(n, f"{key}: want EPOCH VALUE, got {quote(rest.strip())}")
        return Observation(key, parts[0], parts[1], unit, n)

    def _marker(self, n: int, marker: str, state: _Kvn, seg: SegmentMeta | None,
                segments: int) -> tuple[_Kvn, SegmentMeta | None, int]:
        """Return the state after a block marker (and the segment, the segments so far)."""
        after = {"META_START": ((_Kvn.HEADER, _Kvn.BETWEEN), _Kvn.META),
                 "META_STOP": ((_Kvn.META,), _Kvn.AFTER_META),
                 "DATA_START": ((_Kvn.AFTER_META,), _Kvn.DATA),
                 "DATA_STOP": ((_Kvn.DATA,), _Kvn.BETWEEN)}
        before, new = after[marker]
        if state not in before:
            self.fail(n, f"{marker} in {state.value}")
        if marker == "META_START":
            segments += 1
            seg = SegmentMeta(segments, n)
        return new, seg, segments

    def _not_tdm(self, n: int, first: str) -> NoReturn:
        """Refuse a file whose first line `first` is not CCSDS_TDM_VERS."""
        what = "another CCSDS message" if first.startswith("CCSDS_") and \
            first.endswith("_VERS") else "not a CCSDS message"
        self.fail(n, f"{quote(first)}: not a CCSDS TDM ({what}; a TDM's first line is "
                     f"CCSDS_TDM_VERS = 2.0)")

    def _header_line(self, n: int, key: str, value: str, header: set[str]) -> None:
        """Check one header line (the first must be CCSDS_TDM_VERS)."""
        if key not in HEADER_KEYWORDS:
            where = "metadata" if key in METADATA_KEYWORDS else "data" \
                if key in DATA_KEYWORDS else ""
            self.fail(n, f"{shown(key)}: " + (f"a {where} keyword in the header (META_START "
                                              f"missing?)" if where else
                                              "not a TDM header keyword"))
        if key in header:
            self.fail(n, f"{key}: given twice in the header")
        if len(value) > MAX_VALUE:
            self.fail(n, f"{key}: value longer than {MAX_VALUE} characters: {quote(value)}")
        if key == "CCSDS_TDM_VERS" and value not in ("1.0", "2.0"):
            self.fail(n, f"CCSDS_TDM_VERS = {quote(value)}: this reader knows versions 1.0 "
                         f"and 2.0")
        header.add(key)

    def _meta_line(self, n: int, key: str, value: str, seg: SegmentMeta) -> None:
        """Record one metadata line of `seg`."""
        if key not in METADATA_KEYWORDS:
            self.fail(n, f"segment {seg.number}: {shown(key)}: not a TDM metadata keyword")
        if key in seg.values:
            self.fail(n, f"segment {seg.number}: {key}: given twice (first at line "
                         f"{seg.values[key][1]})")
        if len(value) > MAX_VALUE:
            self.fail(n, f"segment {seg.number}: {key}: value longer than {MAX_VALUE} "
                         f"characters: {quote(value)}")
        seg.values[key] = (value, n)

    # --------------------------------------------------------------------------------------
    # XML
    # --------------------------------------------------------------------------------------
    def _xml(self, f: IO[bytes]) -> Iterator[SegmentMeta | Observation]:
        """Yield the segments and observations of an XML TDM (lxml iterparse)."""
        from lxml import etree

        source = _Counted(f, self)
        events = etree.iterparse(source, events=("end",), resolve_entities=False,
                                 no_network=True, load_dtd=False, huge_tree=False,
                                 remove_comments=True, remove_pis=True)
        segments = 0
        seg: SegmentMeta | None = None
        seg_elem: etree._Element | None = None
        root_checked = False
        try:
            for _, elem in events:
                if not root_checked:
                    self._xml_root(elem)
                    root_checked = True
                parent = elem.getparent()
                up = _local(parent.tag) if parent is not None else ""
                if up in _HELD:  # read with its parent, at the parent's end
                    continue
                tag = _local(elem.tag)
                if tag == "observation" and up == "data":
                    if seg is None or parent is None or parent.getparent() is not seg_elem:
                        self.fail(_line(elem, 0), "<observation> outside the <data> of a "
                                                  "segment whose <metadata> came first")
                    yield from self._xml_observation(elem, seg)
                elif tag == "metadata" and up == "segment" and _in_tdm(elem, _DEPTH[tag]):
                    segments += 1
                    seg = self._xml_metadata(elem, segments, _line(parent, 0))
                    seg_elem = parent
                    yield seg
                elif tag == "header" and up == "tdm":
                    self._xml_header(elem)
                elif tag == "segment" and up == "body" and _in_tdm(elem, _DEPTH[tag]):
                    with_metadata = elem is seg_elem
                    if not with_metadata:
                        self.fail(_line(elem, 0), "<segment> without <metadata>")
                elif up in _CHILDREN and tag not in _CHILDREN[up] and \
                        _in_tdm(elem, _DEPTH[up] + 1):
                    self.fail(_line(elem, 0), f"<{cut(tag)}> in <{up}>: not an element of a "
                                              f"TDM there (it holds "
                                              f"{', '.join(sorted(_CHILDREN[up]))})")
                _drop(elem)  # whatever it is: read, or not a TDM's (another of an <ndm>)
        except etree.XMLSyntaxError as exc:
            line = exc.lineno or (exc.position[0] if exc.position else 0)
            self.fail(line, f"not well-formed XML: {one_line(exc.msg or exc, 200)}")
        if not segments:
            self.fail(0, "no TDM <segment> in the file: not a TDM with data")

    def _xml_root(self, elem: etree._Element) -> None:
        """Check that the document is a TDM (a ``<tdm>``, or an ``<ndm>`` holding one)."""
        root = elem.getroottree().getroot()
        name = _local(root.tag)
        if name not in ("tdm", "ndm"):
            self.fail(_line(root, 1), f"not a TDM (its root element is "
                                            f"<{cut(name)}>)")

    def _xml_header(self, elem: etree._Element) -> None:
        """Check a ``<header>``'s keywords."""
        seen: set[str] = set()
        for child in elem:
            name = _local(child.tag)
            if name == "COMMENT":
                continue
            if name not in HEADER_KEYWORDS:
                self.fail(_line(child, 0), f"<{cut(name)}>: not a TDM header keyword")
            if name in seen:
                self.fail(_line(child, 0), f"{name}: given twice in the header")
            seen.add(name)
            self._xml_text(child, name)

    def _xml_metadata(self, elem: etree._Element, number: int, line: int) -> SegmentMeta:
        """Return the `SegmentMeta` of a ``<metadata>``."""
        seg = SegmentMeta(number, line)
        for child in elem:
            name = _local(child.tag)
            n = _line(child, line)
            if name == "COMMENT":
                if len(seg.comments) < MAX_COMMENTS:
                    seg.comments.append((self._xml_text(child, name, MAX_LINE), n))
                continue
            if name not in METADATA_KEYWORDS:
                self.fail(n, f"segment {number}: <{cut(name)}>: not a TDM metadata keyword")
            if name in seg.values:
                self.fail(n, f"segment {number}: {name}: given twice (first at line "
                             f"{seg.values[name][1]})")
            seg.values[name] = (self._xml_text(child, f"segment {number}: {name}"), n)
        return seg

    def _xml_observation(self, elem: etree._Element, seg: SegmentMeta
                         ) -> Iterator[Observation]:
        """Yield the data keywords of an ``<observation>``."""
        epoch = None
        items: list[tuple[str, str, str, int]] = []
        for child in elem:
            name = _local(child.tag)
            n = _line(child, _line(elem, 0))
            if name == "EPOCH":
                epoch = self._xml_text(child, "EPOCH")
            elif name in DATA_KEYWORDS:
                if items:  # TDM/XML: one data keyword an observation
                    self.fail(n, f"segment {seg.number}: <observation> with a second data "
                                 f"keyword <{cut(name)}> (after <{items[0][0]}>): TDM/XML "
                                 f"gives one per observation")
                items.append((name, self._xml_text(child, name), child.get("units") or "", n))
            elif name != "COMMENT":
                self.fail(n, f"segment {seg.number}: <{cut(name)}>: not a TDM data keyword")
        if epoch is None:
            self.fail(_line(elem, 0), f"segment {seg.number}: <observation> without "
                                            f"<EPOCH>")
        for name, value, unit, n in items:
            yield Observation(name, epoch, value, unit.strip(), n)

    def _xml_text(self, elem: etree._Element, what: str, limit: int = MAX_VALUE) -> str:
        """Return the stripped text of `elem`, refused if over `limit` characters."""
        if len(elem):
            self.fail(_line(elem, 0), f"{what}: holds elements, not a value")
        text = (elem.text or "").strip()
        if limit == MAX_VALUE:  # a value: its white space as xsd:token has it
            text = " ".join(text.split())
        if len(text) > limit:
            self.fail(_line(elem, 0), f"{what}: value longer than {limit} characters: "
                                            f"{quote(text)}")
        return text


class _Counted:
    """A binary file whose `read` counts the bytes into its reader's `bytes_read`."""

    def __init__(self, f: IO[bytes], reader: TdmReader) -> None:
        self.f, self.reader = f, reader

    def read(self, n: int = -1) -> bytes:
        """Read up to `n` bytes, counted."""
        data = self.f.read(n)
        self.reader.bytes_read += len(data)
        return data


def _line(elem: etree._Element, default: int) -> int:
    """Return the line an element starts on (`default` if lxml does not know it)."""
    line = getattr(elem, "sourceline", None)
    return line if isinstance(line, int) else default


def _local(tag: Any) -> str:  # noqa: ANN401 - lxml tags are str, or a function for comments
    """Return an element's tag without its namespace."""
    text = tag if isinstance(tag, str) else ""
    return text.rsplit("}", 1)[-1]


def _in_tdm(elem: etree._Element, depth: int) -> bool:
    """Return True if `elem` is `depth` levels below a <tdm> (`_DEPTH`)."""
    node: etree._Element | None = elem
    for _ in range(depth):
        node = node.getparent() if node is not None else None
    return node is not None and _local(node.tag) == "tdm"


def _drop(elem: etree._Element) -> None:
    """Free an element read: its content and the siblings before it (lxml keeps them)."""
    elem.clear()
    parent = elem.getparent()
    if parent is not None:
        while elem.getprevious() is not None:
            del parent[0]

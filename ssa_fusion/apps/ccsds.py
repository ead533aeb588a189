"""CCSDS in and out: `ssa-fusion export oem|tdm BAG` and `ssa-fusion import tdm FILE --bag OUT`.

* **OEM** out of a bag (`formats.ccsds.oem`): the filter's estimates (``/ssa/estimate``), one
  segment per object (all objects, or ``--object ID``), state and covariance per epoch, UTC,
  in ``GCRF``, ``EME2000`` or ``TEME`` (``--frame``). A bag whose estimates say another
  frame than ``gcrf`` (``eci``: recorded before the frames were the real Earth's) is
  refused. With ``--predict-until UTC`` (a laser bag's): the fitted orbit propagated beyond
  the data with its covariance instead (`predict_oem`).
* **TDM** out of a bag (`formats.ccsds.tdm_out`): its real range/azimuth/elevation (``AZEL``) and
  right ascension/declination (``RADEC``, ``ICRF`` or ``EME2000``) measurements
  (``/ssa/measurement``, SENSOR), UTC.
* **TDM into a bag** (`formats.ccsds.tdm_in`) that `ssa-fusion replay` runs through surrogate and
  filter: range/az/el or ra/dec of one station and one object, epochs in UTC, TAI, TT or
  GPS, written on ``/ssa/measurement``, each logged at its stamp.

Frames: the GCRF has the axes of the ICRF (they differ by origin only, which a direction
does not have), so RA/Dec "in GCRF" and "in ICRF" are the same numbers. The TDM 2.0 schema
(and with it ccsds-ndm) knows ``ICRF`` but not ``GCRF`` as a ``REFERENCE_FRAME``: exports
say ``ICRF``; imports read ``GCRF`` as ``ICRF``.

Both exports read estimates and measurements recorded as a catalog's batches
(``/ssa/estimate_batch``, ``/ssa/measurement_batch``) as if recorded one message each
(`bagio.read_records`).

Files are written and read with the ``ccsds-ndm`` library (KVN or XML; reading tells the
format from the content; `formats.ccsds.common`). Conventions, and what is not supported:
docs/CCSDS.md.

TDM carries no measurement noise. The noise of imported measurements is, in this order,
``--sigma`` (AZEL) / ``--sigma-radec`` (RADEC), the metadata comment ``ssa_fusion sigma:``
that `export tdm` writes, else the station's sensor: of the sites file ``--sites`` (stations
of one's own, `formats.sites`, which PARTICIPANTs may then name), else the built-in preset
(`stations.SENSORS`).

`cli` registers this module under two commands, ``export`` and ``import``; the parser's
name (its last word) says which one `add_arguments` builds. Here only what is not the
format's (that is all `formats.ccsds`'): the bag read for the exports and written by the
import, and the commands' options and runs.
"""

from __future__ import annotations

import argparse
import contextlib
import sys
from collections import Counter, defaultdict
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TextIO

from ssa_fusion.apps.args import add_sites
from ssa_fusion.apps.partial import removed_if_unfinished
from ssa_fusion.apps.progress_lines import ProgressLines
from ssa_fusion.core.base import types
from ssa_fusion.core.earth.frames import Frame
from ssa_fusion.formats.ccsds.common import (
    LAYOUTS,
    SIGMA_COMMENT,
    TDM_EXPORT_FRAMES,
    AngleFrame,
    CcsdsError,
    OemFrame,
    counts_said,
    ndm_format,
    write_ndm,
)
from ssa_fusion.formats.ccsds.oem import ephemerides, oem_document
from ssa_fusion.formats.ccsds.tdm_in import read_tdm
from ssa_fusion.formats.ccsds.tdm_out import tdm_document
from ssa_fusion.formats.sites import SiteFileError, load_sites
from ssa_fusion.ros import bagio, messages
from ssa_fusion.ros.topics import TOPIC_ESTIMATE, TOPIC_MEASUREMENT, TOPIC_SMOOTHED, TOPIC_TRUTH


# ------------------------------------------------------------------------------------------
# bags
# ------------------------------------------------------------------------------------------
@dataclass
class BagContents:
    """What the exports read from a bag (core units), and the frames its states say."""

    estimates: list[types.StateEstimate] = field(default_factory=list)
    smoothed: list[types.StateEstimate] = field(default_factory=list)
    """`replay --offline --smooth`'s smoothed estimates (``/ssa/estimate_smoothed``)."""
    measurements: list[types.Measurement] = field(default_factory=list)
    state_frames: dict[str, set[str]] = field(default_factory=lambda: defaultdict(set))
    """``header.frame_id`` of the StateEstimate messages by topic (/ssa/estimate,
    /ssa/truth); `messages.estimate_from_msg` does not keep it."""


def load_bag(bag: Path) -> BagContents:
    """Return the estimates and measurements of `bag`, and the frames of its state messages.

    Measurements and estimates recorded as batches are read as their rows
    (`bagio.read_records`); messages that do not decode and records refused are skipped
    with a warning (as `evaluate.load` does).
    """
    out = BagContents()
    undecodable: Counter[str] = Counter()
    refused: Counter[tuple[str, str]] = Counter()
    topics = (TOPIC_ESTIMATE, TOPIC_SMOOTHED, TOPIC_TRUTH, TOPIC_MEASUREMENT)
    states = {TOPIC_ESTIMATE: out.estimates, TOPIC_SMOOTHED: out.smoothed}
    for m in bagio.read_records(bag, topics=topics, undecodable=undecodable, refused=refused):
        if m.topic == TOPIC_MEASUREMENT:
            out.measurements.append(messages.measurement_from_msg(m.msg))
            continue
        out.state_frames[m.topic].add(str(m.msg.header.frame_id))
        if m.topic in states:
            states[m.topic].append(messages.estimate_from_msg(m.msg))
    for line in bagio.left_out(undecodable, refused):
        print(f"warning: {bag}: {line}", file=sys.stderr)
    return out


def require_gcrf(bag: Path, contents: BagContents, topics: Iterable[str], what: str) -> None:
    """Check that every state message on `topics` says frame ``gcrf``.

    CcsdsError (one line naming the bag and the frame) otherwise: `what` (e.g. "estimates")
    would be exported as GCRF.
    """
    for topic in topics:
        other = sorted(f for f in contents.state_frames.get(topic, ()) if f != Frame.GCRF)
        if other:
            raise CcsdsError(
                f"{bag}: its {topic} messages say frame {other[0]!r}, not {Frame.GCRF!r} "
                f"(recorded before ssa_fusion's frames were the real Earth's): its {what} "
                f"are not GCRF; re-record the bag with this version to export it")


def write_measurement_bag(out: Path, measurements: Iterable[types.Measurement],
                          progress: Callable[[int], None] | None = None) -> int:
    """Write the bag `out` of `measurements` on /ssa/measurement, each logged at its stamp.

    What `replay` plays; it derives /clock from the stamps. One message at a time;
    `progress(written so far)` every `PROGRESS_EVERY` messages. A bag not written to its end
    (an error, an interrupt) is removed. Returns the number of messages written.
    """
    classes = bagio.rosbags_classes()
    n = 0
    with removed_if_unfinished(out):
        writer = bagio.BagWriter(out)
        try:
            writer.add_topic(TOPIC_MEASUREMENT, f"{bagio.MSG_PACKAGE}/msg/Measurement")
            for m in measurements:
                msg = messages.measurement_to_msg(m, classes)
                stamp = msg.header.stamp
                writer.write_msg(TOPIC_MEASUREMENT, stamp.sec * 1_000_000_000 + stamp.nanosec,
                                 msg)
                n += 1
                if progress is not None and n % PROGRESS_EVERY == 0:
                    progress(n)
        except BaseException:
            with contextlib.suppress(OSError):  # a full disk fails the close too
                writer.close()
            raise
        writer.close()
    return n


PROGRESS_EVERY = 8192
"""Messages between two calls of `write_measurement_bag`'s progress callback."""


class ImportProgress(ProgressLines):
    """The progress lines of `import tdm` on stderr (`ProgressLines`): its measurements."""

    def __init__(self, every_s: float = 5.0, stream: TextIO | None = None) -> None:
        super().__init__("import tdm", "measurements", every_s, stream)


# ------------------------------------------------------------------------------------------
# command line
# ------------------------------------------------------------------------------------------
def add_arguments(p: argparse.ArgumentParser) -> None:
    """Add the `export` or the `import` subcommands to `p` (by the last word of its name)."""
    if p.prog.split()[-1] == "import":
        _add_import(p)
    else:
        _add_export(p)


def _add_format(p: argparse.ArgumentParser) -> None:
    """Add ``--format`` (kvn or xml) to `p`."""
    p.add_argument("--format", choices=("kvn", "xml"), default=None,
                   help="file format (default: xml if --out ends in .xml, else kvn)")


def _add_export(p: argparse.ArgumentParser) -> None:
    """Add `export oem` and `export tdm` to `p`."""
    sub = p.add_subparsers(dest="ccsds_command", required=True, metavar="{oem,tdm}")
    _add_export_command(
        sub, "oem", run_export_oem, "the filter's estimates with covariance as a CCSDS OEM",
        "Write the estimates of a bag (/ssa/estimate) as a CCSDS Orbit Ephemeris Message: one "
        "segment per object, state (km, km/s) and 6x6 covariance (km^2 ...) per epoch, UTC, "
        "in GCRF (their frame), EME2000 or TEME.",
        [f.value for f in OemFrame], OemFrame.GCRF,
        "REF_FRAME: GCRF (the estimates as they are; default), EME2000 (IAU 2006 frame bias) "
        "or TEME (SGP4's)")
    _add_export_command(
        sub, "tdm", run_export_tdm,
        "the real range/az/el and ra/dec measurements as a CCSDS TDM",
        "Write the sensor measurements of a bag (/ssa/measurement) as a CCSDS Tracking Data "
        "Message, UTC: range/azimuth/elevation as RANGE km, ANGLE_1/ANGLE_2 (AZEL, deg); "
        "right ascension/declination as ANGLE_1/ANGLE_2 (RADEC, deg, astrometric).",
        [f.value for f in TDM_EXPORT_FRAMES], AngleFrame.ICRF,
        "REFERENCE_FRAME of RADEC angles: ICRF (the GCRF values: the same axes; default) or "
        "EME2000 (rotated by the IAU 2006 frame bias)")


def _add_export_command(sub: argparse._SubParsersAction[argparse.ArgumentParser], name: str,
                        run_it: Callable[[argparse.Namespace], int], help_text: str,
                        description: str, frames: list[str], frame: str,
                        frame_help: str) -> None:
    """Add `export <name>` to `sub`, which `run_it` runs.

    Its options: ``--frame`` (`frames`, default `frame`), the bag, ``--object``, ``--out``,
    ``--format``.
    """
    q = sub.add_parser(name, help=help_text, description=description)
    q.add_argument("--frame", type=str.upper, choices=frames, default=str(frame),
                   help=frame_help)
    q.add_argument("bag", type=Path, help="rosbag2 directory or .mcap file")
    q.add_argument("--object", default=None, help="only this object_id (default: all)")
    q.add_argument("--out", type=Path, default=None,
                   help=f"file to write; must not exist (default: BAG.{name})")
    _add_format(q)
    if name == "oem":
        q.add_argument("--predict-until", default=None, metavar="UTC",
                       help="instead of the estimates: the fitted orbit of the bag's laser "
                            "ranges propagated from its epoch (the last range) to this epoch "
                            "(ISO 8601, UTC), with its covariance")
        q.add_argument("--step", type=float, default=60.0, metavar="S",
                       help="with --predict-until: seconds between states (default 60)")
        q.add_argument("--smoothed", action="store_true",
                       help="the smoothed estimates (/ssa/estimate_smoothed, the definitive "
                            "orbit of `replay --offline --smooth`) instead of the filter's")
    q.set_defaults(_ccsds_run=run_it, _suffix=f".{name}")


def _add_import(p: argparse.ArgumentParser) -> None:
    """Add `import tdm` and `import crd` (`crd_import`) to `p`."""
    from ssa_fusion.apps.crd_import import add_import_crd

    sub = p.add_subparsers(dest="ccsds_command", required=True, metavar="{tdm,crd}")
    t = sub.add_parser("tdm", help="a CCSDS TDM (range, az/el or ra/dec) into a bag `replay` "
                                   "runs",
                       description="Read a CCSDS Tracking Data Message (KVN or XML; UTC, TAI, "
                                   "TT or GPS): RANGE (km), ANGLE_1/ANGLE_2 (AZEL, deg) or "
                                   "ANGLE_1/ANGLE_2 (RADEC in GCRF, ICRF or EME2000, deg) of a "
                                   "known station and one object, into a bag of "
                                   "/ssa/measurement that `ssa-fusion replay` runs through "
                                   "surrogate and filter.")
    t.add_argument("file", type=Path, help="the TDM file")
    t.add_argument("--bag", type=Path, required=True, help="bag to write; must not exist")
    add_sites(t, "stations of your own that the TDM's PARTICIPANTs may name besides the "
                 "built-in ones, and their noise")
    for layout in LAYOUTS.values():
        t.add_argument(layout.option, type=float, nargs=len(layout.sigma_names), default=None,
                       metavar=layout.sigma_names, dest=f"sigma_{layout.angle_type.lower()}",
                       help=f"measurement noise (1 sigma) of every {layout.angle_type} "
                            f"measurement (default: the TDM's '{SIGMA_COMMENT}' comment, "
                            f"else the station's sensor preset)")
    t.set_defaults(_ccsds_run=run_import_tdm)
    add_import_crd(sub)


def run(args: argparse.Namespace) -> int:
    """Exit 0 with one summary line; 2 with one `error:` line."""
    try:
        return int(args._ccsds_run(args))
    except (CcsdsError, SiteFileError, bagio.BagError, OSError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2


def _export(args: argparse.Namespace) -> tuple[Path, str, BagContents]:
    """Return the file to write (``--out``, else next to the bag), its format, the bag read."""
    bag: Path = args.bag
    out = args.out or (bag.with_suffix("") if bag.suffix == ".mcap" else bag).with_name(
        bag.name.removesuffix(".mcap") + args._suffix)
    if out.exists():
        raise CcsdsError(f"{out} exists already; choose another --out")
    return out, ndm_format(out, args.format), load_bag(bag)


def run_export_oem(args: argparse.Namespace) -> int:
    """Run `export oem`: write the bag's estimates as an OEM; return 0."""
    if args.smoothed and args.predict_until is not None:
        raise CcsdsError("--smoothed and --predict-until: one or the other (a prediction "
                         "starts from the fit of a laser bag)")
    out, fmt, contents = _export(args)
    said = ""
    if args.predict_until is not None:
        from ssa_fusion.apps.predict_oem import predicted

        states, said = predicted(args.bag, args.predict_until, args.step)
        ephem = ephemerides(states, args.object)
    else:
        topic = TOPIC_SMOOTHED if args.smoothed else TOPIC_ESTIMATE
        states = contents.smoothed if args.smoothed else contents.estimates
        if args.smoothed and not states:
            raise CcsdsError(f"{args.bag} has no {TOPIC_SMOOTHED}: write them with "
                             f"`ssa-fusion replay {args.bag} --offline --smooth` and export "
                             f"from the bag it writes")
        require_gcrf(args.bag, contents, (topic,), "estimates")
        ephem = ephemerides(states, args.object)
        said = "the smoothed estimates" if args.smoothed else ""
    with removed_if_unfinished(out):
        write_ndm(oem_document(ephem, OemFrame(args.frame)), out, fmt)
    n = sum(len(v) for v in ephem.values())
    print(f"export oem: {n} states with covariance of {len(ephem)} object(s) "
          f"({', '.join(ephem)}) in {args.frame}, UTC" + (f": {said}" if said else "")
          + f" -> {out} ({fmt.upper()})")
    return 0


def run_export_tdm(args: argparse.Namespace) -> int:
    """Run `export tdm`: write the bag's real measurements as a TDM; return 0."""
    out, fmt, contents = _export(args)
    ms = contents.measurements
    if args.object is not None:
        ms = [m for m in ms if m.object_id == args.object]
    if any(m.kind == types.Kind.RA_DEC for m in ms):  # their RA/Dec are in the states' frame
        require_gcrf(args.bag, contents, (TOPIC_ESTIMATE, TOPIC_TRUTH), "RA/Dec measurements")
    export = tdm_document(ms, AngleFrame(args.frame))
    with removed_if_unfinished(out):
        write_ndm(export.doc, out, fmt)
    said = counts_said(export.counts)
    left = (f", {export.skipped} forecasts or other kinds left out" if export.skipped else "")
    print(f"export tdm: {said} measurements in {len(export.doc.body.segment)} segment(s)"
          f"{left} -> {out} ({fmt.upper()})")
    return 0


def _names(names: Sequence[str], most: int = 5) -> str:
    """Return `names` joined by commas, the first `most` of them and how many more."""
    more = f" and {len(names) - most} more" if len(names) > most else ""
    return ", ".join(names[:most]) + more


def run_import_tdm(args: argparse.Namespace) -> int:
    """Run `import tdm`: write the TDM's measurements to a new bag; return 0.

    The file is read as a stream, then the bag written in epoch order (`formats.ccsds.tdm_in`);
    a line on stderr every few seconds says how far either has got.
    """
    if args.bag.exists():
        raise CcsdsError(f"{args.bag} exists already; choose another --bag")
    sigma = {layout.kind: s for layout in LAYOUTS.values()
             if (s := getattr(args, f"sigma_{layout.angle_type.lower()}", None)) is not None}
    sites = load_sites(args.sites) if args.sites else {}
    progress = ImportProgress()
    imported = read_tdm(args.file, sigma, sites, progress=progress.reading)
    progress.total = len(imported)
    write_measurement_bag(args.bag, imported.measurements(), progress=progress.writing)
    used = imported.used_segments()
    objects = sorted({s.object_id for s in used})
    stations = sorted({s.station for s in used})
    said = counts_said(imported.counts())
    from ssa_fusion.apps.replay_outcome import suggestion  # estimation: imported when said

    span = float(imported.t.max() - imported.t.min()) if len(imported) else 0.0
    print(f"import tdm: {said} measurements of {_names(objects)} from "
          f"{_names(stations)}{imported.left_out()} -> {args.bag}\n"
          + suggestion(args.bag, len(imported), span, args.sites))
    return 0

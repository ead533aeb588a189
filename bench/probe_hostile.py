"""Hostile-conditions probe: hostile inputs and conditions against the product's commands
and nodes, each judged on whether the product handled it cleanly.

Classes of probes (a class number is the finding it re-creates):

1. stalls (SIGSTOP for 10 s, then SIGCONT) of sensor_sim or of a filter shard during a
   catalog run, in lockstep and open loop: no valid row refused, the accounting adds up;
2. epochs after 2038 or before 1970 in element sets and in `import tdm`;
3. `live` whose recorder cannot create its bag (under a file, a read-only directory, a
   symlink loop): the run ends within seconds and says why;
5. a full disk under the recorder (a 256 KiB tmpfs in the probe's own mount namespace):
   one line naming the bag, the bag whole (read as it is), `bag repair` onto the disk
   filled to its last block one line;
6. garbage in: `import tdm` and element sets with non-finite or impossible values;
7. floods: 100,000 distinct object ids and a 1 MB object id to a catalog filter shard,
   negative and 1e300 covariances and one object too many to a catalog surrogate (the graph
   tests that send them, `test/graph/test_flood_graph.py` and
   `test_catalog_surrogate_graph.py`, judge: capped, counted, memory bounded);
8. bad parameters: `-p NAME:=[]` to the nodes, offline `--params-file` of `report` and
   `replay` (NaN, wrong types, deep nesting, an alias bomb), a params file of 1M keys;
9. SIGTERM to `live --catalog` at several moments: 128 + 15 and "stopped by SIGTERM";
10. large inputs: a 100 MB one-line catalog, catalog options without `--catalog`
    (`--large`: also a 100 MB TDM import);
11. where the compiled kernels' cache is (the user's own, never one others may write), and
    (`--listen`) what sockets a `live` run's nodes bind beyond loopback;
12. silent accepts: input a reader used to take as something else (a YAML ``0110`` height
    read as octal 72, a 100 kB site id, escape codes in a TDM object id, a TDM epoch outside
    its segment's START/STOP, a one-way ``PATH`` imported as two-way, full-width digits, two
    values in one TDM/XML observation, day 366 of a common year in a TLE, NUL in a name,
    catalogue number 00000, an XInclude in an OMM field, ``q: true`` in a params file);
13. damaged bags: one flipped byte in a chunk, 4 kB of garbage inserted or written over at
    one third: `bag repair` keeps every intact chunk and says what it lost;
14. lockstep under load and pauses, 15. run identity and strangers, 16. what a run leaves to
    other local users (shared memory, logs, sockets): `probe_sharing.py`.

Each probe runs with a wall timeout; its outcome is one of ``clean`` (the expected exit
code; where an error is expected, a bounded error line; no traceback in any output or node
log; nothing silently accepted), ``traceback``, ``hang`` (the timeout), ``silent`` (garbage
accepted, or data lost without a counted cause) or ``unclean`` (no traceback and nothing
lost, but not the expected exit code or an unbounded error). The last line printed is JSON
with the counts per outcome.

Run it (the graph probes start ROS nodes, so in a network namespace of their own)::

    PYTHONPATH=$PWD tools/isolated.sh .venv/bin/python bench/probe_hostile.py [--large]

``--only 2,6`` runs some classes; ``--no-graph`` only the probes that start no node graph.
As root it re-runs itself in a mount namespace of its own (``unshare -m``) to mount its
small tmpfs there; elsewhere the disk probes are skipped, and the table says so.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import re
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from collections import Counter
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path

from bench_lockstep import burners as cpu_burners

ROOT = Path(__file__).resolve().parents[1]
CLI = (sys.executable, "-m", "ssa_fusion.apps.cli")
NODE_DIR = Path(sys.prefix) / "lib" / "ssa_fusion"
SAMPLE_TLE = ROOT / "config" / "catalogs" / "sample.tle"
SAMPLE_OMM_CSV = ROOT / "config" / "catalogs" / "sample_omm.csv"
SAMPLE_OMM_XML = ROOT / "config" / "catalogs" / "sample_omm.xml"
SAMPLE_BAG = ROOT / "bags" / "sample_iss_j2_rae"
OUTCOMES = ("clean", "traceback", "hang", "silent", "unclean", "skipped")
MAX_ERROR_LINE = 500  # characters: a longer error line is not "bounded"
CAPTURE = 1 << 20  # bytes of each stream kept for judging
MOUNT_NS_ENV = "SSA_PROBE_MOUNT_NS"


@dataclass
class Result:
    """What one command did: exit code (None: it hung), output, wall seconds, node logs."""

    rc: int | None
    out: str
    err: str
    seconds: float
    logs: str = ""
    notes: list[str] = field(default_factory=list)


@dataclass
class Verdict:
    """One probe's outcome, with the command that shows it."""

    cls: str
    name: str
    outcome: str
    rc: int | None
    seconds: float
    line: str
    command: str


Judge = Callable[[Result], tuple[str, str]]


@dataclass
class Probe:
    """A probe: `run` makes its inputs in a scratch directory and runs it; `judge` says how
    it went once no hang and no traceback were found (outcome, and why when not clean)."""

    cls: str
    name: str
    run: Callable[[Path], tuple[Result, str]]
    judge: Judge
    graph: bool = False


# --------------------------------------------------------------------------- running


def _read(path: Path) -> str:
    """Return the first `CAPTURE` bytes of a file as text (and its size when cut)."""
    with path.open("rb") as f:
        data = f.read(CAPTURE + 1)
    text = data[:CAPTURE].decode("utf-8", "replace")
    if len(data) > CAPTURE:
        text += f"\n[... {path.stat().st_size} bytes in all]"
    return text


def _stop_group(p: subprocess.Popen[bytes]) -> None:
    """End a process group this probe started: SIGTERM, then SIGKILL after 10 s."""
    for sig, wait in ((signal.SIGTERM, 10.0), (signal.SIGKILL, 5.0)):
        with contextlib.suppress(ProcessLookupError):
            os.killpg(p.pid, sig)
        try:
            p.wait(wait)
            return
        except subprocess.TimeoutExpired:
            continue


def run_cmd(argv: Sequence[str], scratch: Path, timeout: float,
            during: Callable[[subprocess.Popen[bytes], float], None] | None = None,
            env: dict[str, str] | None = None) -> Result:
    """Run `argv` from the repository root with a wall timeout (rc None when it hung).

    `during(popen, start)` runs while it does (signals to it, stalls of its nodes).
    """
    scratch.mkdir(parents=True, exist_ok=True)
    out_f, err_f = scratch / "stdout.txt", scratch / "stderr.txt"
    start = time.monotonic()
    with out_f.open("wb") as o, err_f.open("wb") as e:
        p = subprocess.Popen(list(argv), cwd=ROOT, stdout=o, stderr=e, stdin=subprocess.DEVNULL,
                             start_new_session=True, env={**os.environ, **(env or {})})
        rc: int | None
        try:
            if during is not None:
                during(p, start)
            rc = p.wait(max(0.1, timeout - (time.monotonic() - start)))
        except subprocess.TimeoutExpired:
            rc = None
            _stop_group(p)
    return Result(rc, _read(out_f), _read(err_f), time.monotonic() - start)


def node_logs(out: Path) -> str:
    """Return every node log of a `live` run directory, concatenated."""
    logs = sorted((out / "logs").glob("*.*")) if (out / "logs").is_dir() else []
    return "\n".join(_read(f) for f in logs if f.suffix in (".err", ".out"))


def first_error(r: Result) -> str:
    """Return the first line of stderr that is not the network namespace's note."""
    for line in r.err.splitlines():
        if line.strip() and not line.startswith("isolated:"):
            return line.strip()
    return ""


def error_lines(r: Result) -> list[str]:
    """Return the lines of stderr that say an error."""
    return [ln for ln in r.err.splitlines() if re.search(r"\berror\b", ln, re.IGNORECASE)]


def shell(argv: Sequence[str]) -> str:
    """Return `argv` as one shell command line (PYTHONPATH and cwd as the probe's)."""
    import shlex

    words = ["ssa-fusion", *argv[3:]] if tuple(argv[:3]) == CLI else list(argv)
    return " ".join(shlex.quote(str(w)) for w in words)


# --------------------------------------------------------------------------- judging


def refused(says: str | None = None, rcs: tuple[int, ...] = (2,)) -> Judge:
    """Expect an exit code of `rcs` with one bounded error line (matching `says`)."""

    def judge(r: Result) -> tuple[str, str]:
        if r.rc == 0:
            return "silent", "accepted (exit 0)"
        if r.rc not in rcs:
            return "unclean", f"exit {r.rc}, expected {rcs}"
        lines = error_lines(r)
        if not lines:
            return "unclean", "no error line"
        if len(lines[0]) > MAX_ERROR_LINE:
            return "unclean", f"error line of {len(lines[0])} characters"
        if says and not re.search(says, r.err, re.IGNORECASE):
            return "unclean", f"does not say /{says}/"
        return "clean", ""

    return judge


def refused_or_counted(counted: str = r"left out|skipped|invalid|refused") -> Judge:
    """Expect a refusal in one line (exit 2), or exit 0 that counts what it left out."""
    strict = refused()

    def judge(r: Result) -> tuple[str, str]:
        if r.rc == 0:
            if re.search(counted, r.out + r.err, re.IGNORECASE):
                return "clean", ""
            return "silent", "exit 0 and nothing counted as left out"
        return strict(r)

    return judge


def accepted(says: str | None = None) -> Judge:
    """Expect exit 0 (valid input; `says` in its output)."""

    def judge(r: Result) -> tuple[str, str]:
        if r.rc != 0:
            return "unclean", f"valid input refused: exit {r.rc}"
        if says and not re.search(says, r.out + r.err, re.IGNORECASE):
            return "unclean", f"does not say /{says}/"
        return "clean", ""

    return judge


def judge(p: Probe, r: Result) -> tuple[str, str]:
    """Return a probe's outcome: hang and traceback first, then its own judge."""
    if r.rc is None:
        return "hang", "timed out"
    if any("Traceback (most recent call last)" in t for t in (r.out, r.err, r.logs)):
        return "traceback", "a traceback in its output or a node log"
    outcome, why = p.judge(r)
    if r.notes and outcome == "clean":
        return "unclean", "; ".join(r.notes)
    return outcome, why


# --------------------------------------------------------------------------- inputs

GOOD_ROWS = [(f"2025-01-01T00:{m:02d}:{s:02d}.000", f"{9468.26 - 16.0 * i:.3f}",
              f"{35.81 - 1.5 * i:.3f}", f"{-43.7 + 0.1 * i:.3f}")
             for i, (m, s) in enumerate((k // 2, 30 * (k % 2)) for k in range(20))]


def tdm_kvn(rows: Sequence[tuple[str, str, str, str]], time_system: str = "UTC") -> str:
    """Return a KVN TDM of range/az/el rows (epoch, range km, az deg, el deg)."""
    head = ("CCSDS_TDM_VERS = 2.0\nCREATION_DATE = 2025-01-02T00:00:00\nORIGINATOR = probe\n"
            f"META_START\nTIME_SYSTEM = {time_system}\nPARTICIPANT_1 = columbus\n"
            "PARTICIPANT_2 = probe_object\nMODE = SEQUENTIAL\nPATH = 1,2,1\n"
            "RANGE_UNITS = km\nANGLE_TYPE = AZEL\nMETA_STOP\nDATA_START\n")
    body = "".join(f"RANGE = {e} {r}\nANGLE_1 = {e} {a}\nANGLE_2 = {e} {el}\n"
                   for e, r, a, el in rows)
    return head + body + "DATA_STOP\n"


def tdm_xml(rows: Sequence[tuple[str, str, str, str]]) -> str:
    """Return an XML TDM of range/az/el rows (as `tdm_kvn`)."""
    obs = "".join(
        f"<observation><EPOCH>{e}</EPOCH><{k}{u}>{v}</{k}></observation>\n"
        for e, r, a, el in rows
        for k, u, v in (("RANGE", "", r), ("ANGLE_1", ' units="deg"', a),
                        ("ANGLE_2", ' units="deg"', el)))
    return ('<?xml version="1.0" encoding="UTF-8"?>\n<tdm id="CCSDS_TDM_VERS" version="2.0">'
            "<header><CREATION_DATE>2025-01-02T00:00:00</CREATION_DATE>"
            "<ORIGINATOR>probe</ORIGINATOR></header><body><segment><metadata>"
            "<TIME_SYSTEM>UTC</TIME_SYSTEM><PARTICIPANT_1>columbus</PARTICIPANT_1>"
            "<PARTICIPANT_2>probe_object</PARTICIPANT_2><MODE>SEQUENTIAL</MODE>"
            "<PATH>1,2,1</PATH><RANGE_UNITS>km</RANGE_UNITS><ANGLE_TYPE>AZEL</ANGLE_TYPE>"
            f"</metadata><data>\n{obs}</data></segment></body></tdm>\n")


def with_row(i: int | None, epoch: str | None = None, rng: str | None = None,
             az: str | None = None, el: str | None = None) -> list[tuple[str, str, str, str]]:
    """Return the good rows with row `i` (every row when None) changed where given."""
    rows = []
    for k, (e, r, a, l2) in enumerate(GOOD_ROWS):
        if i is None or k == i:
            e = e if epoch is None else epoch.replace("{s}", f"{k * 30 % 60:02d}")
            r, a, l2 = (r if rng is None else rng, a if az is None else az,
                        l2 if el is None else el)
        rows.append((e, r, a, l2))
    return rows


def tle_checksum(line: str) -> str:
    """Return a TLE line (68 columns) with its modulo-10 checksum appended."""
    s = sum(int(c) if c.isdigit() else (1 if c == "-" else 0) for c in line[:68])
    return line[:68] + str(s % 10)


def tle_objects() -> list[tuple[str, str, str]]:
    """Return the sample catalog's 3LE objects (name, line 1, line 2)."""
    lines = [ln.rstrip("\n") for ln in SAMPLE_TLE.read_text().splitlines()
             if ln.strip() and not ln.startswith("#")]
    return [(lines[k], lines[k + 1], lines[k + 2]) for k in range(0, len(lines) - 2, 3)]


def tle_edit(obj: tuple[str, str, str], line: int, col: int, text: str,
             checksum: bool = True) -> tuple[str, str, str]:
    """Return an object with `text` written into TLE line `line` (1, 2) at column `col`
    (1-based, as the TLE format counts), checksum recomputed unless told not to."""
    name, l1, l2 = obj
    old = l1 if line == 1 else l2
    new = old[: col - 1] + text + old[col - 1 + len(text):]
    new = tle_checksum(new) if checksum else new
    return (name, new, l2) if line == 1 else (name, l1, new)


def tle_text(objs: Sequence[tuple[str, str, str]]) -> str:
    """Return 3LE text of objects."""
    return "".join(f"{n}\n{a}\n{b}\n" for n, a, b in objs)


def omm_csv(**fields: str) -> str:
    """Return the sample OMM CSV (header and its one row) with fields replaced."""
    lines = [ln for ln in SAMPLE_OMM_CSV.read_text().splitlines() if not ln.startswith("#")]
    head = lines[0].split(",")
    row = dict(zip(head, lines[1].split(","), strict=True))
    row.update(fields)
    return ",".join(head) + "\n" + ",".join(row[h] for h in head) + "\n"


def omm_xml(**fields: str) -> str:
    """Return the sample OMM XML with elements replaced (``metadata``/``data`` emptied
    when given as "")."""
    text = SAMPLE_OMM_XML.read_text()
    for k, v in fields.items():
        if k in ("metadata", "data"):
            text = re.sub(rf"<{k}>.*?</{k}>", f"<{k}>{v}</{k}>", text, flags=re.S)
        else:
            text = re.sub(rf"<{k}>[^<]*</{k}>", f"<{k}>{v}</{k}>", text)
    return text


# --------------------------------------------------------------------------- probe kinds


def cli_probe(cls: str, name: str, args: Sequence[str], judge_: Judge,
              files: dict[str, str | bytes | Callable[[Path], None]] | None = None,
              timeout: float = 90.0) -> Probe:
    """A probe of one CLI command; ``{NAME}`` in `args` is the scratch path of file NAME."""

    def run(d: Path) -> tuple[Result, str]:
        for fname, content in (files or {}).items():
            path = d / fname
            path.parent.mkdir(parents=True, exist_ok=True)
            if callable(content):
                content(path)
            elif isinstance(content, bytes):
                path.write_bytes(content)
            else:
                path.write_text(content)
        argv = [*CLI, *(a.replace("{D}", str(d)) for a in args)]
        r = run_cmd(argv, d / "run", timeout)
        if (d / "out").is_dir():
            r.logs = node_logs(d / "out")
        return r, shell(argv)

    return Probe(cls, name, run, judge_)


def tdm_probe(cls: str, name: str, text: str, judge_: Judge, rerun: bool = True,
              suffix: str = ".tdm") -> Probe:
    """`import tdm` of `text`; after a refusal, the same bag path must take a good TDM."""

    def run(d: Path) -> tuple[Result, str]:
        d.mkdir(parents=True, exist_ok=True)
        f, bag = d / f"in{suffix}", d / "bag"
        f.write_text(text)
        argv = [*CLI, "import", "tdm", str(f), "--bag", str(bag)]
        r = run_cmd(argv, d / "run", 120.0)
        if rerun and r.rc not in (0, None):
            good = d / "good.tdm"
            good.write_text(tdm_kvn(GOOD_ROWS))
            again = run_cmd([*CLI, "import", "tdm", str(good), "--bag", str(bag)],
                            d / "rerun", 60.0)
            if again.rc != 0:
                r.notes.append(f"a re-run onto the same --bag failed: {first_error(again)}")
        return r, shell(argv)

    return Probe(cls, name, run, judge_)


def catalog_probe(cls: str, name: str, text: str | bytes | Callable[[Path], None],
                  judge_: Judge, suffix: str = ".tle", timeout: float = 120.0) -> Probe:
    """`live --catalog` of a catalog file (if it is accepted, an hour of its first element
    set spread into 20 objects, so that some are seen: `--synthetic`)."""
    return cli_probe(cls, name, ["live", "--catalog", "{D}/cat" + suffix, "--synthetic", "20",
                                 "--duration", "1", "--no-surrogate", "--time-scale", "max",
                                 "--out", "{D}/out"], judge_, {"cat" + suffix: text}, timeout)


def node_probe(cls: str, name: str, node: str, ros_args: Sequence[str], judge_: Judge,
               files: dict[str, str] | None = None, timeout: float = 30.0) -> Probe:
    """A node started with `ros_args` (``{D}`` the scratch directory); a node still running
    at the timeout took them: judged ``silent`` by `refused`, not a hang."""

    def run(d: Path) -> tuple[Result, str]:
        d.mkdir(parents=True, exist_ok=True)
        for fname, content in (files or {}).items():
            (d / fname).write_text(content)
        argv = [str(NODE_DIR / node), "--ros-args",
                *(a.replace("{D}", str(d)) for a in ros_args)]
        r = run_cmd(argv, d / "run", timeout,
                    env={"ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST"})
        if r.rc is None:
            r.rc = 0  # it ran on: it accepted them
            r.notes.append("the node started and ran on")
        return r, shell(argv)

    return Probe(cls, name, run, judge_)


# --------------------------------------------------------------------------- the probes


def tdm_probes(large: bool) -> Iterator[Probe]:
    """Classes 2 and 6 for `import tdm` (and 10's 100 MB import with `large`)."""
    yield tdm_probe("6", "tdm good (control)", tdm_kvn(GOOD_ROWS), accepted(), rerun=False)
    yield tdm_probe("6", "tdm xml good (control)", tdm_xml(GOOD_ROWS), accepted(),
                    rerun=False, suffix=".xml")
    for year in ("2039", "2100", "9999", "0001", "1957", "1969"):
        epoch = f"{year}-01-01T00:00:{{s}}.000"
        yield tdm_probe("2", f"tdm one epoch in {year}", tdm_kvn(with_row(5, epoch=epoch)),
                        refused_or_counted())
        yield tdm_probe("2", f"tdm every epoch in {year}", tdm_kvn(with_row(None, epoch=epoch)),
                        refused())
        yield tdm_probe("2", f"tdm xml one epoch in {year}", tdm_xml(with_row(5, epoch=epoch)),
                        refused_or_counted(), suffix=".xml")
    yield tdm_probe("2", "tdm TAI epoch 2100", tdm_kvn(with_row(None, epoch="2100-06-01T00:00:{s}"),
                                                       "TAI"), refused())
    values = {"range": ("nan", "NaN", "inf", "-inf", "-5.0", "0", "1e400", "1e300", "0x10"),
              "az": ("nan", "inf", "1e308"),
              "el": ("1000", "-1000", "90.0001", "nan")}
    for what, bad in values.items():
        for v in bad:
            yield tdm_probe("6", f"tdm one {what} = {v}", tdm_kvn(with_row(7, **{
                {"range": "rng"}.get(what, what): v})), refused_or_counted())
    # an azimuth of -1000 deg is 80 deg: wrapped into [0, 360) (docs/CCSDS.md, "Left out")
    yield tdm_probe("6", "tdm one az = -1000 (wrapped)", tdm_kvn(with_row(7, az="-1000")),
                    accepted())
    for v in ("nan", "inf", "-5.0"):
        yield tdm_probe("6", f"tdm every range = {v}", tdm_kvn(with_row(None, rng=v)), refused())
    epochs = {"day-of-year 999": "2025-999T00:00:00", "day-of-year 000": "2025-000T00:00:00",
              "hour 99": "2025-01-01T99:00:00", "month 13": "2025-13-01T00:00:00",
              "second 75": "2025-01-01T00:00:75", "unreadable": "garbage",
              "empty date": "T", "year 99999": "99999-01-01T00:00:00"}
    for what, e in epochs.items():
        yield tdm_probe("6", f"tdm one epoch {what}", tdm_kvn(with_row(3, epoch=e)),
                        refused_or_counted())
    yield tdm_probe("6", "tdm empty RANGE value", tdm_kvn(with_row(4, rng="")),
                    refused_or_counted())
    yield tdm_probe("6", "tdm xml empty <RANGE>", tdm_xml(with_row(4, rng="")),
                    refused_or_counted(), suffix=".xml")
    yield tdm_probe("6", "tdm xml <RANGE> NaN", tdm_xml(with_row(4, rng="NaN")),
                    refused_or_counted(), suffix=".xml")
    yield tdm_probe("6", "tdm xml every <RANGE> empty", tdm_xml(with_row(None, rng="")),
                    refused(), suffix=".xml")
    yield tdm_probe("6", "tdm empty file", "", refused())
    yield tdm_probe("6", "tdm binary garbage", "\x00\x01\xff" * 1000, refused())
    yield tdm_probe("6", "tdm header only", tdm_kvn([]), refused())
    yield tdm_probe("6", "tdm truncated mid-line", tdm_kvn(GOOD_ROWS)[:-40], refused_or_counted())
    if large:
        def big(path: Path) -> None:
            rows = [(f"2025-01-{1 + k // 86400 % 28:02d}T{k // 3600 % 24:02d}:"
                     f"{k // 60 % 60:02d}:{k % 60:02d}.000", "9000.0", "30.0", "40.0")
                    for k in range(0, 86400 * 28, 1)]
            with path.open("w") as f:
                f.write(tdm_kvn([])[:-len("DATA_STOP\n")])  # the header, to DATA_START
                for k in range(0, len(rows)):
                    e = rows[k][0]
                    f.write(f"RANGE = {e} 9000.0\nANGLE_1 = {e} 30.0\nANGLE_2 = {e} 40.0\n")
                    if f.tell() > 100_000_000:
                        break
                f.write("DATA_STOP\n")

        yield cli_probe("10", "tdm import of 100 MB", ["import", "tdm", "{D}/big.tdm", "--bag",
                                                      "{D}/bag"],
                        accepted(), {"big.tdm": big}, timeout=900.0)


def catalog_probes() -> Iterator[Probe]:
    """Classes 2 and 6 for element sets (TLE, OMM CSV and XML), through `live --catalog`."""
    objs = tle_objects()
    cbers = objs[0]
    tle_edits = {
        "inclination nan": (2, 9, "     nan"), "inclination inf": (2, 9, "     inf"),
        "inclination 999": (2, 9, "999.0000"), "inclination -98": (2, 9, "-98.4283"),
        "RAAN nan": (2, 18, "     nan"), "mean anomaly inf": (2, 44, "     inf"),
        "mean motion inf": (2, 53, "        inf"), "mean motion nan": (2, 53, "        nan"),
        "mean motion 0": (2, 53, " 0.00000000"), "mean motion -14": (2, 53, "-14.3547808"),
        "mean motion 99": (2, 53, "99.99999999"), "eccentricity 9999999": (2, 27, "9999999"),
        "B* 0.99999e9": (1, 54, " 99999+9"), "B* nan": (1, 54, "     nan"),
        "Alpha-5 number 1A2B3": (1, 3, "1A2B3"),
        "epoch day 999": (1, 21, "999.78615833"), "epoch day 000": (1, 21, "000.00000000"),
        "epoch year xx": (1, 19, "xx"), "epoch day nan": (1, 21, "         nan"),
        "epoch year 39 (2039)": (1, 19, "39"), "epoch year 56 (2056)": (1, 19, "56"),
        "epoch year 57 (1957)": (1, 19, "57"), "epoch year 71 (1971)": (1, 19, "71"),
    }
    for what, (line, col, text) in tle_edits.items():
        yield catalog_probe("6", f"tle {what}", tle_text([tle_edit(cbers, line, col, text)]),
                            refused())
    yield catalog_probe("6", "tle control (sample's first object)", tle_text([cbers]),
                        accepted(r"lost: 0"))
    # valid element sets, however unusual: the largest element set number of the field's
    # four digits, a one-letter classification other than U (the OMM reader's rule too)
    for what, (line, col, text) in {"element set number 9999": (1, 65, "9999"),
                                    "classification X": (1, 8, "X")}.items():
        yield catalog_probe("6", f"tle {what} (valid)",
                            tle_text([tle_edit(cbers, line, col, text)]), accepted(r"lost: 0"))
    yield catalog_probe("6", "tle Alpha-5 number A2345 (valid)",
                        tle_text([tle_edit(tle_edit(cbers, 1, 3, "A2345"), 2, 3, "A2345")]),
                        accepted(r"lost: 0"))
    yield catalog_probe("6", "tle bad checksum",
                        tle_text([tle_edit(cbers, 1, 69, "0" if cbers[1][68] != "0" else "1",
                                           checksum=False)]), refused())
    yield catalog_probe("6", "tle line 2 of another object",
                        tle_text([(cbers[0], cbers[1], objs[1][2])]), refused())
    yield catalog_probe("6", "tle truncated line 2", tle_text([(*cbers[:2], cbers[2][:40])]),
                        refused())
    yield catalog_probe("6", "tle names only", "CBERS 2\nDELTA 1 DEB\n", refused())
    yield catalog_probe("6", "tle empty file", "", refused())
    yield catalog_probe("6", "tle binary garbage", b"\x00\xff\xfe" * 5000, refused())
    nan = tle_edit
    four = [objs[0], nan(objs[1], 2, 9, "     nan"), objs[2], nan(objs[3], 2, 9, "     nan")]
    yield cli_probe("6", "tle 4 objects, 2 NaN", ["live", "--catalog", "{D}/cat.tle",
                                                 "--duration", "2", "--no-surrogate",
                                                 "--time-scale", "max", "--out", "{D}/out"],
                    refused_or_counted(r"\b2\b.*(nan|skipped|invalid|not finite)"),
                    {"cat.tle": tle_text(four)})
    for year in ("2100", "2039", "9999", "0001", "1957", "1969"):
        yield catalog_probe("2", f"omm csv epoch {year}",
                            omm_csv(EPOCH=f"{year}-01-01T00:00:00"), refused(), ".csv")
        yield catalog_probe("2", f"omm xml epoch {year}",
                            omm_xml(EPOCH=f"{year}-01-01T00:00:00"), refused(), ".xml")
    csv_edits = {"INCLINATION": ("nan", "inf", "999", "-1"), "MEAN_MOTION": ("inf", "nan", "0"),
                 "BSTAR": ("1e9", "nan", "-inf"), "ECCENTRICITY": ("1.5", "-0.1"),
                 "NORAD_CAT_ID": ("1A2B3", "-1", "99999999999"), "CLASSIFICATION_TYPE": ("UU",),
                 "ELEMENT_SET_NO": ("9" * 30, "-5"), "EPOCH": ("", "garbage", "2025-999T00:00:00"),
                 "RA_OF_ASC_NODE": ("1e309",), "MEAN_ANOMALY": ("", )}
    for key, bads in csv_edits.items():
        for v in bads:
            yield catalog_probe("6", f"omm csv {key} = {v[:12]}", omm_csv(**{key: v}),
                                refused(), ".csv")
    yield catalog_probe("6", "omm csv OBJECT_NAME of 200,000 characters",
                        omm_csv(OBJECT_NAME="X" * 200_000), refused_or_counted(), ".csv")
    yield catalog_probe("6", "omm csv header only", omm_csv().splitlines()[0] + "\n", refused(),
                        ".csv")
    for key, v in (("INCLINATION", "NaN"), ("MEAN_MOTION", "INF"), ("BSTAR", "1e9"),
                   ("NORAD_CAT_ID", "1A2B3"), ("CLASSIFICATION_TYPE", "UU"),
                   ("ELEMENT_SET_NO", "9" * 30), ("metadata", ""), ("data", "")):
        yield catalog_probe("6", f"omm xml {key} = {v[:12] or 'empty'}", omm_xml(**{key: v}),
                            refused(), ".xml")
    yield catalog_probe("6", "omm xml not closed", omm_xml()[:-200], refused(), ".xml")


def param_probes() -> Iterator[Probe]:
    """Class 8: node parameters and offline params files."""
    for node, name in (("filter", "p0_sigma"), ("sensor_sim", "gaps"), ("recorder", "topics"),
                       ("surrogate", "topics")):
        yield node_probe("8", f"{node} -p {name}:=[]", node, ["-p", f"{name}:=[]"],
                         refused(r"error:"))
    for node, arg in (("filter", "q:=.nan"), ("filter", "q:=-1.0"), ("filter", "q:=[1,2]"),
                      ("filter", "p0_sigma:=[.nan,1.0,1.0,1.0,1.0,1.0]"),
                      ("filter", "p0_sigma:=[1.0,2.0]"), ("sensor_sim", "gaps:=[1.0]"),
                      ("sensor_sim", "time_scale:=0.0"), ("catalog_filter", "max_objects:=-1"),
                      ("catalog_filter", "shards:=0"), ("catalog_filter", "shard:=5"),
                      ("catalog_surrogate", "max_objects:=0"), ("recorder", "bag:=''")):
        yield node_probe("8", f"{node} -p {arg}", node, ["-p", arg], refused(r"error:"))
    big = "filter:\n  ros__parameters:\n" + "".join(f"    k{i}: {i}\n" for i in range(1_000_000))
    yield node_probe("8", "filter --params-file of 1M keys", "filter",
                     ["--params-file", "{D}/big.yaml"], refused(r"error:"), {"big.yaml": big})
    bomb = ("a: &a [x, x, x, x, x, x, x, x, x]\n"
            + "".join(f"{chr(98 + i)}: &{chr(98 + i)} [{', '.join(['*' + chr(97 + i)] * 9)}]\n"
                      for i in range(8))
            + "filter:\n  ros__parameters:\n    q: *i\n")
    files = {"q nan": "filter:\n  ros__parameters:\n    q: .nan\n",
             "q [1,2]": "filter:\n  ros__parameters:\n    q: [1, 2]\n",
             "q string": "filter:\n  ros__parameters:\n    q: hello\n",
             "p0_sigma short": "filter:\n  ros__parameters:\n    p0_sigma: [1.0]\n",
             "deep nesting": ("filter:\n  ros__parameters:\n    q: " + "[" * 5000 + "]" * 5000
                              + "\n"),
             "alias bomb": bomb,
             "top-level list": "- 1\n- 2\n",
             "not utf-8": "filter:\n  ros__parameters:\n    q: \udcff\n",
             "empty": "",
             "unknown key": "filter:\n  ros__parameters:\n    no_such_parameter: 1.0\n",
             "1M keys": big}
    for what, text in files.items():
        data = text.encode("utf-8", "surrogateescape")
        for cmd in (["report", str(SAMPLE_BAG), "--out", "{D}/rep"],
                    ["replay", str(SAMPLE_BAG), "--offline", "--out", "{D}/rep"]):
            yield cli_probe("8", f"{cmd[0]} --params-file {what}",
                            [*cmd, "--params-file", "{D}/p.yaml"], refused(), {"p.yaml": data},
                            timeout=120.0)


def _tdm_meta(old: str, new: str) -> str:
    """The good KVN TDM with `old` in its metadata replaced by `new`."""
    text = tdm_kvn(GOOD_ROWS)
    assert old in text
    return text.replace(old, new, 1)


def _sites(height: str = "110", site_id: str = "probe_radar") -> str:
    """A sites file of one radar (`height` and `site_id` as written in the YAML)."""
    return ("sites:\n  - {id: " + site_id + ", latitude_deg: 40.0, longitude_deg: -83.0, "
            "height_m: " + height + ", type: radar,\n     noise: {range_m: 20, azimuth_deg: "
            "0.02, elevation_deg: 0.02}, cadence_s: 10, min_elevation_deg: 5}\n")


def _tle_3le(name: str = "PROBE", day: str | None = None, number: str | None = None) -> str:
    """The sample's first 3LE object with its name, epoch day (YYDDD) or number replaced."""
    _, l1, l2 = tle_objects()[0]
    if day is not None:
        l1 = l1[:18] + day + l1[23:]
    if number is not None:
        l1, l2 = l1[:2] + number + l1[7:], l2[:2] + number + l2[7:]
    return f"{name}\n{tle_checksum(l1[:68])}\n{tle_checksum(l2[:68])}\n"


def silent_accept_probes() -> Iterator[Probe]:
    """Class 12: inputs once taken silently as something else, each refused in one line."""
    good = tdm_kvn(GOOD_ROWS)
    for what, sites in (("height_m: 0110 (octal 72)", _sites(height="0110")),
                        ("height_m: 1:50 (base 60)", _sites(height="1:50")),
                        ("a 100 kB site id", _sites(site_id="x" * 100_000))):
        yield cli_probe("12", f"sites file {what}",
                        ["import", "tdm", "{D}/in.tdm", "--sites", "{D}/sites.yaml", "--bag",
                         "{D}/bag"], refused(), {"in.tdm": good, "sites.yaml": sites})
    yield tdm_probe("12", "tdm object id with escape codes",
                    _tdm_meta("probe_object", "probe\x1b[2J\x1b[31mobject"), refused())
    yield tdm_probe("12", "tdm epoch 5 years outside START/STOP",
                    _tdm_meta("META_STOP", "START_TIME = 2030-01-01T00:00:00\n"
                              "STOP_TIME = 2030-01-02T00:00:00\nMETA_STOP"), refused())
    yield tdm_probe("12", "tdm one-way PATH = 1,2 for a range", _tdm_meta("PATH = 1,2,1",
                                                                          "PATH = 1,2"),
                    refused())
    yield tdm_probe("12", "tdm full-width digits", tdm_kvn(with_row(3, rng="９４６８.２")),
                    refused())
    two = tdm_xml(GOOD_ROWS).replace("<RANGE>", "<RANGE>9000</RANGE><RANGE>", 1)
    yield tdm_probe("12", "tdm xml observation with two RANGE", two, refused(),
                    suffix=".xml")
    for what, text in (("day 366 of a common year", _tle_3le(day="19366")),
                       ("NUL in a name", _tle_3le(name="PROBE\x00NAME")),
                       ("escape codes in a name", _tle_3le(name="PROBE\x1b[31mRED")),
                       ("catalogue number 00000", _tle_3le(number="00000"))):
        yield catalog_probe("12", f"tle {what}", text, refused_or_counted())
    xinclude = SAMPLE_OMM_XML.read_text().replace(
        "<OBJECT_NAME>", '<OBJECT_NAME><xi:include xmlns:xi="http://www.w3.org/2001/XInclude" '
        'href="/etc/hostname"/>', 1)
    yield catalog_probe("12", "omm xml XInclude in OBJECT_NAME", xinclude,
                        refused_or_counted(), suffix=".xml")
    for cmd in (["report", str(SAMPLE_BAG), "--out", "{D}/rep"],
                ["replay", str(SAMPLE_BAG), "--offline", "--out", "{D}/rep"]):
        yield cli_probe("12", f"{cmd[0]} --params-file q: true",
                        [*cmd, "--params-file", "{D}/p.yaml"], refused(),
                        {"p.yaml": "filter:\n  ros__parameters:\n    q: true\n"},
                        timeout=120.0)


def _damaged_bag(damage: Callable[[bytearray], bytes]) -> Callable[[Path], None]:
    """Write the sample bag, with `damage` done to its .mcap, at the given path."""

    def make(path: Path) -> None:
        shutil.copytree(SAMPLE_BAG, path)
        mcap = next(path.glob("*.mcap"))
        mcap.write_bytes(damage(bytearray(mcap.read_bytes())))

    return make


def _flip_middle(data: bytearray) -> bytes:
    data[len(data) // 2] ^= 0x01
    return bytes(data)


def _garbage(data: bytearray, insert: bool) -> bytes:
    at = len(data) // 3
    junk = bytes((i * 7919) % 251 for i in range(4096))
    return bytes(data[:at] + junk + data[at + (0 if insert else 4096):])


def damaged_bag_probes() -> Iterator[Probe]:
    """Class 13: `bag repair` of the sample bag damaged in its middle keeps what is intact."""
    for what, damage in (("one flipped byte in the middle", _flip_middle),
                         ("4 kB of garbage inserted at one third",
                          lambda d: _garbage(d, True)),
                         ("4 kB written over at one third", lambda d: _garbage(d, False))):
        yield cli_probe("13", f"bag repair: {what}",
                        ["bag", "repair", "{D}/bag", "--out", "{D}/fixed"],
                        accepted(r"recovered \d+ messages"), {"bag": _damaged_bag(damage)})


def cli_option_probes(large: bool = False) -> Iterator[Probe]:
    """Class 10: catalog options without a catalog, a 100 MB one-line catalog (`large`: a
    catalog of 170,000 objects, 26 MB, wrong in its last line; its numbers stay below
    180000, whose Alpha-5 letter `sgp4.exporter` writes as I, which Alpha-5 skips)."""
    for opt in (["--objects", "5"], ["--shards", "2"], ["--synthetic", "10"], ["--open-loop"],
                ["--no-surrogate"], ["--surrogate-param", "min_span=1"],
                ["--remote-shards", "1"]):
        yield cli_probe("10", f"live {' '.join(opt)} without --catalog",
                        ["live", *opt, "--out", "{D}/out"], refused(), timeout=30.0)
    for opt in (["--duration", "-1"], ["--duration", "nan"], ["--shards", "0"],
                ["--shards", "100000"], ["--objects", "-3"], ["--synthetic", "-1"],
                ["--time-scale", "0"], ["--time-scale", "nan"], ["--start", "2100-01-01T00:00:00Z"],
                ["--start", "1957-10-04T00:00:00Z"], ["--start", "garbage"]):
        short = [] if opt[0] == "--duration" else ["--duration", "0.02"]
        yield cli_probe("10", f"live --catalog {' '.join(opt)}",
                        ["live", "--catalog", str(SAMPLE_TLE), *opt, *short, "--out",
                         "{D}/out"], refused(), timeout=60.0)

    yield cli_probe("2", "live --catalog ending after 2038-01-19T03:14:07",
                    ["live", "--catalog", str(SAMPLE_TLE), "--start", "2038-01-19T00:00:00Z",
                     "--duration", "6", "--out", "{D}/out"], refused(r"end"), timeout=60.0)
    for start in ("2039-01-01T00:00:00Z", "1969-12-31T00:00:00Z", "2038-01-19T03:00:00Z"):
        yield cli_probe("2", f"live --start {start[:10]} (iss_radar_columbus)",
                        ["live", "--scenario", "iss_radar_columbus", "--start", start,
                         "--duration", "2", "--out", "{D}/out"],
                        refused(), timeout=60.0)

    def one_line(path: Path) -> None:
        with path.open("wb") as f:
            for _ in range(100):
                f.write(b"1 28057U 03049A   06177.78615833" * 32768)

    yield catalog_probe("10", "catalog of one 100 MB line", one_line, refused(), timeout=120.0)
    if large:
        def big(path: Path) -> None:
            from sgp4.exporter import export_tle

            sys.path.insert(0, str(ROOT))
            from ssa_fusion.formats import element_sets as catalog_io
            from ssa_fusion.sim import survey

            base = catalog_io.read_catalog(SAMPLE_TLE)[0]
            with path.open("w") as f:
                for e in survey.synthetic_catalog(base, 170_000, seed=1, first_id=1):
                    line1, line2 = export_tle(e.satrec)
                    f.write(f"{e.name}\n{line1}\n{line2}\n")
                f.write("LAST\n1 99999U garbage\n2 99999 garbage\n")

        yield cli_probe("10", "catalog of 170,000 objects (26 MB), its last object wrong",
                        ["live", "--catalog", "{D}/big.tle", "--duration", "0.01", "--out",
                         "{D}/out"], refused(r"big\.tle:510002: TLE line 1"), {"big.tle": big},
                        timeout=300.0)


# ------------------------------------------------------------------- graph probes


def domain_pids(domain: int) -> list[int]:
    """Process ids whose environment has ROS_DOMAIN_ID=domain (this probe's run only)."""
    pids = []
    for d in Path("/proc").iterdir():
        if not d.name.isdigit() or int(d.name) == os.getpid():
            continue
        with contextlib.suppress(OSError):
            if f"ROS_DOMAIN_ID={domain}".encode() in (d / "environ").read_bytes().split(b"\0"):
                pids.append(int(d.name))
    return pids


def node_pid(domain: int, name: str) -> int | None:
    """Return the pid of the node `name` in `domain`, if running: renamed ``__node:=name``
    (a catalog run's) or the executable of that name (the single-object graph's)."""
    for pid in domain_pids(domain):
        with contextlib.suppress(OSError):
            argv = Path(f"/proc/{pid}/cmdline").read_bytes().split(b"\0")
            if f"__node:={name}".encode() in argv or (
                    not any(a.startswith(b"__node:=") for a in argv)
                    and any(a.endswith(f"/lib/ssa_fusion/{name}".encode()) for a in argv)):
                return pid
    return None


_DOMAINS = iter(range(150, 232))


def live_catalog_probe(cls: str, name: str, extra: Sequence[str],
                       during: Callable[[Result, int, Path], Callable[
                           [subprocess.Popen[bytes], float], None]] | None,
                       judge_: Judge, timeout: float = 400.0, catalog: bool = True,
                       burners: int = 0) -> Probe:
    """A `live --catalog` run (`catalog` False: the single-object `live`) in its own ROS
    domain; `during` acts on it while it runs, beside `burners` CPU-bound processes. Any
    node of the run left behind is ended (by pid) and noted."""

    def run(d: Path) -> tuple[Result, str]:
        domain = next(_DOMAINS)
        out = d / "out"
        what = ["--catalog", str(SAMPLE_TLE)] if catalog else []
        argv = [*CLI, "live", *what, *extra, "--out", str(out), "--domain-id", str(domain)]
        notes: list[str] = []
        box = Result(None, "", "", 0.0, notes=notes)
        with cpu_burners(burners):
            r = run_cmd(argv, d / "run", timeout,
                        during=during(box, domain, out) if during else None,
                        env={"ROS_DOMAIN_ID": str(domain)})
        r.notes = notes
        left = domain_pids(domain)
        if left:
            r.notes.append(f"{len(left)} process(es) of the run left behind")
            for pid in left:
                with contextlib.suppress(ProcessLookupError):
                    os.kill(pid, signal.SIGKILL)
        r.logs = node_logs(out)
        summary = out / "catalog.json"
        if summary.exists():
            r.out += "\nCATALOG_JSON " + summary.read_text().replace("\n", " ")
        return r, shell(argv)

    return Probe(cls, name, run, judge_, graph=True)


def wait_for_node(domain: int, name: str, out: Path, limit: float = 120.0) -> int | None:
    """Wait until node `name` runs and the recorder has written something; its pid."""
    deadline = time.monotonic() + limit
    while time.monotonic() < deadline:
        pid = node_pid(domain, name)
        if pid and any(f.stat().st_size > 20_000 for f in (out / "bag").glob("*.mcap")):
            return pid
        time.sleep(0.2)
    return None


LIVE = "ssa-fusion"
"""`stall`'s name for the `ssa-fusion live` process itself."""


def stall(node: str, seconds: float = 10.0) -> Callable[[Result, int, Path], Callable[
        [subprocess.Popen[bytes], float], None]]:
    """Stop `node` with SIGSTOP once the run records, for `seconds`, then SIGCONT."""

    def make(box: Result, domain: int, out: Path) -> Callable[
            [subprocess.Popen[bytes], float], None]:
        def act(p: subprocess.Popen[bytes], start: float) -> None:
            pid = wait_for_node(domain, "sensor_sim" if node == LIVE else node, out)
            if pid is not None and node == LIVE:
                pid = p.pid
            if pid is None:
                box.notes.append(f"{node} never ran: not stalled")
                return
            os.kill(pid, signal.SIGSTOP)
            time.sleep(seconds)
            os.kill(pid, signal.SIGCONT)

        return act

    return make


def sigterm_after(delay: float, sig: signal.Signals = signal.SIGTERM) -> Callable[
        [Result, int, Path], Callable[[subprocess.Popen[bytes], float], None]]:
    """Send `sig` to `live` `delay` s after its sensor_sim started (0: at once)."""

    def make(box: Result, domain: int, out: Path) -> Callable[
            [subprocess.Popen[bytes], float], None]:
        def act(p: subprocess.Popen[bytes], start: float) -> None:
            if delay > 0:
                deadline = time.monotonic() + 120.0
                while node_pid(domain, "sensor_sim") is None and time.monotonic() < deadline:
                    time.sleep(0.1)
                time.sleep(delay)
            else:
                time.sleep(1.0)
            if p.poll() is None:
                p.send_signal(sig)
            else:
                box.notes.append("the run ended before the signal")

        return act

    return make


def accounted(lockstep: bool) -> Judge:
    """Judge a catalog run's accounting: `lost: N` printed equals published − received,
    no row refused at the door, no rejection cause beyond a filter's own, and (lockstep)
    nothing lost."""
    own = {"iod_pending", "reinitialised", "rejected_gate", "rejected_nis"}

    def judge_(r: Result) -> tuple[str, str]:
        m = re.search(r"CATALOG_JSON (.*)$", r.out, re.S)
        if m is None:
            return "unclean", f"no summary (exit {r.rc}): {first_error(r)}"
        s = json.loads(m.group(1))
        lost = s["published"] - s["received_by_shards"]
        said = re.search(r"lost: (\d+)", r.out)
        if said is None or int(said.group(1)) != lost or s["lost_measurements"] != lost:
            return "silent", (f"published {s['published']} − received "
                              f"{s['received_by_shards']} = {lost}, says "
                              f"{said.group(0) if said else 'nothing'}")
        if s["recorded_measurements"] != s["published"]:
            return "silent", (f"recorded {s['recorded_measurements']} of "
                              f"{s['published']} published")
        other = {k: v for k, v in s["rejected_and_pending"].items() if k not in own and v}
        if s["refused_at_door"] or other:
            return "silent", f"valid rows refused: door {s['refused_at_door']}, {other}"
        if lockstep and lost:
            return "silent", f"lockstep lost {lost}"
        if r.rc != (1 if lost else 0):
            return "unclean", f"exit {r.rc} with {lost} lost"
        return "clean", ""

    return judge_


def graph_probes() -> Iterator[Probe]:
    """Classes 1, 3, 4 and 9: catalog runs stalled, unable to record, stopped by SIGTERM."""
    run = ["--synthetic", "200", "--duration", "6", "--shards", "2"]
    for mode, extra in (("lockstep", []), ("open loop", ["--open-loop"])):
        for node in ("sensor_sim", "catalog_filter_1"):
            yield live_catalog_probe("1", f"{mode}: {node} stalled 10 s", [*run, *extra],
                                     stall(node), accounted(mode == "lockstep"))
    for node in ("recorder", "catalog_surrogate_0", LIVE):
        for mode, extra in (("lockstep", []), ("open loop", ["--open-loop"])):
            yield live_catalog_probe("1", f"{mode}: {node} stalled 10 s", [*run, *extra],
                                     stall(node), accounted(mode == "lockstep"))
    yield live_catalog_probe("1", "lockstep: sensor_sim stalled 30 s", run,
                             stall("sensor_sim", 30.0), accounted(True))
    for mode, extra in (("lockstep", []), ("open loop", ["--open-loop"])):
        yield live_catalog_probe("4", f"{mode} beside 3 CPU burners", [*run, *extra], None,
                                 accounted(mode == "lockstep"), burners=3)
    for delay in (0.0, 2.0, 6.0, 12.0):
        yield live_catalog_probe("9", f"SIGTERM {delay:g} s into live --catalog", run,
                                 sigterm_after(delay), _stopped_by_sigterm, timeout=180.0)
    for sig in (signal.SIGINT, signal.SIGHUP):
        for delay in (2.0, 6.0):
            yield live_catalog_probe("9", f"{sig.name} {delay:g} s into live --catalog", run,
                                     sigterm_after(delay, sig), stopped_by(sig),
                                     timeout=180.0)
    for sig in (signal.SIGTERM, signal.SIGINT):
        yield live_catalog_probe("9", f"{sig.name} 4 s into live (one object)", [],
                                 sigterm_after(4.0, sig), stopped_by(sig), timeout=180.0,
                                 catalog=False)

    def bag_probe(what: str, bag: str, setup: Callable[[Path], None], catalog: bool) -> Probe:
        def run_(d: Path) -> tuple[Result, str]:
            d.mkdir(parents=True, exist_ok=True)
            setup(d)
            short = ["--duration", "0.5"] if catalog else []  # the bag fails before it runs
            return live_catalog_probe("3", "", ["--bag", bag.replace("{D}", str(d)), *short],
                                      None, _cannot_record, timeout=120.0,
                                      catalog=catalog).run(d)

        return Probe("3", f"live{' --catalog' if catalog else ''}, bag {what}", run_,
                     _cannot_record, graph=True)

    for catalog in (True, False):
        yield bag_probe("under /dev/null", "/dev/null/bag", lambda d: None, catalog)
        yield bag_probe("in a symlink loop", "{D}/loop_a/bag", _symlink_loop, catalog)
        yield bag_probe("is a symlink loop", "{D}/loop_a", _symlink_loop, catalog)
        yield bag_probe("exists as a file", "{D}/file", _a_file, catalog)
        yield bag_probe("in a read-only directory", "{D}/ro/bag", _read_only_dir, catalog)


FLOOD_TESTS = {
    "100,000 object ids and a 1 MB id to a catalog_filter shard":
        "test/graph/test_flood_graph.py",
    "negative and 1e300 covariances, an object beyond max_objects to catalog_surrogate":
        "test/graph/test_catalog_surrogate_graph.py",
}
"""Class 7's probes: the graph tests that send each flood (their assertions are the judge)."""


def flood_probes() -> Iterator[Probe]:
    """Class 7: floods of object ids, an object id of 1 MB, absurd covariances."""
    for name, test in FLOOD_TESTS.items():
        argv = [sys.executable, "-m", "pytest", "-q", "-s", "-p", "no:cacheprovider",
                "--tb=line", "--rootdir", str(ROOT), str(ROOT / test)]

        def run(d: Path, argv: list[str] = argv) -> tuple[Result, str]:
            return run_cmd(argv, d / "run", 300.0), shell(argv)

        yield Probe("7", name, run, _flood_held, graph=True)


def _flood_held(r: Result) -> tuple[str, str]:
    """The flood's graph test passed: capped, counted, memory bounded, the node alive."""
    if r.rc != 0:
        return "silent", f"pytest exit {r.rc}"
    return "clean", ""


def _a_file(d: Path) -> None:
    """Make `d`/file, a file."""
    (d / "file").write_text("x")


def _symlink_loop(d: Path) -> None:
    """Make loop_a -> loop_b -> loop_a in `d`."""
    (d / "loop_a").symlink_to(d / "loop_b")
    (d / "loop_b").symlink_to(d / "loop_a")


def _read_only_dir(d: Path) -> None:
    """Make `d`/ro a read-only directory (a read-only tmpfs: root ignores file modes)."""
    (d / "ro").mkdir()
    done = subprocess.run(["mount", "-t", "tmpfs", "-o", "ro,size=64k", "tmpfs", str(d / "ro")],
                          capture_output=True, text=True, check=False)
    if done.returncode:
        (d / "ro").chmod(0o555)


def _cannot_record(r: Result) -> tuple[str, str]:
    """A run whose bag cannot be made: exit 1 or 2 within a minute, saying why."""
    if r.rc == 0:
        return "silent", "ran without its bag"
    if r.seconds > 60.0:
        return "unclean", f"took {r.seconds:.0f} s"
    if not re.search(r"cannot create|cannot write|exists|not a directory|symbolic|read-only",
                     r.err, re.IGNORECASE):
        return "unclean", "does not say why"
    return "clean", ""


def stopped_by(sig: signal.Signals) -> Judge:
    """A run stopped by `sig`: 128 + its number, says so, nothing left behind (checked by
    the run)."""

    def judge_(r: Result) -> tuple[str, str]:
        if r.rc != 128 + sig:
            return "unclean", f"exit {r.rc}, expected {128 + sig}"
        if f"stopped by {sig.name}" not in r.err:
            return "unclean", f"does not say 'stopped by {sig.name}'"
        return "clean", ""

    return judge_


_stopped_by_sigterm = stopped_by(signal.SIGTERM)


def disk_probes(can_mount: bool) -> Iterator[Probe]:
    """Class 5: a full disk under a catalog run's recorder, then `bag repair`."""
    if not can_mount:
        yield Probe("5", "disk full (no tmpfs can be mounted here)", lambda d: (
            Result(0, "", "", 0.0), "mount -t tmpfs"), lambda r: ("skipped", ""), graph=True)
        return

    def mount_small(d: Path) -> Path:
        disk = d / "disk"
        disk.mkdir(parents=True, exist_ok=True)
        subprocess.run(["mount", "-t", "tmpfs", "-o", "size=256k", "tmpfs", str(disk)],
                       check=True)
        return disk

    def full(d: Path) -> tuple[Result, str]:
        disk = mount_small(d)
        try:
            p = live_catalog_probe("5", "", ["--synthetic", "200", "--duration", "6",
                                             "--bag", str(disk / "bag")], None, _full_disk)
            r, cmd = p.run(d)
            if (disk / "bag").exists():
                whole = run_cmd([sys.executable, "-c", READ_WHOLE_BAG, str(disk / "bag")],
                                d / "read", 120.0)
                if whole.rc != 0:
                    r.notes.append(f"the bag is not whole: {first_error(whole)}")
                fill(disk)
                onto = run_cmd([*CLI, "bag", "repair", str(disk / "bag"), "--out",
                                str(disk / "rep")], d / "repair_full", 120.0)
                if onto.rc != 2 or "No space left" not in onto.err or len(error_lines(onto)) != 1:
                    r.notes.append(f"bag repair onto the full disk: exit {onto.rc}: "
                                   f"{first_error(onto)}")
                ok = run_cmd([*CLI, "bag", "repair", str(disk / "bag"), "--out",
                              str(d / "rep")], d / "repair", 120.0)
                if ok.rc != 0:
                    r.notes.append(f"bag repair elsewhere: exit {ok.rc}: {first_error(ok)}")
                r.err += onto.err + ok.err
            else:
                r.notes.append("no bag to repair")
            return r, cmd + f"  (bag on a 256k tmpfs); ssa-fusion bag repair {disk}/bag --out X"
        finally:
            subprocess.run(["umount", "-l", str(disk)], check=False)

    yield Probe("5", "live --catalog onto a full disk, then bag repair", full, _full_disk,
                graph=True)

    def single(d: Path) -> tuple[Result, str]:
        disk = mount_small(d)
        try:
            fill(disk, keep=96 * 1024)  # room for the bag's start, not for the run
            p = live_catalog_probe("5", "", ["--bag", str(disk / "bag")], None, _full_disk,
                                   catalog=False)
            return p.run(d)
        finally:
            subprocess.run(["umount", "-l", str(disk)], check=False)

    yield Probe("5", "live (one object) onto a nearly full disk", single, _full_disk,
                graph=True)

    def onto_full(name: str, args: list[str]) -> Probe:
        def run(d: Path) -> tuple[Result, str]:
            disk = mount_small(d)
            try:
                (d / "good.tdm").write_text(tdm_kvn(GOOD_ROWS))
                fill(disk)
                argv = [*CLI, *(a.replace("{D}", str(d)).replace("{DISK}", str(disk))
                                for a in args)]
                r = run_cmd(argv, d / "run", 120.0)
                left = [q.name for q in disk.iterdir() if q.name != "filler"]
                if left:
                    r.notes.append(f"left on the full disk: {left}")
                return r, shell(argv) + "  (onto a full 256k tmpfs)"
            finally:
                subprocess.run(["umount", "-l", str(disk)], check=False)

        return Probe("5", name, run, refused(r"No space left on device", rcs=(1, 2)))

    yield onto_full("import tdm onto a full disk",
                    ["import", "tdm", "{D}/good.tdm", "--bag", "{DISK}/bag"])
    yield onto_full("replay --offline onto a full disk",
                    ["replay", str(SAMPLE_BAG), "--offline", "--out", "{DISK}/rep"])
    yield onto_full("export oem onto a full disk",
                    ["export", "oem", str(SAMPLE_BAG), "--out", "{DISK}/x.oem"])
    yield onto_full("export tdm onto a full disk",
                    ["export", "tdm", str(SAMPLE_BAG), "--out", "{DISK}/x.tdm"])


READ_WHOLE_BAG = """
import sys
from rosbags.rosbag2 import Reader
with Reader(sys.argv[1]) as r:
    n = sum(1 for _ in r.messages())
assert n > 0, 'an empty bag'
print(n, 'messages')
"""
"""A bag is whole when `rosbags`' Reader opens it as it is (metadata.yaml, MCAP summary)."""


def fill(disk: Path, keep: int = 0) -> None:
    """Take what room is left on `disk` but `keep` bytes (another writer filling it)."""
    with contextlib.suppress(OSError), (disk / "filler").open("wb", buffering=0) as f:
        while True:
            fs = os.statvfs(disk)
            if fs.f_bavail * fs.f_frsize <= keep:
                return
            f.write(b"x" * 4096)


def _full_disk(r: Result) -> tuple[str, str]:
    """A run whose disk filled: exit 1, one line naming the bag and the reason (the probe's
    notes say whether the bag was whole and what `bag repair` did)."""
    if r.rc == 0:
        return "silent", "exit 0 on a full disk"
    if "No space left on device" not in r.err:
        return "unclean", "does not say the disk is full"
    return "clean", ""


def listen_probe() -> Iterator[Probe]:
    """Class 11: sockets a `live` run's nodes bind beyond loopback.

    Judged: a socket on any address but loopback outside the kernel's ephemeral port range
    (the RTPS ports a participant announces and reads: discovery, user data). Each Fast DDS
    participant also has a sending socket on ``0.0.0.0`` at an ephemeral port (its "any
    address" sender, with the allowed interface as the outbound one); Fast DDS reads nothing
    from it and announces no locator on it (docs/MULTIHOST.md), so it is not counted.
    """

    def make(box: Result, domain: int, out: Path) -> Callable[
            [subprocess.Popen[bytes], float], None]:
        def act(p: subprocess.Popen[bytes], start: float) -> None:
            if wait_for_node(domain, "sensor_sim", out) is None:
                box.notes.append("never ran")
                return
            for pid in domain_pids(domain):
                for kind in ("tcp", "udp", "tcp6", "udp6"):
                    with contextlib.suppress(OSError):
                        wild = [w for w in _wild_sockets(pid, kind)
                                if not _ephemeral(int(w.rsplit(":", 1)[1], 16))]
                        if wild:
                            box.notes.append(f"pid {pid} binds {kind} {wild[0]}")
            p.send_signal(signal.SIGTERM)

        return act

    yield live_catalog_probe("11", "live --catalog binds loopback only", [], make,
                             _loopback_only, timeout=180.0)


CACHE_CHECK = """
import os, sys
from pathlib import Path
from ssa_fusion.core.base import jit
from ssa_fusion.core.motion import kepler
d = jit.cache_directory(kepler._solve_chi.py_func)
root = Path(sys.argv[1])
if os.environ.get('NUMBA_CACHE_DIR'):
    assert d is None, f'a cache directory others may write is used: {d}'
else:
    assert d is not None and root not in d.parents, f'cache in the source tree: {d}'
    mode = d.stat().st_mode & 0o777
    assert d.stat().st_uid == os.getuid() and mode == 0o700, oct(mode)
held = [str(q) for q in (root / 'ssa_fusion').rglob('*.nbi')]
assert not held, f'numba index files in the source tree: {held[:2]}'
print('ok', d)
"""
"""Where the compiled kernels' cache is (class 11): not in the source tree, the user's own,
never a directory others may write (a pickle is unpickled from it)."""


def cache_probes() -> Iterator[Probe]:
    """Class 11: the numba cache outside the source tree, owned by the user, 0700."""

    def probe(name: str, planted: Callable[[Path], None] | None) -> Probe:
        def run(d: Path) -> tuple[Result, str]:
            env = {}
            if planted is not None:
                (d / "shared" / "ssa_fusion").mkdir(parents=True, exist_ok=True)
                planted(d / "shared" / "ssa_fusion")
                env = {"NUMBA_CACHE_DIR": str(d / "shared")}
            argv = [sys.executable, "-c", CACHE_CHECK, str(ROOT)]
            return run_cmd(argv, d / "run", 120.0, env=env), shell(argv)

        return Probe("11", name, run, accepted(r"^ok"))

    yield probe("the compiled cache: the user's own, 0700, outside the source tree", None)
    yield probe("the compiled cache: NUMBA_CACHE_DIR's ssa_fusion writable by all: unused",
                lambda d: d.chmod(0o777))
    if os.geteuid() == 0:  # only root can give a directory to another user
        yield probe("the compiled cache: NUMBA_CACHE_DIR's ssa_fusion another user's: unused",
                    lambda d: os.chown(d, 65534, 65534))


def _ephemeral(port: int) -> bool:
    """Whether `port` is in the kernel's ephemeral range (ip_local_port_range)."""
    lo, hi = map(int, Path("/proc/sys/net/ipv4/ip_local_port_range").read_text().split())
    return lo <= port <= hi


def _wild_sockets(pid: int, kind: str) -> list[str]:
    """Return a process's sockets of `kind` bound to an address other than loopback."""
    inodes = set()
    for fd in Path(f"/proc/{pid}/fd").iterdir():
        with contextlib.suppress(OSError):
            target = os.readlink(fd)
            if target.startswith("socket:["):
                inodes.add(target[8:-1])
    wild = []
    for line in Path(f"/proc/{pid}/net/{kind}").read_text().splitlines()[1:]:
        cols = line.split()
        local, inode = cols[1], cols[9]
        addr = local.split(":")[0]
        loop = addr.endswith("7F") if len(addr) == 8 else addr.endswith("01000000")
        if inode in inodes and not loop:
            wild.append(local)
    return wild


def _loopback_only(r: Result) -> tuple[str, str]:
    """The run bound nothing beyond loopback (its notes say what it did bind)."""
    if r.notes:
        return "unclean", "; ".join(r.notes[:2])
    return "clean", ""


# --------------------------------------------------------------------------- main


def in_own_mount_namespace() -> bool:
    """Re-run this script in a mount namespace of its own when root can make one."""
    if os.environ.get(MOUNT_NS_ENV):
        return True
    if os.geteuid() != 0 or shutil.which("unshare") is None:
        return False
    test = subprocess.run(["unshare", "-m", "--propagation", "private", "true"],
                          capture_output=True, check=False)
    if test.returncode:
        return False
    os.environ[MOUNT_NS_ENV] = "1"
    os.execvp("unshare", ["unshare", "-m", "--propagation", "private", sys.executable,
                          *sys.argv])


def can_mount_tmpfs(where: Path) -> bool:
    """Whether a tmpfs can be mounted (and unmounted) here."""
    d = where / "mount_test"
    d.mkdir(parents=True, exist_ok=True)
    if subprocess.run(["mount", "-t", "tmpfs", "-o", "size=64k", "tmpfs", str(d)],
                      capture_output=True, check=False).returncode:
        return False
    subprocess.run(["umount", str(d)], check=False)
    return True


def all_probes(args: argparse.Namespace, can_mount: bool) -> list[Probe]:
    """Return the probes the options select."""
    probes = [*tdm_probes(args.large), *catalog_probes(), *param_probes(),
              *cli_option_probes(args.large), *cache_probes(), *silent_accept_probes(),
              *damaged_bag_probes()]
    if not args.no_graph:
        from probe_sharing import sharing_probes

        probes += [*graph_probes(), *flood_probes(), *disk_probes(can_mount),
                   *sharing_probes()]
        if args.listen:
            probes += list(listen_probe())
    if args.only:
        keep = set(args.only.split(","))
        probes = [p for p in probes if p.cls in keep]
    if args.match:
        probes = [p for p in probes if re.search(args.match, p.name)]
    return probes


def main(argv: Sequence[str] | None = None) -> int:
    """Run the probes; print the table and, last, the counts per outcome as JSON."""
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--large", action="store_true", help="also the 100 MB TDM import")
    ap.add_argument("--listen", action="store_true", help="also the sockets of a live run")
    ap.add_argument("--no-graph", action="store_true", help="no probe that starts a graph")
    ap.add_argument("--only", default="", help="classes to run, e.g. 2,6")
    ap.add_argument("--match", default="", help="only probes whose name matches this regex")
    ap.add_argument("--keep", action="store_true", help="keep the scratch directory")
    args = ap.parse_args(argv)
    mount_ns = in_own_mount_namespace()
    scratch = Path(tempfile.mkdtemp(prefix="probe_hostile_"))
    can_mount = mount_ns and can_mount_tmpfs(scratch)
    probes = all_probes(args, can_mount)
    print(f"probe_hostile: {len(probes)} probes; scratch {scratch}; "
          f"{'own mount namespace' if mount_ns else 'no mount namespace of its own'}"
          f"{'' if can_mount else ' (disk-full probes skipped: no tmpfs can be mounted)'}",
          flush=True)
    verdicts: list[Verdict] = []
    print(f"{'class':>5} | {'outcome':9} | {'rc':>4} | {'s':>6} | probe | first error line",
          flush=True)
    try:
        for k, p in enumerate(probes):
            d = scratch / f"{k:03d}"
            r, command = p.run(d)
            outcome, why = judge(p, r)
            line = (why + ": " if why and outcome != "clean" else "") + first_error(r)[:160]
            v = Verdict(p.cls, p.name, outcome, r.rc, r.seconds, line, command)
            verdicts.append(v)
            print(f"{v.cls:>5} | {v.outcome:9} | {v.rc!s:>4} | {v.seconds:6.1f} | {v.name} | "
                  f"{v.line}", flush=True)
            if not args.keep:
                shutil.rmtree(d, ignore_errors=True)
    finally:
        if not args.keep:
            shutil.rmtree(scratch, ignore_errors=True)
    bad = [v for v in verdicts if v.outcome not in ("clean", "skipped")]
    if bad:
        print("\nnot clean, and the command that shows each (from the repository root):")
        for v in bad:
            print(f"  [{v.cls}] {v.name}: {v.outcome}: {v.line}\n      {v.command}")
    counts = Counter(v.outcome for v in verdicts)
    assert verdicts, "no probe ran"
    print(json.dumps({"probes": len(verdicts), **{o: counts.get(o, 0) for o in OUTCOMES}}))
    return 0


if __name__ == "__main__":
    sys.exit(main())

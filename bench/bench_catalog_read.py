"""Benchmark of reading large catalogs (`formats.element_sets.read_catalog`): time and memory.

Four generated files: a TLE of `--objects` objects (two lines each, 100,000: 14 MB), an OMM
CSV and an OMM XML of as many, and a 3LE of 340,000 objects (every NORAD number, Alpha-5
included) with long names and a comment line each: 100 MB. Each is read in a subprocess of
its own by the streaming reader of this tree (`new`, with a progress callback) and, when
`--baseline REV` is in the repository, by the reader of that revision (`old`: the whole text
read at once), alternately, `--repeat` times. A child reports its wall time, its resident
memory before the read (interpreter and imports), after it (holding the entries) and its
peak; "transient" is peak minus after: what the read held besides its entries.

The benchmark asserts that every read gave the expected number of objects, and that both
readers gave the same entries (ids and element sets, compared in the child by a digest).

Usage: .venv/bin/python bench/bench_catalog_read.py [--objects 100000] [--mb 100]
       [--repeat 1] [--baseline 659c0be] [--keep DIR]
(prints parseable lines; the last one is JSON)
"""

from __future__ import annotations

import argparse
import hashlib
import importlib.util
import itertools
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

L1 = "1 25544U 98067A   20001.82137887  .00016717  00000-0  10270-3 0  9127"
L2 = "2 25544  51.6392  96.6358 0005156  88.7140 271.4601 15.49497216  6061"
CSV_HEADER = ("OBJECT_NAME,OBJECT_ID,EPOCH,MEAN_MOTION,ECCENTRICITY,INCLINATION,RA_OF_ASC_NODE,"
              "ARG_OF_PERICENTER,MEAN_ANOMALY,EPHEMERIS_TYPE,CLASSIFICATION_TYPE,NORAD_CAT_ID,"
              "ELEMENT_SET_NO,REV_AT_EPOCH,BSTAR,MEAN_MOTION_DOT,MEAN_MOTION_DDOT")
MAX_OBJECTS = 340_000
"""NORAD numbers a TLE can carry (0 .. 339999, Alpha-5 above 99999)."""
ALPHA5 = "ABCDEFGHJKLMNPQRSTUVWXYZ"
BASELINE = "659c0be"
"""The last revision whose catalog reader read the whole text at once."""


def satnum(i: int) -> str:
    """The five columns of NORAD number `i` (Alpha-5 from 100000)."""
    return f"{i:05d}" if i < 100_000 else ALPHA5[i // 10_000 - 10] + f"{i % 10_000:04d}"


def checksum(line: str) -> str:
    """`line` (68 columns) with its checksum column."""
    s = sum(int(c) if c.isdigit() else c == "-" for c in line[:68])
    return line[:68] + str(s % 10)


def tle_lines(i: int) -> tuple[str, str]:
    """TLE lines of object `i`: the ISS's element set, its node and anomaly turned."""
    raan, anomaly = (96.6358 + 0.37 * i) % 360.0, (271.4601 + 7.1 * i) % 360.0
    line2 = f"{L2[:2]}{satnum(i)}{L2[7:17]}{raan:8.4f}{L2[25:43]}{anomaly:8.4f}{L2[51:]}"
    return checksum(f"{L1[:2]}{satnum(i)}{L1[7:]}"), checksum(line2)


def write_tle(path: Path, objects: int, names: int = 0, comment: bool = False) -> None:
    """Write `objects` element sets: TLE (`names` 0) or 3LE with names of `names` characters,
    each after a comment line if `comment`."""
    with path.open("w") as f:
        for i in range(objects):
            if comment:
                f.write(f"# element set {i} of {objects}, generated\n")
            if names:
                f.write(f"OBJECT {i} ".ljust(names, "X") + "\n")
            a, b = tle_lines(i)
            f.write(f"{a}\n{b}\n")


def write_csv(path: Path, objects: int) -> None:
    """Write `objects` OMMs as CSV (CelesTrak's columns)."""
    with path.open("w") as f:
        f.write(CSV_HEADER + "\n")
        for i in range(objects):
            f.write(f"OBJECT {i},1998-067A,2019-12-31T19:42:47.134368,15.49497216,.0005156,"
                    f"51.6392,{(96.6358 + 0.37 * i) % 360.0:.4f},88.7140,"
                    f"{(271.4601 + 7.1 * i) % 360.0:.4f},0,U,{i},912,606,.1027e-3,.00016717,0\n")


def write_xml(path: Path, objects: int) -> None:
    """Write `objects` OMMs as one NDM/XML document (segments as sgp4's exporter writes)."""
    with path.open("w") as f:
        f.write('<?xml version="1.0" encoding="UTF-8"?>\n<ndm>\n<omm id="CCSDS_OMM_VERS" '
                'version="2.0">\n<header><ORIGINATOR>bench</ORIGINATOR></header>\n<body>\n')
        for i in range(objects):
            f.write(f"""<segment>
  <metadata>
    <OBJECT_NAME>OBJECT {i}</OBJECT_NAME>
    <OBJECT_ID>1998-067A</OBJECT_ID>
    <CENTER_NAME>EARTH</CENTER_NAME>
    <REF_FRAME>TEME</REF_FRAME>
    <TIME_SYSTEM>UTC</TIME_SYSTEM>
    <MEAN_ELEMENT_THEORY>SGP4</MEAN_ELEMENT_THEORY>
  </metadata>
  <data>
    <meanElements>
      <EPOCH>2019-12-31T19:42:47.134368</EPOCH>
      <MEAN_MOTION>15.49497216</MEAN_MOTION>
      <ECCENTRICITY>.0005156</ECCENTRICITY>
      <INCLINATION>51.6392</INCLINATION>
      <RA_OF_ASC_NODE>{(96.6358 + 0.37 * i) % 360.0:.4f}</RA_OF_ASC_NODE>
      <ARG_OF_PERICENTER>88.7140</ARG_OF_PERICENTER>
      <MEAN_ANOMALY>{(271.4601 + 7.1 * i) % 360.0:.4f}</MEAN_ANOMALY>
    </meanElements>
    <tleParameters>
      <EPHEMERIS_TYPE>0</EPHEMERIS_TYPE>
      <CLASSIFICATION_TYPE>U</CLASSIFICATION_TYPE>
      <NORAD_CAT_ID>{i}</NORAD_CAT_ID>
      <ELEMENT_SET_NO>912</ELEMENT_SET_NO>
      <REV_AT_EPOCH>606</REV_AT_EPOCH>
      <BSTAR>.1027e-3</BSTAR>
      <MEAN_MOTION_DOT>.00016717</MEAN_MOTION_DOT>
      <MEAN_MOTION_DDOT>0</MEAN_MOTION_DDOT>
    </tleParameters>
  </data>
</segment>
""")
        f.write("</body>\n</omm>\n</ndm>\n")


def status_kib(key: str) -> int:
    """This process's `key` of /proc/self/status, KiB: VmRSS (resident memory now), VmHWM
    (its peak; unlike ru_maxrss, not the parent's before exec)."""
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith(f"{key}:"):
            return int(line.split()[1])
    return 0


def child(reader: str, path: Path, baseline: str) -> None:
    """Read `path` with `reader` (new or old); print one JSON line of numbers."""
    if reader == "new":
        from ssa_fusion.formats import element_sets as module
    else:  # the revision's module, imported under another name beside this tree's core
        source = subprocess.run(["git", "show", f"{baseline}:ssa_fusion/formats/element_sets.py"],
                                cwd=ROOT, check=True, capture_output=True, text=True).stdout
        name = "ssa_fusion.core._catalog_baseline"
        spec = importlib.util.spec_from_loader(name, loader=None)
        assert spec is not None
        module = importlib.util.module_from_spec(spec)
        sys.modules[name] = module
        exec(compile(source, f"{baseline}:ssa_fusion/formats/element_sets.py", "exec"),
             module.__dict__)
    calls: list[tuple[int, int, int]] = []
    before = status_kib("VmRSS")
    t0 = time.perf_counter()
    if reader == "new":
        entries = module.read_catalog(path, progress=lambda *c: calls.append(c))
    else:
        entries = module.read_catalog(path)
    wall = time.perf_counter() - t0
    after = status_kib("VmRSS")
    peak = status_kib("VmHWM")
    digest = hashlib.sha256()
    for e in entries:
        s = e.satrec
        digest.update(repr((e.object_id, e.name, e.source, s.jdsatepoch, s.jdsatepochF,
                            s.no_kozai, s.ecco, s.inclo, s.nodeo, s.argpo, s.mo, s.bstar,
                            s.ndot, s.nddot)).encode())
    monotone = all(a[0] <= b[0] for a, b in itertools.pairwise(calls))
    print(json.dumps({"objects": len(entries), "wall_s": round(wall, 2),
                      "rss_before_mib": round(before / 1024, 1),
                      "rss_after_mib": round(after / 1024, 1),
                      "peak_rss_mib": round(peak / 1024, 1),
                      "transient_mib": round((peak - after) / 1024, 1),
                      "digest": digest.hexdigest()[:16], "progress_calls": len(calls),
                      "progress_monotone": monotone,
                      "progress_last": list(calls[-1]) if calls else None}))


def run_child(reader: str, path: Path, baseline: str) -> dict[str, object]:
    """Run `child` in a subprocess; return its numbers."""
    out = subprocess.run([sys.executable, __file__, "--child", reader, "--baseline", baseline,
                          str(path)], cwd=ROOT, check=True, capture_output=True, text=True)
    return dict(json.loads(out.stdout.strip().splitlines()[-1]))


def has_revision(rev: str) -> bool:
    """Whether the repository has `rev`'s catalog reader."""
    return subprocess.run(["git", "cat-file", "-e", f"{rev}:ssa_fusion/formats/element_sets.py"],
                          cwd=ROOT, capture_output=True).returncode == 0


def main() -> int:
    """Generate the files, read each by both readers, check and print (last line JSON)."""
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--objects", type=int, default=100_000,
                   help="objects of the TLE, CSV and XML files")
    p.add_argument("--mb", type=float, default=100.0,
                   help="size of the big 3LE file, MB (0: none)")
    p.add_argument("--repeat", type=int, default=1, help="reads of each file by each reader")
    p.add_argument("--baseline", default=BASELINE,
                   help="revision whose whole-text reader to compare with ('' for none)")
    p.add_argument("--keep", type=Path, default=None, help="directory to keep the files in")
    p.add_argument("--child", choices=("new", "old"), help=argparse.SUPPRESS)
    p.add_argument("file", nargs="?", type=Path, help=argparse.SUPPRESS)
    args = p.parse_args()
    if args.child:
        child(args.child, args.file, args.baseline)
        return 0
    readers = ["old", "new"] if args.baseline and has_revision(args.baseline) else ["new"]
    if readers == ["new"]:
        print(f"baseline {args.baseline!r} not in the repository: the new reader only")
    results: dict[str, dict[str, object]] = {}
    with tempfile.TemporaryDirectory(prefix="bench_catalog_") as tmp:
        work = args.keep or Path(tmp)
        work.mkdir(parents=True, exist_ok=True)
        n = min(args.objects, MAX_OBJECTS)
        files = {f"tle_{n}": (work / f"tle_{n}.tle", n, lambda f: write_tle(f, n)),
                 f"csv_{n}": (work / f"omm_{n}.csv", n, lambda f: write_csv(f, n)),
                 f"xml_{n}": (work / f"omm_{n}.xml", n, lambda f: write_xml(f, n))}
        if args.mb:
            # 3LE lines of 120-character names and a comment: ~296 bytes an object
            big = min(MAX_OBJECTS, int(args.mb * 1e6 / 296))
            files[f"3le_{args.mb:g}mb"] = (work / f"big_{args.mb:g}mb.tle", big,
                                          lambda f: write_tle(f, big, names=120, comment=True))
        for label, (path, expected, write) in files.items():
            write(path)
            size = path.stat().st_size
            print(f"file {label}: {path.name} {size / 1e6:.1f} MB, {expected} objects")
            runs: dict[str, list[dict[str, object]]] = {r: [] for r in readers}
            for _ in range(args.repeat):
                for reader in readers:  # alternately: the machine's load is shared
                    r = run_child(reader, path, args.baseline)
                    assert r["objects"] == expected, (label, reader, r)
                    runs[reader].append(r)
                    print(f"  {reader}: {r['wall_s']} s, peak RSS {r['peak_rss_mib']} MiB "
                          f"(before {r['rss_before_mib']}, holding the entries "
                          f"{r['rss_after_mib']}, transient {r['transient_mib']})")
            new = runs["new"]
            assert all(r["progress_monotone"] for r in new), new
            assert all(r["progress_last"] == [size, size, expected] for r in new), new
            if "old" in runs:
                assert {r["digest"] for r in runs["old"]} == {r["digest"] for r in new}, runs
            results[label] = {"mb": round(size / 1e6, 1), "objects": expected,
                              **{reader: {k: min(float(str(r[k])) for r in rs) for k in
                                          ("wall_s", "peak_rss_mib", "rss_before_mib",
                                           "rss_after_mib", "transient_mib")}
                                 for reader, rs in runs.items()}}
            if args.keep is None:
                path.unlink()
    print(json.dumps(results))
    return 0


if __name__ == "__main__":
    sys.exit(main())

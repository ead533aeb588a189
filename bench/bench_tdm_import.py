"""Benchmark of `ssa-fusion import tdm` on a large file: time and peak memory.

The file is the sample bag's own TDM (`ssa-fusion export tdm`, 1,920 range/az/el epochs in
one segment of 17.5 h) with its DATA lines repeated, each copy a day later than the one
before, in one segment, until the file has `--mb` megabytes: a 100 MB KVN file holds ~0.43
million measurements (1.3 million observation lines). The import runs as a subprocess under
``/usr/bin/time -v`` (wall time, peak resident memory); the benchmark asserts that it exited
0 and imported every epoch of the file, and that the bag holds them. `--xml` writes the
same measurements as a TDM in XML.

Usage: .venv/bin/python bench/bench_tdm_import.py [--mb 100] [--xml] [--keep DIR]
(prints parseable lines; the last one is JSON)
"""

from __future__ import annotations

import argparse
import datetime as dt
import json
import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
SAMPLE = ROOT / "bags" / "sample_iss_j2_rae"
DAY0 = dt.date(2025, 1, 1)
"""The day of the sample's epochs (every epoch of its TDM is on it)."""


def sample_tdm(workdir: Path, fmt: str) -> Path:
    """Export the sample bag's measurements as a TDM (`fmt`: kvn or xml) into `workdir`."""
    out = workdir / f"sample.{fmt}"
    subprocess.run([sys.executable, "-m", "ssa_fusion.apps.cli", "export", "tdm", str(SAMPLE),
                    "--out", str(out), "--format", fmt], check=True, cwd=ROOT,
                   stdout=subprocess.DEVNULL)
    return out


def big_tdm(sample: Path, out: Path, mb: float, fmt: str) -> tuple[int, int]:
    """Write `out`: `sample`'s data repeated a day apart until it has `mb` MB.

    Returns (bytes written, epochs: measurements the import must give).
    """
    text = sample.read_text()
    day = DAY0.isoformat()
    if fmt == "kvn":
        head, rest = text.split("DATA_START\n", 1)
        data, tail = rest.split("DATA_STOP", 1)
        head, tail = head + "DATA_START\n", "DATA_STOP" + tail
    else:
        head, rest = text.split("<observation>", 1)
        data, tail = rest.rsplit("</observation>", 1)
        head, data, tail = head, "<observation>" + data + "</observation>", tail
    per_copy = len(set(re.findall(rf"{day}T[0-9:.]+", data)))
    target = int(mb * 1e6)
    written = len(head) + len(tail)
    copies = 0
    with out.open("w") as f:
        f.write(head)
        while written < target:
            block = data.replace(f"{day}T", f"{DAY0 + dt.timedelta(days=copies)}T")
            f.write(block)
            written += len(block)
            copies += 1
        f.write(tail)
    return out.stat().st_size, copies * per_copy


def timed_import(tdm: Path, bag: Path) -> dict[str, object]:
    """Run `import tdm` under /usr/bin/time -v: its exit code, output and the numbers."""
    cmd = ["/usr/bin/time", "-v", sys.executable, "-m", "ssa_fusion.apps.cli", "import", "tdm",
           str(tdm), "--bag", str(bag)]
    t0 = time.perf_counter()
    run = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True)
    wall = time.perf_counter() - t0
    rss = re.search(r"Maximum resident set size \(kbytes\): (\d+)", run.stderr)
    progress = [line for line in run.stderr.splitlines() if line.startswith("import tdm:")]
    return {"exit": run.returncode, "stdout": run.stdout.strip(), "wall_s": round(wall, 2),
            "peak_rss_mb": round(int(rss.group(1)) / 1024, 1) if rss else None,
            "progress": progress, "stderr_tail": run.stderr.strip().splitlines()[-25:]}


def bag_count(bag: Path) -> int:
    """The number of messages on /ssa/measurement in `bag` (its metadata)."""
    from ssa_fusion.ros import bagio
    from ssa_fusion.ros.topics import TOPIC_MEASUREMENT

    return sum(1 for _ in bagio.read_bag(bag, topics=(TOPIC_MEASUREMENT,)))


def main() -> int:
    """Generate the file, import it, check and print the numbers (last line JSON)."""
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--mb", type=float, default=100.0, help="size of the TDM file, MB")
    p.add_argument("--xml", action="store_true", help="an XML TDM (default KVN)")
    p.add_argument("--keep", type=Path, default=None,
                   help="directory to keep the TDM and the bag in (default: a temporary one)")
    args = p.parse_args()
    fmt = "xml" if args.xml else "kvn"
    with tempfile.TemporaryDirectory(prefix="bench_tdm_") as tmp:
        work = args.keep or Path(tmp)
        work.mkdir(parents=True, exist_ok=True)
        tdm = work / f"big_{args.mb:g}mb.{fmt}"
        size, epochs = big_tdm(sample_tdm(work, fmt), tdm, args.mb, fmt)
        print(f"file: {tdm.name} {size / 1e6:.1f} MB ({fmt.upper()}), {epochs} epochs")
        bag = work / f"bag_{args.mb:g}mb_{fmt}"
        r = timed_import(tdm, bag)
        print(f"import: exit {r['exit']}, {r['wall_s']} s, peak RSS {r['peak_rss_mb']} MB, "
              f"{len(r['progress'])} progress lines")  # type: ignore[arg-type]
        for line in r["progress"]:  # type: ignore[union-attr]
            print(f"  {line}")
        print(f"said: {r['stdout']}")
        if r["exit"] != 0:
            print("\n".join(r["stderr_tail"]))  # type: ignore[arg-type]
        assert r["exit"] == 0, "import failed"
        assert f"{epochs} range/az/el measurements" in str(r["stdout"]), r["stdout"]
        in_bag = bag_count(bag)
        assert in_bag == epochs, (in_bag, epochs)
        print(f"bag: {in_bag} measurements")
        print(json.dumps({"bench": "tdm_import", "format": fmt, "mb": round(size / 1e6, 1),
                          "epochs": epochs, "wall_s": r["wall_s"],
                          "peak_rss_mb": r["peak_rss_mb"],
                          "progress_lines": len(r["progress"])}))  # type: ignore[arg-type]
    return 0


if __name__ == "__main__":
    sys.exit(main())

"""Benchmark: a catalog of tens of thousands of objects over LEO, MEO, GEO and HEO through
the filter shards in lockstep: real-time factor, losses, memory per object.

The catalog: every element set of ``config/catalogs/celestrak_active_2025-07.tle`` (306 real
objects: 277 LEO, 8 MEO, 18 GEO, 3 HEO) spread into ``--objects`` / 306 copies each
(`sim.survey.synthetic_catalog`: the same orbit shape and regime, ascending node and mean
anomaly drawn uniformly), written as a TLE file (`sgp4.exporter`). Then

    ssa-fusion live --catalog FILE --duration HOURS --shards 2 --time-scale max --no-surrogate

(lockstep, as fast as the nodes go; the radar network of iss_network), and its summary
(``catalog.json``): measurements published, received and lost, sim time over wall time,
each filter shard's resident memory at the end over the objects it holds. While it runs,
the filter shards' resident memory is printed every ``--rss-period`` wall s (``/proc``): how
it grows over the day.

    nice -n 10 python bench/bench_catalog_scale.py [--objects 30000] [--hours 24]

Asserts that the run published measurements of objects of every regime it was given and
that the accounting adds up (lost = published - received). Prints the summary; the last line
is JSON. The targets it reports against (not asserted): >= 100x real time, 0 lost,
<= 20 KiB per object.

Each run's phases are timed apart, as the summary gives them: start-up (the command's start
to the first measurement), running (first measurement to last estimate) and summary (last
estimate to the summary printed); with each node's CPU time per measurement published and
the simulator's peak resident memory (it computes the measurements a window at a time).

``--base sample``: the flood instead, the sample's CBERS 2 spread into ``--objects`` LEO
objects (as ``live --catalog config/catalogs/sample.tle --synthetic N``); its target:
>= 20,000 measurements/s through the graph. ``--bad-sets``: ``config/catalogs/bad_sets.tle``
appended to the catalog written (a real catalog carries such sets): the run leaves them out,
names and counts them.

``--surrogate``: the same with a catalog_surrogate beside each filter shard (every gap
fitted: lockstep waits for the fits), ``--hours`` more than a day (the residual fits once
an object's pass ends span a day). Reports the fits made (of the learned residual and physics-only,
`core.catalog.gap_bank.GapBankConfig.physics`), refused and skipped, the
surrogates' fitting wall time and memory, and the gaps after the first day (an object's
estimate followed by ``pass_break`` or more without one) with the fraction that got a
forecast (`studies.catalog_gaps.gap_coverage`; also counted from each object's own first
gap); asserts that fits were made and forecasts published. Targets (not asserted):
>= 20x real time, >= 90 % of the gaps after the first day forecast.

``--conjunctions``: the conjunction node beside them (``live --conjunctions``: the newest
estimates re-screened every sim hour over a day, CDMs written); reports its re-screenings,
approaches and CDMs and asserts that every re-screening was recorded. Target (not asserted):
>= 20x real time with 30,000 objects, nothing lost.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path
from typing import Any

from sgp4.exporter import export_tle

from ssa_fusion.core.motion.element_sets import CatalogEntry
from ssa_fusion.formats import element_sets as catalog_io
from ssa_fusion.sim import survey

ROOT = Path(__file__).resolve().parents[1]
REAL = ROOT / "config" / "catalogs" / "celestrak_active_2025-07.tle"
SAMPLE = ROOT / "config" / "catalogs" / "sample.tle"
BAD_SETS = ROOT / "config" / "catalogs" / "bad_sets.tle"
TARGET_FLOOD = 20_000.0  # measurements/s through the graph, --base sample
TARGET_STARTUP_S = 30.0  # command start to the first measurement
TARGET_SPEED = 100.0  # x real time, the filter path
TARGET_KIB = 20.0  # per object, the filter processes
TARGET_SPEED_SURROGATE = 20.0  # x real time, filter and surrogate shards
TARGET_SPEED_CONJUNCTIONS = 20.0  # x real time, with the conjunction node (live, 30,000 objects)
TARGET_COVERED = 0.9  # of the gaps after the first day, with a forecast


def regime(entry: CatalogEntry) -> str:
    """LEO, MEO, GEO or HEO, from the element set's mean motion and eccentricity."""
    revs_per_day = entry.satrec.no_kozai * 1440.0 / (2.0 * 3.141592653589793)
    if entry.satrec.ecco > 0.25:
        return "HEO"
    if revs_per_day > 11.25:
        return "LEO"
    return "GEO" if 0.9 < revs_per_day < 1.1 else "MEO"


def write_catalog(path: Path, objects: int, seed: int, base: Path = REAL,
                  bad_sets: bool = False) -> dict[str, int]:
    """Write the spread catalog of `objects` as a TLE file; return objects per regime.

    Every set of `base` spread (the sample's: its first only); `bad_sets`: `BAD_SETS` after.
    """
    bases = catalog_io.read_catalog(base)
    if base == SAMPLE:
        bases = bases[:1]
    per, extra = divmod(objects, len(bases))
    counts: dict[str, int] = {}
    first = 1  # NORAD catalogue numbers start at 1
    with path.open("w") as f:
        for i, base in enumerate(bases):
            n = per + (i < extra)
            if not n:
                continue
            for e in survey.synthetic_catalog(base, n, seed=seed + i, first_id=first):
                line1, line2 = export_tle(e.satrec)
                f.write(f"{e.name}\n{line1}\n{line2}\n")
            counts[regime(base)] = counts.get(regime(base), 0) + n
            first += n
        if bad_sets:
            f.write(BAD_SETS.read_text())
    return counts


def _children() -> dict[int, list[int]]:
    """Return every process's children (Linux ``/proc``): parent pid -> child pids."""
    kids: dict[int, list[int]] = {}
    for d in Path("/proc").iterdir():
        if not d.name.isdigit():
            continue
        try:
            ppid = int((d / "stat").read_text().rsplit(")", 1)[1].split()[1])
        except (OSError, IndexError, ValueError):
            continue
        kids.setdefault(ppid, []).append(int(d.name))
    return kids


def filter_rss_kib(root: int) -> dict[str, int]:
    """Return the resident memory (KiB) of each catalog_filter process under pid `root`.

    Keyed by its node name (``__node:=`` of its command line), from ``/proc`` (Linux).
    """
    kids, out, todo = _children(), {}, [root]
    while todo:
        pid = todo.pop()
        todo += kids.get(pid, [])
        try:
            argv = (Path(f"/proc/{pid}/cmdline").read_bytes().decode(errors="replace")
                    .split("\0"))
            status = Path(f"/proc/{pid}/status").read_text()
        except OSError:
            continue
        name = next((a.split(":=", 1)[1] for a in argv if a.startswith("__node:=")), "")
        if not name.startswith("catalog_filter") or not any(
                a.endswith("catalog_filter") for a in argv[:3]):
            continue
        for line in status.splitlines():
            if line.startswith("VmRSS:"):
                out[name] = int(line.split()[1])
    return out


class RssSampler(threading.Thread):
    """Samples the filter shards' resident memory every `period_s` wall s while a run goes.

    ``samples``: (wall s since the start, {node name: KiB}) of each sample that found one;
    each is printed as it is taken (`line`).
    """

    def __init__(self, root: int, period_s: float) -> None:
        super().__init__(daemon=True)
        self.root, self.period_s = root, period_s
        self.samples: list[tuple[float, dict[str, int]]] = []
        self._done = threading.Event()
        self._t0 = time.perf_counter()

    def run(self) -> None:
        """Sample until `stop`."""
        while not self._done.wait(self.period_s):
            rss = filter_rss_kib(self.root)
            if rss:
                self.samples.append((time.perf_counter() - self._t0, rss))
                print(self.line(*self.samples[-1]), flush=True)

    def stop(self) -> None:
        """End the sampling (joins the thread)."""
        self._done.set()
        self.join()

    @staticmethod
    def line(t: float, rss: dict[str, int]) -> str:
        """Return one sample as a line: wall s, each shard's MiB and their sum."""
        each = " ".join(f"{n}={v / 1024:.0f}" for n, v in sorted(rss.items()))
        return f"  rss at {t:6.0f} s: {each} sum={sum(rss.values()) / 1024:.0f} MiB"


def main() -> None:
    """Build the catalog, run it, print the summary and the JSON line."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--objects", type=int, default=30_000)
    ap.add_argument("--hours", type=float, default=24.0)
    ap.add_argument("--shards", type=int, default=2)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--surrogate", action="store_true",
                    help="run a catalog_surrogate beside each filter shard")
    ap.add_argument("--rss-period", type=float, default=60.0,
                    help="wall s between two samples of the shards' resident memory")
    ap.add_argument("--base", choices=("real", "sample"), default="real",
                    help="spread the 306 real sets (default) or the sample's CBERS 2 (the "
                         "flood)")
    ap.add_argument("--bad-sets", action="store_true",
                    help="append config/catalogs/bad_sets.tle to the catalog written")
    ap.add_argument("--conjunctions", action="store_true",
                    help="add the conjunction node (live --conjunctions; target >= "
                         f"{TARGET_SPEED_CONJUNCTIONS:g}x real time)")
    args = ap.parse_args()
    load_before = os.getloadavg()
    print(f"load average at the start: {load_before[0]:.2f} {load_before[1]:.2f} "
          f"{load_before[2]:.2f} on {os.cpu_count()} cores")
    with tempfile.TemporaryDirectory() as tmp:
        root = Path(tmp)
        cat = root / "catalog.tle"
        t = time.perf_counter()
        regimes = write_catalog(cat, args.objects, args.seed,
                                REAL if args.base == "real" else SAMPLE, args.bad_sets)
        print(f"catalog: {args.objects} objects {regimes}, written in "
              f"{time.perf_counter() - t:.1f} s ({cat.stat().st_size / 1e6:.1f} MB)")
        cmd = [str(Path(sys.executable).parent / "ssa-fusion"), "live", "--catalog", str(cat),
               "--duration", str(args.hours), "--shards", str(args.shards),
               "--time-scale", "max", *([] if args.surrogate else ["--no-surrogate"]),
               *(["--conjunctions"] if args.conjunctions else []), "--out", str(root / "run")]
        print("$ " + " ".join(cmd[1:]), flush=True)
        t = time.perf_counter()
        with subprocess.Popen(cmd, env={**os.environ, "ROS_AUTOMATIC_DISCOVERY_RANGE":
                                        "LOCALHOST"}, stdout=subprocess.PIPE,
                              stderr=subprocess.PIPE, text=True) as proc:
            print(f"filter shards' resident memory every {args.rss_period:g} wall s:",
                  flush=True)
            sampler = RssSampler(proc.pid, args.rss_period)
            sampler.start()
            out, err = proc.communicate()
            sampler.stop()
        done = subprocess.CompletedProcess(cmd, proc.returncode, out, err)
        wall = time.perf_counter() - t
        print("\n".join(done.stdout.strip().splitlines()[-12:]))
        assert (root / "run" / "catalog.json").exists(), done.stderr[-3000:]
        s = json.loads((root / "run" / "catalog.json").read_text())
    published, received = s["published"], s["received_by_shards"]
    assert published > 0 and s["objects_with_estimates"] > 0, "nothing published or fused"
    assert s["lost_measurements"] >= abs(published - received), "the accounting is short"
    shards = s["per_shard"]
    held = sum(int(v["objects"]) for v in shards.values())
    rss_mib = sum(float(v["rss_mib"]) for v in shards.values())
    kib_per_object = rss_mib * 1024.0 / args.objects
    ran = s["sim_wall_s"] or float("nan")
    speed = s["live_real_time_factor"] or float("nan")
    target = (TARGET_SPEED_CONJUNCTIONS if args.conjunctions else
              TARGET_SPEED_SURROGATE if args.surrogate else TARGET_SPEED)
    print(f"published {published}, received {received}, lost {s['lost_measurements']}; "
          f"{s['sim_s'] / 3600:g} h of sim time in {ran:.0f} s from the first measurement to "
          f"the last estimate ({wall:.0f} s with start-up and the summary): {speed:.1f}x real "
          f"time (target >= {target:g}x)")
    print(f"filter shards: {held} objects held ({s['objects_with_estimates']} with estimates), "
          f"{rss_mib:.0f} MiB resident at the end: {kib_per_object:.1f} KiB per catalog object "
          f"(target <= {TARGET_KIB:g})")
    extra = surrogate_summary(s) if args.surrogate else {}
    if args.conjunctions:
        conj = s["conjunctions"]
        assert conj["rescreenings"] > 0 and conj["batches_recorded"] == conj["rescreenings"], (
            f"the conjunction node did not re-screen, or a re-screening went unrecorded: {conj}")
        print(f"conjunctions: {conj['rescreenings']} re-screenings (all recorded), "
              f"{conj['approaches_published']} approaches published, "
              f"{conj['approaches_standing']} standing, {conj['cdms']} CDMs")
        extra["conjunctions"] = {k: v for k, v in conj.items() if k != "cdm_dir"}
    extra.update(phase_summary(s))
    load_after = os.getloadavg()
    print(f"load average at the end: {load_after[0]:.2f} {load_after[1]:.2f} "
          f"{load_after[2]:.2f}")
    extra.update({"load_before": [round(v, 2) for v in load_before],
                  "load_after": [round(v, 2) for v in load_after]})
    print(json.dumps({"objects": args.objects, "regimes": regimes, "hours": args.hours,
                      "shards": args.shards, "published": published, "received": received,
                      "lost": s["lost_measurements"], "sim_s": s["sim_s"],
                      "graph_wall_s": ran, "command_wall_s": round(wall, 1),
                      "real_time_factor": round(speed, 1), "objects_held": held,
                      "objects_with_estimates": s["objects_with_estimates"],
                      "rss_mib": round(rss_mib, 1),
                      "kib_per_object": round(kib_per_object, 2), **extra}))


def phase_summary(s: dict[str, Any]) -> dict[str, Any]:
    """Print the run's phases, CPU per node, simulator memory and skips; return them."""
    def sec(key: str) -> str:
        return "?" if s.get(key) is None else f"{s[key]:.1f} s"

    print(f"phases: start-up {sec('startup_s')} (target <= {TARGET_STARTUP_S:g} s to the "
          f"first measurement), running {sec('running_s')}, summary {sec('summary_s')}; "
          f"{s.get('throughput_per_s') or 0:.0f} measurements/s through the graph (the flood's "
          f"target >= {TARGET_FLOOD:g})")
    print("CPU per measurement published: " + ", ".join(
        f"{n} {v} us ({s['cpu_s'][n]:.1f} s)" for n, v in s["cpu_us_per_measurement"].items()))
    print(f"sensor_sim peak RSS {s.get('simulator_peak_rss_mib')} MiB (target <= 1024); "
          f"element sets left out: {s.get('element_sets_skipped', 0)}")
    return {k: s.get(k) for k in ("startup_s", "running_s", "summary_s", "throughput_per_s",
                                  "cpu_us_per_measurement", "cpu_s", "simulator_peak_rss_mib",
                                  "element_sets_skipped")}


def surrogate_summary(s: dict[str, Any]) -> dict[str, Any]:
    """Print the surrogate shards' fits and gap coverage of summary `s`; return them.

    Asserts that fits were made and forecasts published.
    """
    g = s["surrogates"]
    total = {k: sum(int(v[k]) for v in g.values()) for k in (
        "fits_made", "fits_physics", "fits_refused", "fits_skipped", "waiting_for_fit",
        "published_forecast")}
    fit_s = sum(float(v["fit_seconds"]) for v in g.values())
    rss = sum(float(v["rss_mib"]) for v in g.values())
    gc = s["gap_coverage"]
    assert total["fits_made"] > 0 and total["published_forecast"] > 0, \
        f"no fits or no forecasts: {total}"
    covered = gc["with_forecast"] / gc["gaps"] if gc["gaps"] else float("nan")
    learned = total["fits_made"] - total["fits_physics"]
    print(f"surrogate shards: fits made {total['fits_made']} ({learned} of the learned "
          f"residual, {total['fits_physics']} physics-only), refused {total['fits_refused']}, "
          f"skipped {total['fits_skipped']}, waiting {total['waiting_for_fit']}; "
          f"{fit_s:.1f} s of fitting ({1e3 * fit_s / total['fits_made']:.1f} ms per fit "
          f"made); {total['published_forecast']} forecasts; {rss:.0f} MiB resident")
    print(f"gaps after the first {gc['after_s'] / 3600:g} h: {gc['gaps']}, "
          f"{gc['with_forecast']} with a forecast ({100 * covered:.1f} %, target >= "
          f"{100 * TARGET_COVERED:g} %); fits made / gaps "
          f"{total['fits_made'] / max(gc['gaps'], 1):.3f}")
    own = gc["object_with_forecast"] / max(gc["object_gaps"], 1)
    print(f"gaps {gc['after_s'] / 3600:g} h or more after the object's own first gap (when "
          f"its pass ends can span min_span): {gc['object_gaps']}, "
          f"{gc['object_with_forecast']} with a forecast ({100 * own:.1f} %)")
    return {**total, "fits_learned": learned, "fit_seconds": round(fit_s, 1),
            "object_gaps": gc["object_gaps"], "object_gaps_covered": round(own, 4),
            "ms_per_fit": round(1e3 * fit_s / total["fits_made"], 2),
            "surrogate_rss_mib": round(rss, 1), "gaps_after_first_day": gc["gaps"],
            "gaps_with_forecast": gc["with_forecast"], "gaps_covered": round(covered, 4)}

if __name__ == "__main__":
    main()

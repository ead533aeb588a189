"""Benchmark: a catalog run gives the same estimates on an idle and on a loaded machine.

`ssa-fusion live --catalog` (``--synthetic N`` LEO objects, ``--hours`` of the radar network,
two filter shards, no surrogate; ``--surrogate``: two surrogate shards too, every gap fitted,
fits from 3 pass ends over 6 h, so that a day's run has fits) three times:

* lockstep (the default) as fast as the nodes go (``--time-scale max``), machine idle;
* the same beside 4 CPU burners (busy loops, 2 cores);
* open loop (``--open-loop``) at ``--open-scale`` beside 4 CPU burners: what lockstep
  replaces.

Prints each run's accounting (published, recorded, lost), wall time and real-time factor,
and the estimates of the loaded runs against the idle one (count, bit-identical ones,
largest relative difference; with ``--surrogate`` the gap forecasts too), and whether the
bags hold the same /ssa/* messages (topic, log time, bytes). Asserts that the runs published
measurements, that the lockstep runs lost none, that their estimates (and forecasts) agree
to 1e-12 and that their bags are the same. The last line is JSON.

    nice -n 10 python bench/bench_lockstep.py [--objects 300] [--hours 6]
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

from bench_catalog import live_catalog, same_estimates


@contextmanager
def burners(n: int) -> Iterator[None]:
    """Run `n` busy-loop processes for the duration of the block."""
    procs = [subprocess.Popen([sys.executable, "-c", "while True: pass"]) for _ in range(n)]
    try:
        yield
    finally:
        for p in procs:
            p.kill()
            p.wait()


def same_bag(a: Path, b: Path) -> bool:
    """Whether two bags hold the same /ssa/* messages (`ros.bag_runs.same_messages`)."""
    from ssa_fusion.ros.bag_runs import same_messages

    return same_messages(a, b)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--objects", type=int, default=300)
    ap.add_argument("--hours", type=float, default=6.0)
    ap.add_argument("--open-scale", type=float, default=20000.0)
    ap.add_argument("--burners", type=int, default=4)
    ap.add_argument("--surrogate", action="store_true",
                    help="with the surrogate shards: compare the gap forecasts too")
    args = ap.parse_args()
    runs: dict[str, dict] = {}
    with tempfile.TemporaryDirectory() as tmp:
        root = Path(tmp)
        plan = [("lockstep_idle", 0, "max", ()),
                ("lockstep_loaded", args.burners, "max", ()),
                ("open_loop_loaded", args.burners, args.open_scale, ("--open-loop",))]
        fits = ("--surrogate-param", "min_span=21600", "--surrogate-param", "min_anchors=3")
        for name, load, scale, extra in plan:
            extra = (*extra, *fits) if args.surrogate else extra
            print(f"{name}: {load} burners, --time-scale {scale} {' '.join(extra)}")
            with burners(load):
                s = live_catalog(root / name, args.objects, args.hours, scale, 2,
                                 surrogate=args.surrogate, extra=extra,
                                 lossless=not extra)
            runs[name] = {"published": s["published"],
                          "recorded": s["recorded_measurements"],
                          "lost": s["lost_measurements"],
                          "refused_by_shards": s["received_by_shards"] - s["consumed_by_banks"],
                          "wall_s": round(s["wall_s"], 1),
                          "real_time_factor": round(args.hours * 3600.0 / s["wall_s"], 1)}
            print(f"  {runs[name]}")
        for name in ("lockstep_loaded", "open_loop_loaded"):
            try:
                n, same, worst = same_estimates(root / "lockstep_idle" / "bag", root / name / "bag")
                runs[name].update(estimates=n, bit_identical=same, worst_relative=worst)
                if args.surrogate:
                    n, same, worst = same_estimates(root / "lockstep_idle" / "bag",
                                                    root / name / "bag", forecasts=True)
                    runs[name].update(forecasts=n, forecasts_bit_identical=same,
                                      forecasts_worst_relative=worst)
            except AssertionError as exc:  # different (object, epoch) pairs: lost input
                runs[name].update(estimates_differ=str(exc))
            runs[name]["bag_identical"] = same_bag(root / "lockstep_idle" / "bag",
                                                   root / name / "bag")
            print(f"{name} against lockstep_idle: {runs[name]}")
    for name in ("lockstep_idle", "lockstep_loaded"):
        assert runs[name]["published"] > 1000 and runs[name]["lost"] == 0, runs[name]
    assert runs["lockstep_loaded"]["worst_relative"] <= 1e-12, runs["lockstep_loaded"]
    assert runs["lockstep_loaded"]["bag_identical"], "the lockstep runs' bags differ"
    if args.surrogate:
        assert runs["lockstep_loaded"]["forecasts"] > 0, "no gap forecast to compare"
        assert runs["lockstep_loaded"]["forecasts_worst_relative"] <= 1e-12, runs[
            "lockstep_loaded"]
    print(json.dumps({"objects": args.objects, "hours": args.hours,
                      "surrogate": args.surrogate, "runs": runs}))


if __name__ == "__main__":
    main()

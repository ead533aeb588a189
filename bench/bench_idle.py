"""Benchmark: what the catalog graph's nodes cost while they wait (CPU % of one core, idle).

Starts the nodes of a catalog run except the simulator (`graphs.catalog_graph`: the recorder,
one catalog_filter and its catalog_surrogate, and with ``--conjunctions`` the conjunction
node) as processes over DDS in a private domain, waits until each has reported on
``/diagnostics`` (started), then reads each process's CPU time (``/proc/PID/stat``: user +
system) over ``--seconds`` wall s while nothing is published: what they burn while the
simulator starts, or while they wait for a lockstep step. Then stops them (SIGTERM) and
times how long each took to exit.

    nice -n 10 tools/isolated.sh .venv/bin/python bench/bench_idle.py [--seconds 20]

Prints one line per node and a last line of JSON. Target (not asserted): <= 1 % of a core
per idle node. Asserts that every node was measured and exited 0.
"""

from __future__ import annotations

import argparse
import json
import os
import tempfile
import time
from pathlib import Path

from ssa_fusion import graphs
from ssa_fusion.ros.interfaces import DiagnosticArray
from ssa_fusion.ros.processes import Graph
from ssa_fusion.ros.topics import TOPIC_DIAGNOSTICS
from ssa_fusion.sim import sky

ROOT = Path(__file__).resolve().parents[1]
SAMPLE = ROOT / "config" / "catalogs" / "sample.tle"
TARGET_PERCENT = 1.0
"""Most CPU an idle node may take, % of one core."""
TICKS = os.sysconf("SC_CLK_TCK")


def cpu_s(pid: int) -> float:
    """Return the CPU time (user + system, s) process `pid` has used (Linux ``/proc``)."""
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / TICKS


def main() -> None:
    """Start the idle nodes, measure them, stop them, print the lines and the JSON."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seconds", type=float, default=20.0, help="wall s measured")
    ap.add_argument("--conjunctions", action="store_true", help="the conjunction node too")
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        root = Path(tmp)
        specs = [s for s in graphs.catalog_graph(
            sky.SKY_SCENARIOS[graphs.DEFAULT_SCENARIO], SAMPLE, 0, 0, 3600.0, float("inf"), 1,
            1, True, {}, root / "bag", conjunctions=root / "cdm" if args.conjunctions else None)
            if s.executable != "sensor_sim"]
        graph = Graph(root / "logs")
        try:
            diagnostics = graph.collect(DiagnosticArray, TOPIC_DIAGNOSTICS)
            procs = {s.name: graph.start_node(s.executable, "-r", f"__node:={s.name}",
                                              name=s.name, params=s.params) for s in specs}
            graph.wait_for(lambda: set(procs) <= {st.name for d in diagnostics
                                                  for st in d.status}, 120.0,
                           "every node's first /diagnostics report")
            time.sleep(2.0)  # the first seconds of a node: its imports' tail, discovery
            before = {n: cpu_s(p.popen.pid) for n, p in procs.items()}
            t0 = time.perf_counter()
            time.sleep(args.seconds)
            wall = time.perf_counter() - t0
            percent = {n: 100.0 * (cpu_s(p.popen.pid) - before[n]) / wall
                       for n, p in procs.items()}
            stop = time.perf_counter()
        finally:
            problems = graph.close()
        stop_s = time.perf_counter() - stop
    assert not problems, problems
    for name, pct in percent.items():
        print(f"{name}: {pct:.2f} % of a core idle over {wall:.1f} s (target <= "
              f"{TARGET_PERCENT:g} %)")
    print(f"stopped every node in {stop_s:.2f} s")
    print(json.dumps({"seconds": round(wall, 1), "idle_percent": {
        n: round(v, 2) for n, v in percent.items()}, "max_percent": round(max(percent.values()), 2),
        "stop_s": round(stop_s, 2)}))


if __name__ == "__main__":
    main()

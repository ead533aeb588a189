"""Benchmark: reading a bag of N measurements recorded as batches against one message each.

The same N range/az/el measurements (a catalog of `--objects` objects seen from three
stations, epochs one second apart in turns, values drawn at random within the plausible) are
written twice with the project's bag writer: as MeasurementBatch messages of `--rows` rows
each on /ssa/measurement_batch (as sensor_sim publishes a step's), and as one Measurement a
message on /ssa/measurement, each logged at its batch's log time (what a recorder of the
same step would log). Then each is read, best of `--repeat` in CPU time of the process
(`time.process_time`: the figures hold on a shared machine), by:

* ``read_bag``: the messages as stored (batches as batches), the floor;
* ``read_records``: what every reader reads with (`bagio.read_records`: a batch's rows as
  Measurement messages);
* ``evaluate.load``: what `ssa-fusion report` reads the bag with (into core measurements);
* ``export tdm``: `ssa-fusion export tdm` in process (reading, the TDM written; once: the
  writing, by ccsds-ndm, takes most of it).

Usage: .venv/bin/python bench/bench_bag_rows.py [--n 100000] [--rows 500] [--objects 1000]
[--repeat 3]  (prints a table, then one JSON line)
"""

from __future__ import annotations

import argparse
import contextlib
import io
import json
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from ssa_fusion.apps import cli, evaluate  # noqa: E402
from ssa_fusion.core.base.rows import MeasurementRows  # noqa: E402
from ssa_fusion.core.base.types import Kind  # noqa: E402
from ssa_fusion.ros import bagio, messages  # noqa: E402

T0 = 1_767_225_600.0  # 2026-01-01 UTC
STATIONS = ("millstone", "tira", "altair")


def measurements(n: int, objects: int, seed: int = 1) -> MeasurementRows:
    """N plausible range/az/el measurements of `objects` objects from `STATIONS`."""
    rng = np.random.default_rng(seed)
    ids = [f"obj{i:05d}" for i in rng.integers(0, objects, n)]
    z = np.column_stack([rng.uniform(400.0, 3000.0, n), rng.uniform(0.0, 2 * np.pi, n),
                         rng.uniform(0.1, 1.5, n)])
    R = np.tile(np.diag([0.02**2, 3e-4**2, 3e-4**2]), (n, 1, 1))
    return MeasurementRows(T0 + np.arange(n, dtype=float), ids,
                           [STATIONS[i % 3] for i in range(n)], z, R,
                           np.full(n, Kind.RANGE_AZ_EL, np.uint8),
                           shard_key=messages.shard_keys(ids))


def write(bag: Path, rows: MeasurementRows, per_batch: int, batches: bool) -> None:
    """Write `rows` to `bag` in batches of `per_batch` rows, or one message each."""
    c = bagio.rosbags_classes()
    writer = bagio.BagWriter(bag)
    topic = "/ssa/measurement_batch" if batches else "/ssa/measurement"
    writer.add_topic(topic, bagio.MEASUREMENT_BATCH if batches else bagio.MEASUREMENT)
    for i in range(0, len(rows), per_batch):
        part = rows.take(np.arange(i, min(i + per_batch, len(rows))))
        t_ns = int(messages.stamps_ns(part.t)[-1])
        if batches:
            writer.write_msg(topic, t_ns, messages.measurement_batch_to_msg(part, classes=c))
            continue
        for k in range(len(part)):
            m = evaluate.types.Measurement(float(part.t[k]), part.z[k], part.R[k],
                                           Kind.RANGE_AZ_EL, 0, part.object_id[k],
                                           part.frame_id[k])
            writer.write_msg(topic, t_ns, messages.measurement_to_msg(m, c))
    writer.close()


def best(fn: Callable[[], object], repeat: int) -> float:
    """Return the shortest CPU time (s) of this process over `repeat` calls of `fn`.

    CPU time, not wall time: on a machine other work shares, it is the work done alone.
    """
    times = []
    for _ in range(repeat):
        t = time.process_time()
        fn()
        times.append(time.process_time() - t)
    return min(times)


def export_tdm(bag: Path, out: Path) -> None:
    """`ssa-fusion export tdm BAG --out OUT` in process (OUT replaced)."""
    out.unlink(missing_ok=True)
    with contextlib.redirect_stdout(io.StringIO()):
        assert cli.main(["export", "tdm", str(bag), "--out", str(out)]) == 0


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--n", type=int, default=100_000, help="measurements")
    p.add_argument("--rows", type=int, default=500, help="rows a batch")
    p.add_argument("--objects", type=int, default=1000)
    p.add_argument("--repeat", type=int, default=3)
    a = p.parse_args()
    rows = measurements(a.n, a.objects)
    result: dict[str, dict[str, float]] = {}
    with tempfile.TemporaryDirectory() as tmp:
        for form in ("single", "batch"):
            bag = Path(tmp) / form
            t = time.process_time()
            write(bag, rows, a.rows, form == "batch")
            wrote = time.process_time() - t
            size = sum(f.stat().st_size for f in bag.iterdir()) / 1e6
            got = sum(1 for _ in bagio.read_records(bag))
            assert got == a.n, f"{form}: {got} records of {a.n}"
            result[form] = {
                "write_s": wrote, "bag_mb": size,
                "read_bag_s": best(lambda b=bag: sum(1 for _ in bagio.read_bag(b)), a.repeat),
                "read_records_s": best(lambda b=bag: sum(1 for _ in bagio.read_records(b)),
                                       a.repeat),
                "evaluate_load_s": best(lambda b=bag: evaluate.load(b), a.repeat),
                "export_tdm_s": best(lambda b=bag, f=form: export_tdm(
                    b, Path(tmp) / f"{f}.tdm"), 1),
            }
        same = (Path(tmp) / "single.tdm").read_text().splitlines()
        other = (Path(tmp) / "batch.tdm").read_text().splitlines()
        assert [x for x in same if "CREATION_DATE" not in x] == [
            x for x in other if "CREATION_DATE" not in x], "the TDMs differ"
    print(f"N = {a.n} range/az/el measurements of {a.objects} objects; batches of {a.rows} "
          f"rows; CPU s, best of {a.repeat}")
    print(f"{'':18s} {'single':>10s} {'batch':>10s} {'single/batch':>13s}")
    for key in result["single"]:
        s, b = result["single"][key], result["batch"][key]
        print(f"{key:18s} {s:10.3f} {b:10.3f} {s / b:13.2f}")
    print(json.dumps({"n": a.n, "rows": a.rows, **result}))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

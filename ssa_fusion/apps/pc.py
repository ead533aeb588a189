"""`ssa-fusion pc FILE...`: the collision probability of CCSDS CDMs, beside the message's own.

Each file is read (`formats.ccsds.cdm`, KVN or XML) and its Pc computed from its two states,
RTN covariances and hard-body radius (`core.conjunction.collision_probability`): Foster's 2D
Pc, or with ``--method mc`` the 3D Monte Carlo Pc; a message without a covariance gets the
largest Pc the missing one allows. Printed: a table of TCA, miss distance, our Pc, the
message's ``COLLISION_PROBABILITY`` and the relative difference (computed from the logs, so
a Pc of 1e-168 compares too), the method and its warnings; ``--json`` prints one JSON object
per message instead. A file that cannot be read is one line on stderr, and the exit code
is 1 (the other files are still done).
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from dataclasses import dataclass

from ssa_fusion.core.conjunction.probability import collision_probability
from ssa_fusion.core.conjunction.result import PcMethod, PcResult
from ssa_fusion.formats.ccsds.cdm import Cdm, read_cdm
from ssa_fusion.formats.ccsds.common import CcsdsError

_METHODS = {"foster": PcMethod.FOSTER_2D, "mc": PcMethod.MONTE_CARLO_3D}


@dataclass(frozen=True)
class Row:
    """One message's Pc beside its own."""

    path: str
    cdm: Cdm
    result: PcResult

    @property
    def rel_diff(self) -> float | None:
        """(ours - message's) / message's, from the logs (None without a message Pc > 0)."""
        theirs = self.cdm.pc
        if theirs is None or theirs <= 0 or not math.isfinite(self.result.log10_pc):
            return None
        return math.expm1((self.result.log10_pc - math.log10(theirs)) * math.log(10.0))

    def as_json(self) -> dict[str, object]:
        """Return the row as the JSON object ``--json`` prints."""
        r = self.result
        return {"file": self.path, "message_id": self.cdm.message_id, "tca": self.cdm.tca_text,
                "miss_m": r.miss_km * 1e3, "pc": r.pc, "log10_pc": r.log10_pc,
                "method": r.method.value, "message_pc": self.cdm.pc,
                "message_method": self.cdm.pc_method, "rel_diff": self.rel_diff,
                "warnings": sorted(w.value for w in r.warnings),
                **({"std_error": r.std_error, "samples": r.samples} if r.samples else {})}


def add_arguments(p: argparse.ArgumentParser) -> None:
    """Add the `pc` command's arguments."""
    p.add_argument("files", nargs="+", metavar="FILE", help="CDM files (KVN or XML)")
    p.add_argument("--json", action="store_true",
                   help="print one JSON object per message instead of the table")
    p.add_argument("--hbr", type=float, default=None, metavar="M",
                   help="combined hard-body radius, m (default: the message's HBR)")
    p.add_argument("--method", choices=sorted(_METHODS), default="foster",
                   help="foster: the 2D Pc (default); mc: the 3D Monte Carlo Pc")
    p.add_argument("--samples", type=int, default=100_000,
                   help="Monte Carlo sample pairs (--method mc; default 100000)")


def _row(path: str, args: argparse.Namespace) -> Row:
    """Read one CDM and compute its Pc; CcsdsError (one line) when it cannot."""
    cdm = read_cdm(path)
    hbr = args.hbr * 1e-3 if args.hbr is not None else cdm.hbr_km
    if hbr is None or not hbr > 0:
        raise CcsdsError(f"{path}: no hard-body radius (HBR, or COMMENT HBR = ... [m]); "
                         f"give --hbr")
    x1, p1, x2, p2 = cdm.inputs()
    method = _METHODS[args.method]
    if method is PcMethod.MONTE_CARLO_3D and (p1 is None or p2 is None):
        raise CcsdsError(f"{path}: a covariance is missing: no Monte Carlo Pc")
    return Row(path, cdm, collision_probability(x1, p1, x2, p2, hbr, method,
                                                samples=args.samples))


def _pc_text(pc: float | None, log10_pc: float | None = None) -> str:
    """Return a Pc for the table (its log10 when below the float range)."""
    if pc is None:
        return "-"
    if pc == 0 and log10_pc is not None and math.isfinite(log10_pc):
        return f"1e{log10_pc:.1f}"
    return f"{pc:.4e}"


def table(rows: list[Row]) -> list[str]:
    """Return the lines of the table of rows."""
    head = (f"{'message':<40} {'TCA (UTC)':<24} {'miss [m]':>10} {'Pc':>11} "
            f"{'CDM Pc':>11} {'rel diff':>9}  method / warnings")
    out = [head, "-" * len(head)]
    for row in rows:
        r, d = row.result, row.rel_diff
        name = row.cdm.message_id or row.path
        out.append(f"{name[:40]:<40} {row.cdm.tca_text[:24]:<24} {r.miss_km * 1e3:>10.1f} "
                   f"{_pc_text(r.pc, r.log10_pc):>11} {_pc_text(row.cdm.pc):>11} "
                   f"{'-' if d is None else f'{d * 100:+.3f}%':>9}  {r.method.value}"
                   f"{' ' + ','.join(sorted(w.value for w in r.warnings)) if r.warnings else ''}")
    return out


def run(args: argparse.Namespace) -> int:
    """Run `ssa-fusion pc`: 0 when every file was read, 1 otherwise."""
    rows: list[Row] = []
    failed = 0
    for path in args.files:
        try:
            row = _row(path, args)
        except (CcsdsError, ValueError) as exc:
            print(f"error: {exc}", file=sys.stderr)
            failed += 1
            continue
        rows.append(row)
        if args.json:
            print(json.dumps(row.as_json()), flush=True)
    if not args.json and rows:
        print("\n".join(table(rows)))
    return 1 if failed else 0

"""Benchmark: the high-fidelity force model against Orekit over a day, and its cost per call.

Two orbits from 2016-02-13 00:00 UTC: LAGEOS-2 (a = 12,270 km, e = 0.0135, i = 52.6 deg,
A/m = 7e-4 m^2/kg, Cr = 1.13) and a LEO (700 km, i = 98.2 deg, A/m = 0.01 m^2/kg, Cr = 1.3,
drag with a ballistic coefficient of 100 kg/m^2 in the exponential atmosphere), each
propagated over 24 h by `ssa_fusion.core.motion.high_fidelity.propagate` (fixed-step DOP853,
60 s) and by Orekit (adaptive DOP853, the step and tolerance of `OREKIT_SETTINGS`) with the
same forces, switched on one at a time and all together: the
EGM96 geopotential 20 x 20 (the central term alone with every other force), the Sun, the
Moon, solar radiation pressure (conical shadow), drag (the LEO). Printed: the largest
position difference over the day (positions every 5 min), per case; target <= 1 cm.

Orekit runs in a virtual environment of its own (never a dependency of ssa_fusion), found at
``$OREKIT_VENV`` (default ``~/orekit-venv``); create it with::

    python3 -m venv ~/orekit-venv
    ~/orekit-venv/bin/pip install orekit-jpype jplephem==2.24 de421==2008.1

(JDK 11+ on the PATH). Orekit reads the same data as ssa_fusion, prepared here in a temporary
directory: the IERS finals2000A and leap-second tables of astropy-iers-data (the finals'
dX/dY nutation corrections zeroed, as `frames` does not apply them), and the EGM96 file
shipped with ssa_fusion; the Sun and the Moon are DE421 evaluated by jplephem inside the
Orekit process (`orekit_reference.py`). Without that environment the comparison is skipped
with a message, and the timing part still runs.

Timing: microseconds (CPU time) per derivative call with the STM (6 x 6 + the Cr
sensitivity) inside a day's integration (the day's time divided by its 1440 x 12 stage
calls), 20 x 20 + Sun/Moon + SRP, beside the catalog's two-body + J2 kernel with its STM
(`propagation.integrate_stm`); and the CPU time of one three-day LAGEOS-2 arc with the STM
(what one iteration of an orbit fit over the real data integrates).

Usage::

    python bench/bench_force_model.py [--skip-orekit]

Last line: a JSON object. Asserts that the propagations were finite, and, when Orekit ran,
that every case was compared.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # run from a source checkout

from ssa_fusion.core.base.constants import R_EARTH
from ssa_fusion.core.earth.ephemeris import sun_moon_span
from ssa_fusion.core.earth.timescales import iso, parse_utc
from ssa_fusion.core.motion import high_fidelity as hf
from ssa_fusion.core.motion import propagation
from ssa_fusion.core.motion.force_spec import AU_KM, SOLAR_PRESSURE, DragSpec, ForceSpec, SrpSpec
from ssa_fusion.formats.icgem import EGM96_FILE, egm96

EPOCH = "2016-02-13T00:00:00"
DAY_S = 86400.0
STEP_S = 60.0
OFFSETS = np.arange(0.0, DAY_S + 1.0, 300.0)
MASS_KG = 1000.0
TARGET_M = 0.01
LAGEOS_STEP_S = 300.0
"""Step of the timed three-day LAGEOS-2 arc (0.25 mm from 20 s steps after three days)."""
OREKIT_SETTINGS = {"lageos2": (300.0, 1e-4), "leo700": (10.0, 1e-6)}
"""Orekit's longest step (s) and position tolerance (m) per orbit. Measured in LEO: with
1e-4 m and steps up to 300 s Orekit's own result moves by 7 cm (20 x 20) to 37 cm (SRP)
after a day when asked for its positions every 60 s instead of 300 s; with SRP it needs
steps of 10 s and 1e-6 m to settle (0.1 mm from ssa_fusion; 5 cm at 60 s and 1e-4 m)."""


def _kepler_state(a: float, e: float, i: float, raan: float, argp: float,
                  nu: float) -> np.ndarray:
    """GCRF state (km, km/s) of Keplerian elements (km, rad) about EGM96's GM."""
    mu = egm96().gm
    p = a * (1 - e * e)
    r = p / (1 + e * math.cos(nu))
    rp = np.array([r * math.cos(nu), r * math.sin(nu), 0.0])
    vp = math.sqrt(mu / p) * np.array([-math.sin(nu), e + math.cos(nu), 0.0])
    cO, sO, ci, si, cw, sw = (math.cos(raan), math.sin(raan), math.cos(i), math.sin(i),
                              math.cos(argp), math.sin(argp))
    R = np.array([[cO * cw - sO * sw * ci, -cO * sw - sO * cw * ci, sO * si],
                  [sO * cw + cO * sw * ci, -sO * sw + cO * cw * ci, -cO * si],
                  [sw * si, cw * si, ci]])
    return np.concatenate([R @ rp, R @ vp])


ORBITS = {
    "lageos2": (_kepler_state(12270.0, 0.0135, math.radians(52.64), 1.0, 2.0, 0.5),
                SrpSpec(7.0e-4, 1.13), None),
    "leo700": (_kepler_state(7078.0, 0.001, math.radians(98.2), 0.3, 1.0, 0.0),
               SrpSpec(0.01, 1.3), DragSpec(bc=100.0)),
}


def _cases() -> list[tuple[str, np.ndarray, ForceSpec]]:
    """(name, x0, spec) of every case: each force alone, then all of them."""
    g = egm96()
    out = []
    for orbit, (x0, srp, drag) in ORBITS.items():
        alone = {"geopotential": ForceSpec(g, 20, sun=False, moon=False),
                 "sun": ForceSpec(g, 0, sun=True, moon=False),
                 "moon": ForceSpec(g, 0, sun=False, moon=True),
                 "srp": ForceSpec(g, 0, sun=False, moon=False, srp=srp)}
        if drag is not None:
            alone["drag"] = ForceSpec(g, 0, sun=False, moon=False, drag=drag)
        alone["all"] = ForceSpec(g, 20, sun=True, moon=True, srp=srp, drag=drag)
        out += [(f"{orbit} {name}", x0, spec) for name, spec in alone.items()]
    return out


def _job_case(name: str, x0: np.ndarray, spec: ForceSpec) -> dict:
    deg, order = spec.truncation
    f: dict = {"degree": deg, "order": order, "sun": spec.sun, "moon": spec.moon,
               "srp": spec.srp is not None, "drag": spec.drag is not None}
    if spec.srp is not None:
        f.update(area_to_mass=spec.srp.area_to_mass, cr=spec.srp.cr)
    if spec.drag is not None:
        d = spec.drag
        f.update(bc=d.bc, rho0=d.rho0, h0=d.h0 * 1e3, scale_height=d.scale_height * 1e3)
    return {"name": name, "epoch": EPOCH, "x0": (x0 * 1e3).tolist(), "forces": f,
            "mass": MASS_KG, "offsets": OFFSETS.tolist(),
            "max_step": OREKIT_SETTINGS[name.split()[0]][0],
            "tolerance": OREKIT_SETTINGS[name.split()[0]][1]}


def _data_dir(root: Path) -> Path:
    """Orekit's data: the product's EOP (dX, dY zeroed), leap seconds and EGM96."""
    import astropy_iers_data

    src = Path(astropy_iers_data.IERS_A_FILE)
    lines = []
    for line in src.read_text().splitlines():
        chars = list(line.ljust(185))
        for a, b in ((98, 106), (117, 125), (166, 175), (176, 185)):
            if line[a - 1:b].strip():
                chars[a - 1:b] = list("0.000".rjust(b - a + 1))
        lines.append("".join(chars).rstrip())
    (root / "finals2000A.all").write_text("\n".join(lines) + "\n")
    (root / "tai-utc.dat").write_text(_tai_utc(src.parent / "Leap_Second.dat"))
    shutil.copy(EGM96_FILE, root / EGM96_FILE.name)
    return root


def _tai_utc(leap_second_dat: Path) -> str:
    """The IERS Leap_Second.dat table in USNO's tai-utc.dat format (which Orekit reads)."""
    months = ["JAN", "FEB", "MAR", "APR", "MAY", "JUN", "JUL", "AUG", "SEP", "OCT", "NOV",
              "DEC"]
    out = []
    for line in leap_second_dat.read_text().splitlines():
        w = line.split()
        if not w or line.startswith("#"):
            continue
        mjd, day, month, year, dat = float(w[0]), int(w[1]), int(w[2]), int(w[3]), int(w[4])
        out.append(f" {year} {months[month - 1]} {day:2d} =JD {mjd + 2400000.5:.1f}  "
                   f"TAI-UTC= {dat:4.1f}       S + (MJD - 41317.) X 0.0      S")
    return "\n".join(out) + "\n"


def _orekit_python() -> Path | None:
    venv = Path(os.environ.get("OREKIT_VENV", Path.home() / "orekit-venv"))
    py = venv / "bin" / "python"
    return py if py.exists() else None


def _run_orekit(cases: list, py: Path) -> dict:
    t0 = parse_utc(EPOCH)
    span = sun_moon_span(t0, 0.0, DAY_S)
    import erfa

    from ssa_fusion.core.earth.timescales import jd_tt
    j1, j2 = jd_tt(np.array([t0, t0 + DAY_S]))
    tdb_tt = erfa.dtdb(j1, j2, 0.0, 0.0, 0.0, 0.0)
    with tempfile.TemporaryDirectory() as tmp:
        root = _data_dir(Path(tmp))
        job = {"data_dir": str(root), "gravity_file": EGM96_FILE.name,
               "epoch": EPOCH, "tdb_minus_tt": float(tdb_tt[0]),
               "tdb_rate": float(tdb_tt[1] - tdb_tt[0]) / DAY_S,
               "earth_share": span.earth_share, "gm_sun": span.gm_sun * 1e9,
               "gm_moon": span.gm_moon * 1e9, "earth_radius": R_EARTH * 1e3,
               "au": AU_KM * 1e3, "solar_pressure": SOLAR_PRESSURE,
               "cases": [_job_case(*c) for c in cases]}
        (root / "job.json").write_text(json.dumps(job))
        script = Path(__file__).with_name("orekit_reference.py")
        subprocess.run([str(py), str(script), str(root / "job.json"), str(root / "out.json")],
                       check=True, timeout=3000)
        result: dict = json.loads((root / "out.json").read_text())
    return result


def _ours(cases: list) -> dict:
    t0 = parse_utc(EPOCH)
    out = {}
    for name, x0, spec in cases:
        tr = hf.propagate(spec, x0, t0, t0 + OFFSETS, max_step_s=STEP_S, stm=False)
        assert tr.ok.all(), name
        out[name] = tr.x[:, :3]
    return out


def _timing() -> dict:
    """Microseconds per derivative call with the STM: the full model and the J2 kernel.

    CPU time of this process (the kernels are single-threaded): the machine's other load
    does not enter, as it would in wall time.
    """
    t0 = parse_utc(EPOCH)
    x0, srp, _ = ORBITS["leo700"]
    spec = ForceSpec(egm96(), 20, sun=True, moon=True, srp=srp)
    ctx = hf.setup(spec, t0, 0.0, DAY_S)
    calls = math.ceil(DAY_S / STEP_S) * 12
    hf.propagate(ctx, x0, t0, [t0 + 600.0], which=[4])  # compile / load
    best = math.inf
    for _ in range(3):
        tic = time.process_time()
        tr = hf.propagate(ctx, x0, t0, [t0 + DAY_S], which=[4], max_step_s=STEP_S)
        best = min(best, time.process_time() - tic)
    assert tr.ok.all() and np.isfinite(tr.phi).all()
    propagation.integrate_stm("j2", x0[None], [600.0])
    best_j2 = math.inf
    for _ in range(3):
        tic = time.process_time()
        _, _, ok = propagation.integrate_stm("j2", x0[None], [DAY_S], STEP_S)
        best_j2 = min(best_j2, time.process_time() - tic)
    assert ok.all()
    x1, _, _ = ORBITS["lageos2"]
    t = t0 + np.linspace(0.0, 3 * DAY_S, 70)
    tic = time.process_time()
    arc = hf.propagate(ForceSpec(egm96(), 20, srp=ORBITS["lageos2"][1]), x1, t0, t, which=[4],
                       max_step_s=LAGEOS_STEP_S)
    arc_s = time.process_time() - tic
    assert arc.ok.all()
    return {"full_us_per_call": best / calls * 1e6, "j2_us_per_call": best_j2 / calls * 1e6,
            "full_day_s": best, "j2_day_s": best_j2, "lageos_3day_arc_s": arc_s}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--skip-orekit", action="store_true")
    args = ap.parse_args()
    cases = _cases()
    ours = _ours(cases)
    py = None if args.skip_orekit else _orekit_python()
    rows: dict[str, float] = {}
    if py is None:
        print("Orekit comparison skipped: no Orekit environment (set OREKIT_VENV; see the "
              "module docstring to create one)" if not args.skip_orekit else
              "Orekit comparison skipped (--skip-orekit)")
    else:
        tic = time.perf_counter()
        ref = _run_orekit(cases, py)
        print(f"Orekit ran in {time.perf_counter() - tic:.1f} s ({EPOCH} UTC, 24 h, "
              f"positions every {OFFSETS[1] - OFFSETS[0]:.0f} s)")
        print(f"{'case':<24} {'max |dr| vs Orekit [mm]':>24}")
        for name, _, _ in cases:
            d = np.linalg.norm(ours[name] * 1e3 - np.asarray(ref[name]), axis=1)
            rows[name] = float(d.max())
            flag = "" if rows[name] <= TARGET_M else "  > 1 cm"
            print(f"{name:<24} {rows[name] * 1e3:>24.4f}{flag}")
        assert len(rows) == len(cases)
    t = _timing()
    print(f"derivative with STM, 20x20 + Sun/Moon + SRP: {t['full_us_per_call']:.2f} us/call "
          f"(a day at {STEP_S:.0f} s: {t['full_day_s'] * 1e3:.0f} ms); two-body + J2 kernel: "
          f"{t['j2_us_per_call']:.3f} us/call ({t['j2_day_s'] * 1e3:.1f} ms)")
    print(f"a three-day LAGEOS-2 arc to 70 epochs with STM and Cr sensitivity, "
          f"{LAGEOS_STEP_S:.0f} s steps (20x20 + Sun/Moon + SRP): "
          f"{t['lageos_3day_arc_s'] * 1e3:.0f} ms")
    print(json.dumps({"epoch": EPOCH, "step_s": STEP_S, "orekit": py is not None,
                      "max_diff_m": rows, "target_m": TARGET_M,
                      "all_within_target": bool(rows) and max(rows.values()) <= TARGET_M,
                      **t, "time_utc": iso(time.time())}))


if __name__ == "__main__":
    main()

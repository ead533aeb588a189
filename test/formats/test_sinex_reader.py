"""The SINEX reader (formats.sinex): SLRF2014 positions and velocities and the ILRS
eccentricities against values read off the files by hand, the choice of a station's
solution and eccentricity by epoch, and hostile files refused in one line."""

from __future__ import annotations

import calendar

import numpy as np
import pytest
from crd_samples import bounded
from fuzz_text import error_of, mutated
from hypothesis import HealthCheck, given, settings
from realdata import ECCENTRICITIES, STATIONS, lageos, needs_lageos

from ssa_fusion.formats import sinex
from ssa_fusion.formats.records import RecordError

T2016 = float(calendar.timegm((2016, 2, 13, 12, 0, 0)))
T2010 = float(calendar.timegm((2010, 1, 1, 0, 0, 0)))


def estimate(idx, typ, code, value, unit="m", soln="1", epoch="10:001:00000", std=1e-3):
    return (f" {idx:5d} {typ:6s} {code:4s} {'A':>2s} {soln:>4s} {epoch:12s} {unit:4s} 2 "
            f"{value:21.14E} {std:11.5E}")


def eccentricity(code, start, end, une, system="UNE", soln="1"):
    return (f" {code:4s} {'A':>2s} {soln:>4s} L {start} {end} {system}"
            + "".join(f"{v:9.4f}" for v in une))


def snx(*blocks: tuple[str, list[str]]) -> str:
    lines = ["%=SNX 2.02 TST 20:001:00000 TST 10:001:00000 20:001:00000 L 00002 2 X V"]
    for name, rows in blocks:
        lines += [f"+{name}", f"*a comment of {name}", *rows, f"-{name}"]
    return "\n".join([*lines, "%ENDSNX", ""])


GOOD = snx(
    ("SOLUTION/EPOCHS", [" 7001  A    1 C 00:001:00000 10:100:00000 05:001:00000",
                         " 7001  A    2 C 10:200:00000 00:000:00000 15:001:00000"]),
    ("SOLUTION/ESTIMATE", [estimate(i + 1, t, "7001", v, u, s) for i, (t, v, u, s) in enumerate(
        [("STAX", 4500000.0, "m", "1"), ("STAY", 3000000.0, "m", "1"),
         ("STAZ", 3400000.0, "m", "1"), ("VELX", 0.01, "m/y", "1"),
         ("STAX", 4500000.5, "m", "2"), ("STAY", 3000000.0, "m", "2"),
         ("STAZ", 3400000.0, "m", "2"), ("LOD", 1.0, "ms", "1")])]),
    ("SITE/ECCENTRICITY", [eccentricity("7001", "00:001:00000", "10:100:86399", (1.0, 0, 0)),
                           eccentricity("7001", "10:101:00000", "00:000:00000",
                                        (2.5, -1490.101, 4030.63))]))


@needs_lageos
def test_slrf2014_and_eccentricities_as_checked_by_hand():
    sol = sinex.read_solutions(lageos(STATIONS))
    y = sinex.solution_at(sol, "7090", T2016)
    #   205 STAX   7090  A    1 10:001:00000 m    2 -.238900753398029E+07 0.51901E-03
    np.testing.assert_array_equal(y.position_m, [-.238900753398029E+07, 0.504332944749889E+07,
                                                 -.307852422322662E+07])
    np.testing.assert_array_equal(y.velocity_m_yr, [-.468389138240797E-01,
                                                    0.839461295243685E-02,
                                                    0.509471988578335E-01])
    assert y.sigma_m[0] == 0.51901E-03 and y.t_ref == T2010 and y.line == 1028
    # 7090 A 1 C 83:011:58876 30:000:00000: from 1983-01-11 16:21:16 to "2030 day 0"
    assert y.start == calendar.timegm((1983, 1, 11, 16, 21, 16))
    assert y.end == calendar.timegm((2029, 12, 31, 0, 0, 0))
    m = sinex.solution_at(sol, "7941", T2016)
    assert m.position_m[0] == 0.464197861713781E+07 and m.velocity_m_yr[2] == 0.144917604701781E-01
    # 1868 has two solutions with a gap between them (03:157 .. 03:279)
    assert sinex.solution_at(sol, "1868", calendar.timegm((2000, 1, 1, 0, 0, 0))).solution == "1"
    assert sinex.solution_at(sol, "1868", T2016).solution == "2"
    with pytest.raises(RecordError, match="station 1868: no solution for 2003-08-01"):
        sinex.solution_at(sol, "1868", calendar.timegm((2003, 8, 1, 0, 0, 0)), "f")
    with pytest.raises(RecordError, match="no SOLUTION/ESTIMATE of station 9999"):
        sinex.solution_at(sol, "9999", T2016, "f")

    ecc = sinex.read_eccentricities(lageos(ECCENTRICITIES))
    # 7090 A 1 L 14:080:00000 00:000:00000 UNE 3.1827 -0.0064 0.0194 (line 905)
    e = sinex.eccentricity_at(ecc, "7090", T2016)
    np.testing.assert_array_equal(e.une_m, [3.1827, -0.0064, 0.0194])
    assert (e.line, e.end) == (905, None)
    old = sinex.eccentricity_at(ecc, "7090", calendar.timegm((1990, 1, 1, 0, 0, 0)))
    np.testing.assert_array_equal(old.une_m, [3.1770, 0.0030, 0.0100])  # line 895
    np.testing.assert_array_equal(sinex.eccentricity_at(ecc, "7119", T2016).une_m,
                                  [2.6304, 0.0029, 0.0032])
    assert not sinex.eccentricity_at(ecc, "7825", T2016).une_m.any()
    # fixed columns: 7307 A 1 L ... UNE -17.6930-1490.101-4030.630 (the numbers touch)
    far = [x for x in ecc if x.code == "7307" and x.point == "A"]
    np.testing.assert_array_equal(far[0].une_m, [-17.6930, -1490.101, -4030.630])


def test_a_small_file_and_the_choice_by_epoch(tmp_path):
    p = tmp_path / "ok.snx"
    p.write_text(GOOD)
    sol = sinex.read_solutions(p)
    assert sorted(sol) == [("7001", "A", "1"), ("7001", "A", "2")]
    one = sol[("7001", "A", "1")]
    np.testing.assert_array_equal(one.velocity_m_yr, [0.01, 0.0, 0.0])  # VELY, VELZ absent: 0
    assert sinex.solution_at(sol, "7001", calendar.timegm((2012, 1, 1, 0, 0, 0))
                             ).position_m[0] == 4500000.5
    ecc = sinex.read_eccentricities(p)
    assert [e.une_m[0] for e in ecc] == [1.0, 2.5]
    np.testing.assert_array_equal(ecc[1].une_m, [2.5, -1490.101, 4030.63])


def _replace(old, new, text=GOOD):
    assert old in text
    return text.replace(old, new, 1)


HOSTILE = {
    "no header": (GOOD.split("\n", 1)[1], ":1: not a SINEX file"),
    "no %ENDSNX": (_replace("%ENDSNX\n", ""), "the file ends without %ENDSNX: truncated?"),
    "an unclosed block": (_replace("-SITE/ECCENTRICITY\n", ""),
                          "%ENDSNX inside block SITE/ECCENTRICITY"),
    "nested blocks": (_replace("+SOLUTION/ESTIMATE", "+SOLUTION/ESTIMATE\n+OTHER"),
                      "+OTHER inside block SOLUTION/ESTIMATE"),
    "closing another block": (_replace("-SOLUTION/EPOCHS", "-SOLUTION/ESTIMATE"),
                              "-SOLUTION/ESTIMATE closes no open block"),
    "a data line outside blocks": (_replace("%ENDSNX", " 7001 A stray\n%ENDSNX"),
                                   "a data line outside any block"),
    "NaN value": (_replace("4.50000000000000E+06", " " * 17 + "nan"),
                  "SOLUTION/ESTIMATE: estimated value: nan is not a decimal number"),
    "wrong unit": (_replace("VELX   7001  A    1 10:001:00000 m/y", "VELX   7001  A    1 "
                            "10:001:00000 mm  "), "unit mm of VELX: want m/y"),
    "bad epoch": (_replace("10:001:00000 m   ", "10:400:00000 m   "),
                  "reference epoch: 10:400:00000 is not a day of 2010"),
    "an epoch that is not one": (_replace("10:001:00000 m   ", "1O:001:00000 m   "),
                                 "is not an epoch YY:DDD:SSSSS"),
    "a station inside the Earth": (_replace("4.50000000000000E+06", "1.00000000000000E+06"),
                                   "km from the geocentre: not at the Earth's surface"),
    "STAZ missing": (snx(("SOLUTION/ESTIMATE", [estimate(1, "STAX", "7001", 4.5e6),
                                                estimate(2, "STAY", "7001", 3e6)])),
                     "station 7001 A 1 has no STAZ"),
    "a parameter twice": (snx(("SOLUTION/ESTIMATE", [estimate(1, "STAX", "7001", 4.5e6),
                                                     estimate(2, "STAX", "7001", 4.5e6)])),
                          "STAX of 7001 A 1 given twice (first at line 4)"),
    "a truncated line": (_replace(estimate(3, "STAZ", "7001", 3400000.0),
                                  estimate(3, "STAZ", "7001", 3400000.0)[:60]),
                         "a line of 60 characters, want 80 (truncated?)"),
    "XYZ eccentricity": (_replace(" UNE ", " XYZ "), "reference system XYZ"),
    "eccentricity end before start": (_replace("00:001:00000 10:100:86399",
                                               "10:100:86399 00:001:00000"),
                                      "data end 2000-01-01T00:00:00.000Z before data start"),
    "a 100 kB line": (_replace("*a comment of SOLUTION/EPOCHS", "*" + "x" * 100_000),
                      "line longer than 1024 bytes"),
    "binary garbage": (b"%=SNX\n" + bytes(range(128, 256)), ":2: not text"),
    "a NUL byte": (_replace("*a comment of SOLUTION/EPOCHS", "*a \x00"),
                   ":3: a NUL byte at column 4"),
    "a terminal escape": (_replace("*a comment of SOLUTION/EPOCHS", "*\x1b]0;owned\x07"),
                          "control character '\\x1b' at column 2"),
    "empty": ("", ":1: empty: not a SINEX file"),
}


@pytest.mark.parametrize("case", sorted(HOSTILE))
def test_hostile_sinex_is_refused_in_one_line(tmp_path, case):
    text, expected = HOSTILE[case]
    path = tmp_path / "hostile.snx"

    def both(p):
        sinex.read_solutions(p)
        sinex.read_eccentricities(p)

    msg = bounded(error_of(both, RecordError, path, text), path)
    assert expected in msg, msg


@settings(max_examples=60, deadline=None, suppress_health_check=[
    HealthCheck.too_slow, HealthCheck.function_scoped_fixture])
@given(text=mutated(GOOD, ["+", "-", "%ENDSNX", "STAX", "VELX", "m/y", "nan", "\x00", "\n",
                           " ", "00:000:00000", "E+99"]))
def test_mutated_sinex_reads_or_is_refused_in_one_line(tmp_path, text):
    path = tmp_path / "fuzz.snx"
    path.write_text(text)
    for read in (sinex.read_solutions, sinex.read_eccentricities):
        try:
            read(path)
        except RecordError as exc:
            bounded(str(exc), path)

"""The CPF reader (formats.ilrs.cpf), the tabulated orbit that interpolates it
(core.motion.tabulated) and the reference orbits of `import crd --reference`
(formats.reference_orbit): the real SGF prediction against values read off it by hand, an
exact Kepler orbit, small v1/v2 files, and hostile files refused in one line."""

from __future__ import annotations

import calendar

import numpy as np
import pytest
from crd_samples import bounded
from fuzz_text import error_of, mutated
from hypothesis import HealthCheck, given, settings
from realdata import CPF, lageos, needs_lageos

from ssa_fusion.core.base import types
from ssa_fusion.core.earth.frames import itrs_to_gcrs
from ssa_fusion.core.motion.kepler import kepler_state
from ssa_fusion.core.motion.tabulated import TabulatedOrbit
from ssa_fusion.formats.ccsds.common import OemFrame, write_ndm
from ssa_fusion.formats.ccsds.oem import oem_document
from ssa_fusion.formats.ilrs.cpf import read_cpf
from ssa_fusion.formats.records import RecordError
from ssa_fusion.formats.reference_orbit import read_reference

DAY = float(calendar.timegm((2020, 3, 5, 0, 0, 0)))  # MJD 58913
R0 = np.array([7049.498186, 5346.456274, 8307.028039])
X0 = np.concatenate([R0, np.sqrt(398600.4418 / np.linalg.norm(R0)) * np.cross(
    R0, [0.3, -0.5, 1.0]) / np.linalg.norm(np.cross(R0, [0.3, -0.5, 1.0]))])
"""A circular orbit at 12,137 km (LAGEOS's height), km, km/s."""


def kepler_table(n: int = 12, step: float = 300.0) -> tuple[np.ndarray, np.ndarray]:
    t = np.arange(n) * step
    x, ok = kepler_state(np.repeat(X0[None], n, 0), t)
    assert ok.all()
    return DAY + t, x


def cpf_text(version: int = 1, velocities: bool = False, n: int = 12) -> str:
    t, x = kepler_table(n)
    h1 = f"H1 CPF  {version}  TST 2020  3  5  1  1234{'  1' if version == 2 else ''} lageos1"
    h2 = ("H2  7603901 1155     8820 2020  3  5  0  0  0 2020  3  5  0 55  0   300 1 1  0 0 0"
          + ("  1" if version == 2 else ""))
    rows = []
    for ti, xi in zip(t, x, strict=True):
        m = xi * 1000.0
        rows.append(f"10 0 58913 {ti - DAY:12.5f}  0 {m[0]:14.3f} {m[1]:14.3f} {m[2]:14.3f}")
        if velocities:
            rows.append(f"20 0 {m[3]:13.6f} {m[4]:13.6f} {m[5]:13.6f}")
    return "\n".join([h1, h2, "H9", *rows, "99", ""])


@needs_lageos
def test_the_real_cpf_as_checked_by_hand():
    o = read_cpf(lageos(CPF))
    # H1 CPF 1 SGF 2016 2 13 2 5441 lageos2 / H2 9207002 5986 22195 2016 2 13 0 0 0 ...
    assert (o.target, o.ilrs_id, o.norad, o.source, o.step_s) == (
        "lageos2", 9207002, 22195, "SGF", 300.0)
    day = calendar.timegm((2016, 2, 13, 0, 0, 0))
    assert (o.start, o.end) == (day, day + 23 * 3600 + 54 * 60)
    assert len(o.t) == 288 and o.t[0] == day and o.t[-1] == day + 86100.0
    # 10 0 57431 0.00000 0 7049498.186 5346456.274 8307028.039
    np.testing.assert_allclose(o.position_km[0], [7049.498186, 5346.456274, 8307.028039],
                               rtol=0, atol=1e-9)
    np.testing.assert_allclose(o.position_km[-1], [-10108.280313, -3150.523401, -6140.646075],
                               rtol=0, atol=1e-9)
    assert o.velocity_km_s is None and not o.com_applied
    r = np.linalg.norm(o.position_km, axis=1)
    assert r.min() > 11900 and r.max() < 12400  # LAGEOS-2: a = 12,163 km, e = 0.014


def test_lagrange_reproduces_an_exact_orbit():
    t, x = kepler_table(40, 300.0)
    table = TabulatedOrbit(t, x[:, :3])
    q = t[0] + np.linspace(0.0, t[-1] - t[0], 97)
    exact, _ = kepler_state(np.repeat(X0[None], len(q), 0), q - t[0])
    got = table.states(q)
    assert np.abs(got[:, :3] - exact[:, :3]).max() < 1e-6  # 1 mm
    assert np.abs(got[:, 3:] - exact[:, 3:]).max() < 3e-8  # 30 um/s (at the table's ends)
    with_v = TabulatedOrbit(t, x[:, :3], x[:, 3:])
    assert np.abs(with_v.states(q)[:, 3:] - exact[:, 3:]).max() < 2e-8
    with pytest.raises(ValueError, match="outside the table's span"):
        table.states([t[-1] + 1.0])
    with pytest.raises(ValueError, match="degree 9 interpolation needs 10"):
        TabulatedOrbit(t[:5], x[:5, :3])


def test_v1_and_v2_and_the_reference_orbit_in_the_gcrf(tmp_path):
    t, x = kepler_table()
    p1, p2 = tmp_path / "a.cpf", tmp_path / "b.cpf"
    p1.write_text(cpf_text(1))
    p2.write_text(cpf_text(2, velocities=True))
    a, b = read_cpf(p1), read_cpf(p2)
    np.testing.assert_array_equal(a.t, t)
    np.testing.assert_allclose(a.position_km, x[:, :3], atol=1e-6)
    assert a.velocity_km_s is None
    np.testing.assert_allclose(b.velocity_km_s, x[:, 3:], atol=1e-9)
    ref = read_reference(p2)  # ITRF table -> GCRF states at its epochs
    assert ref.source == "cpf" and "7603901" in ref.names and "8820" in ref.names
    np.testing.assert_allclose(ref.x, itrs_to_gcrs(np.column_stack([b.position_km,
                                                                    b.velocity_km_s]), t),
                               atol=1e-9)
    # an OEM in EME2000 read back as GCRF: the frame bias undone
    estimates = {"8820": [types.StateEstimate(t=ti, x=xi, object_id="8820")
                          for ti, xi in zip(t, x, strict=True)]}
    oem = tmp_path / "ref.oem"
    write_ndm(oem_document(estimates, OemFrame.EME2000), oem, "kvn")
    back = read_reference(oem)
    assert back.source == "oem" and back.names == ("8820",)
    np.testing.assert_allclose(back.x, x, atol=1e-9)
    np.testing.assert_array_equal(back.t, t)


def _replace(old, new, text=None):
    text = cpf_text() if text is None else text
    assert old in text
    return text.replace(old, new, 1)


HOSTILE = {
    "no 99": (_replace("99\n", ""), "the file ends without record 99"),
    "a truncated position": (_replace(" 0 58913      0.00000  0 ", " 0 58913      0.00000 "),
                             ":4: record 10: 6 field(s), want 7 (truncated?)"),
    "NaN": (_replace("    0.00000  0    7049498.186", "    0.00000  0    nan"),
            "record 10: x: nan is not a decimal number"),
    "inside the Earth": (_replace("7049498.186    5346456.274    8307028.039",
                                  "3049498.186    2346456.274    4307028.039"),
                         "below the Earth's surface"),
    "epochs not increasing": (_replace("    300.00000", "      0.00000"),
                              ":5: record 10: epoch 2020-03-05T00:00:00.000Z not after"),
    "an epoch outside the header": (_replace("    300.00000", "  86000.00000"),
                                    "outside the header's"),
    "light-time vectors": (_replace("10 0 58913      0.00000", "10 1 58913      0.00000"),
                           "direction flag 1 (light-time-corrected vectors)"),
    "an inertial frame": (_replace("300 1 1  0 0 0", "300 1 1  1 0 0"),
                          ":2: H2: reference frame 1"),
    "data before H9": (_replace("H9\n", ""), ":3: record 10: before H9"),
    "headers out of order": (_replace("H9\n", "H9\nH3 1 2 3\n"),
                             ":4: H3: after H9: the headers come in the order"),
    "H2 first": (cpf_text().split("\n", 1)[1], ":1: H2: not a CPF file"),
    "a CRD file": ("h1 CRD  1 2016  2 13 14 1 2 3\n", "format CRD: not a CPF file"),
    "velocities for some": (_replace("99\n", "20 0 1.0 2.0 3.0\n99\n"),
                            "velocities for 1 of the 12 positions"),
    "month 13": (_replace("2020  3  5  0  0  0", "2020 13  5  0  0  0"),
                 ":2: H2: start month: 13 outside [1, 12]"),
    "after 99": (cpf_text() + "10 0 58913 1.0 0 1 2 3\n", "after record 99"),
    "a 100 kB line": ("H1 " + "x" * 100_000 + "\n", ":1: line longer than 1024 bytes"),
    "binary garbage": (bytes(range(128, 256)) * 3, ":1: not text"),
    "a NUL byte": (_replace("lageos1", "lage\x00os1"), ":1: a NUL byte at column"),
    "a terminal escape": (_replace("lageos1", "\x1b[1;1H\x1b[2Jlageos1"),
                          ":1: control character '\\x1b'"),
    "empty": ("", ":1: empty: not a CPF file"),
}


@pytest.mark.parametrize("case", sorted(HOSTILE))
def test_hostile_cpf_is_refused_in_one_line(tmp_path, case):
    text, expected = HOSTILE[case]
    path = tmp_path / "hostile.cpf"
    msg = bounded(error_of(read_cpf, RecordError, path, text), path)
    assert expected in msg, msg


@settings(max_examples=60, deadline=None, suppress_health_check=[
    HealthCheck.too_slow, HealthCheck.function_scoped_fixture])
@given(text=mutated(cpf_text(), ["H1", "H2", "H9", "10", "20", "99", "nan", "\x00", "\n", " ",
                                 "-1", "1e300"]))
def test_mutated_cpf_reads_or_is_refused_in_one_line(tmp_path, text):
    path = tmp_path / "fuzz.cpf"
    path.write_text(text)
    try:
        read_cpf(path)
    except RecordError as exc:
        bounded(str(exc), path)

"""The geopotential (core.motion.geopotential) against independent references.

* a second formulation: the potential and its gradient by direct summation over the
  associated Legendre functions of scipy (spherical coordinates, numpy), at a few points;
* the degree-2 zonal field against the two-body + J2 model of `propagation` (J2 = -sqrt(5) C20);
* the gravity gradient against central differences of the acceleration;
* the ICGEM reader on the shipped EGM96 file (values read by hand) and on hostile files.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.special import gammaln, lpmv

from ssa_fusion.core.motion import geopotential as gp
from ssa_fusion.core.motion.propagation import j2_gravity
from ssa_fusion.formats.icgem import IcgemError, egm96, read_icgem

POINTS = np.array([[4000.0, 3000.0, 5200.0], [-6900.0, 1200.0, -300.0],
                   [1000.0, -11800.0, 2500.0], [300.0, 200.0, 7000.0]])


def _direct(field: gp.GravityField, r: np.ndarray, degree: int) -> tuple[float, np.ndarray]:
    """Potential and acceleration (ITRF, km/s^2) by direct Legendre summation."""
    x, y, z = r
    rn = math.sqrt(x * x + y * y + z * z)
    phi, lam = math.asin(z / rn), math.atan2(y, x)
    s, cphi = math.sin(phi), math.cos(phi)
    u = du_dr = du_dphi = du_dlam = 0.0
    for n in range(degree + 1):
        q = (field.radius / rn) ** n
        for m in range(n + 1):
            norm = math.exp(0.5 * (math.log(2.0 - (m == 0)) + math.log(2 * n + 1)
                                   + gammaln(n - m + 1) - gammaln(n + m + 1)))
            p = (-1) ** m * lpmv(m, n, s)  # no Condon-Shortley phase
            p1 = (-1) ** m * lpmv(m, n - 1, s) if n > m else 0.0
            dp = -(n * s * p - (n + m) * p1) / cphi  # d P_nm(sin phi) / d phi
            cs = field.c[n, m] * math.cos(m * lam) + field.s[n, m] * math.sin(m * lam)
            sc = -field.c[n, m] * math.sin(m * lam) + field.s[n, m] * math.cos(m * lam)
            u += q * norm * p * cs
            du_dr += -(n + 1) * q * norm * p * cs
            du_dphi += q * norm * dp * cs
            du_dlam += q * norm * p * m * sc
    k = field.gm / rn
    ar, aphi, alam = k * du_dr / rn, k * du_dphi / rn, k * du_dlam / (rn * cphi)
    er = np.array([cphi * math.cos(lam), cphi * math.sin(lam), s])
    ephi = np.array([-s * math.cos(lam), -s * math.sin(lam), cphi])
    elam = np.array([-math.sin(lam), math.cos(lam), 0.0])
    return k * u, ar * er + aphi * ephi + alam * elam


def _kernel(field: gp.GravityField, r: np.ndarray, degree: int, order: int | None = None,
            gradient: bool = True) -> tuple[np.ndarray, np.ndarray]:
    mo = degree if order is None else order
    t = gp.kernel_tables(field, degree, mo)
    v, w, out = np.zeros((degree + 3, mo + 3)), np.zeros((degree + 3, mo + 3)), np.zeros(19)
    gp.geopotential_acceleration(float(r[0]), float(r[1]), float(r[2]), field.radius, degree,
                                 mo, t.rec, t.weights, gradient, v, w, out)
    g = np.array([[out[3], out[4], out[5]], [out[4], out[6], out[7]],
                  [out[5], out[7], out[8]]])
    return out[:3].copy(), g


@pytest.mark.parametrize("degree", [4, 20, 36, 70])
def test_acceleration_equals_direct_legendre_summation(degree: int) -> None:
    field = egm96()
    for r in POINTS:
        u_ref, a_ref = _direct(field, r, degree)
        a, _ = _kernel(field, r, degree)
        assert np.linalg.norm(a - a_ref) < 1e-12 * np.linalg.norm(a_ref)
        # the non-central part too (a thousandth of the total): relative 1e-9 of itself
        central = -field.gm * r / np.linalg.norm(r) ** 3
        assert np.linalg.norm(a - a_ref) < 1e-9 * np.linalg.norm(a_ref - central)
        assert gp.potential(field, r, degree) == pytest.approx(u_ref, rel=1e-13)


def test_degree_two_is_the_j2_model() -> None:
    field = egm96()
    j2 = -math.sqrt(5.0) * field.c[2, 0]
    for r in POINTS:
        a, g = _kernel(field, r, 2, 0)
        ref = j2_gravity(*r, field.gm, j2, field.radius, 0.0, 0.0, 1.0)
        assert np.allclose(a, ref[:3], rtol=0.0, atol=1e-15 * np.linalg.norm(a))
        gref = np.array([[ref[3], ref[4], ref[5]], [ref[4], ref[6], ref[7]],
                         [ref[5], ref[7], ref[8]]])
        assert np.allclose(g, gref, rtol=0.0, atol=1e-13 * np.abs(gref).max())


def test_gradient_equals_central_differences_and_is_traceless() -> None:
    field = egm96()
    h = 1e-2
    for degree, order in ((20, 20), (30, 12), (70, 70)):
        for r in POINTS:
            _, g = _kernel(field, r, degree, order)
            fd = np.array([(_kernel(field, r + h * e, degree, order, False)[0]
                            - _kernel(field, r - h * e, degree, order, False)[0]) / (2 * h)
                           for e in np.eye(3)]).T
            assert np.abs(g - fd).max() < 1e-7 * np.abs(g).max()
            assert abs(np.trace(g)) < 1e-12 * np.abs(g).max()  # Laplace: the field is harmonic


def test_truncation_is_checked() -> None:
    with pytest.raises(ValueError, match="degree 121"):
        gp.kernel_tables(egm96(), 121)
    with pytest.raises(ValueError, match="order 5"):
        gp.kernel_tables(egm96(), 4, 5)


def test_shipped_egm96_values() -> None:
    f = egm96()
    assert (f.name, f.max_degree, f.tide_system) == ("EGM96", 120, "tide_free")
    assert f.gm == pytest.approx(398600.4415, rel=1e-15)
    assert f.radius == pytest.approx(6378.1363, rel=1e-15)
    assert f.c[2, 0] == -0.484165371736e-03  # the file's line "gfc 2 0"
    assert (f.c[2, 2], f.s[2, 2]) == (0.243914352398e-05, -0.140016683654e-05)
    assert (f.c[120, 120], f.s[120, 120]) == (-0.456798788660e-09, -0.159135018852e-08)


HEAD = ("product_type gravity_field\nmodelname T\nearth_gravity_constant 0.3986004415E+15\n"
        "radius 0.6378136300E+07\nmax_degree 2\nnorm fully_normalized\nend_of_head ====\n")


@pytest.mark.parametrize(("text", "match"), [
    ("no header\n", "no end_of_head"),
    (HEAD.replace("radius 0.6378136300E+07\n", ""), "radius missing"),
    (HEAD.replace("norm fully_normalized", "norm unnormalized"), "norm"),
    (HEAD + "gfc 2 0 nan 0.0\n", ":8: C: not finite"),
    (HEAD + "gfc 2 0 1x 0.0\n", ":8: C: not a number"),
    (HEAD + "gfc 3 0 1.0 0.0\n", ":8: L, M: 3, 0"),
    (HEAD + "gfc 2 0 1.0 0.0\ngfc 2 0 1.0 0.0\n", ":9: L, M: coefficient 2, 0 given twice"),
    (HEAD + "gfct 2 0 1.0 0.0 0 0 20000101\n", ":8: key"),
])
def test_hostile_icgem_files_are_refused_in_one_line(tmp_path: object, text: str,
                                                     match: str) -> None:
    from pathlib import Path

    p = Path(str(tmp_path)) / "f.gfc"
    p.write_text(text)
    with pytest.raises(IcgemError, match=match) as err:
        read_icgem(p)
    assert "\n" not in str(err.value)


def test_icgem_reader_fortran_exponents_and_truncation(tmp_path: object) -> None:
    from pathlib import Path

    p = Path(str(tmp_path)) / "f.gfc"
    p.write_text(HEAD + "gfc 0 0 1.0D+00 0.0\ngfc 2 1 -0.25D-09 0.5D-09\n")
    f = read_icgem(p)
    assert (f.c[0, 0], f.c[2, 1], f.s[2, 1]) == (1.0, -0.25e-9, 0.5e-9)
    assert read_icgem(p, max_degree=1).max_degree == 1

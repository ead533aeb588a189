"""Screening a catalog for close approaches (`core.conjunction.screening`).

Against references computed independently: the closed form of two circular orbits crossing
(TCA and miss), a brute-force screening of every pair on a fine grid with exact states
(`evaluation.screening_reference`) on catalogs with planted close approaches, and the
apogee/perigee filter at its edge (a pair just inside the screening distance is found, one
just outside is not).
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from planted_conjunctions import T0, planted

from ssa_fusion.core.base.constants import MU_EARTH, R_EARTH
from ssa_fusion.core.conjunction import apsides
from ssa_fusion.core.conjunction.ephemeris import ElementSetEphemeris, StateEphemeris
from ssa_fusion.core.conjunction.screening import ScreeningConfig, screen
from ssa_fusion.core.motion.dynamics import elements_to_state
from ssa_fusion.evaluation.screening_reference import brute_force_approaches, match
from ssa_fusion.formats.element_sets import read_catalog
from ssa_fusion.sim import survey

REAL = "config/catalogs/celestrak_active_2025-07.tle"


def _circular(radius: float, inc: float, u: float) -> np.ndarray:
    """State on a circular orbit of node along x, inclination ``inc``, at latitude arg u."""
    e1, e2 = np.array([1.0, 0.0, 0.0]), np.array([0.0, math.cos(inc), math.sin(inc)])
    v = math.sqrt(MU_EARTH / radius)
    return np.r_[radius * (math.cos(u) * e1 + math.sin(u) * e2),
                 v * (-math.sin(u) * e1 + math.cos(u) * e2)]


@pytest.mark.parametrize(("theta_deg", "lag_s"), [(70.0, 0.8), (150.0, -0.3), (8.0, 2.0)])
def test_tca_and_miss_of_two_crossing_circular_orbits_are_the_closed_form(theta_deg, lag_s):
    # Two circular orbits of one radius, planes theta apart, at the common node t_c and
    # t_c + lag: |dr|^2 = R^2 (2 - (1 + cos th) cos d - (1 - cos th) cos s) with d = n lag and
    # s the sum of the arguments of latitude, least at s = 0: TCA = t_c + lag / 2 exactly
    # and miss = R sqrt((1 + cos th)(1 - cos d)); and again at the other node, half a
    # period earlier.
    radius, tc = 7000.0, T0 + 3000.0
    n = math.sqrt(MU_EARTH / radius**3)
    th = math.radians(theta_deg)
    xa = _circular(radius, 0.3, n * (T0 - tc))
    xb = _circular(radius, 0.3 + th, n * (T0 - tc - lag_s))
    eph = StateEphemeris(["a", "b"], [xa, xb], [T0, T0], model="two_body")
    found = screen(eph, T0, T0 + 4000.0, ScreeningConfig(distance_km=20.0))
    miss = radius * math.sqrt((1 + math.cos(th)) * (1 - math.cos(n * lag_s)))
    half = math.pi / n
    assert found.tca.tolist() == pytest.approx([tc + lag_s / 2 - half, tc + lag_s / 2],
                                               abs=1e-4)
    assert found.miss_km.tolist() == pytest.approx([miss, miss], abs=1e-6)
    rtn = found.relative_rtn()
    # same radius at TCA: the chord's radial part only, -miss^2 / 2R
    assert rtn[:, 0] == pytest.approx(-miss**2 / (2 * radius), abs=1e-9)
    assert np.linalg.norm(rtn[:, 3:], axis=1) == pytest.approx(
        2 * math.sqrt(MU_EARTH / radius) * math.sin(th / 2), rel=1e-3)


@pytest.mark.parametrize("gap_offset_km", [-0.001, 0.001])
def test_apogee_touching_perigee_at_the_screening_distance_edge(gap_offset_km):
    # The inner orbit's apogee and the outer's perigee on one line at the same epoch: the
    # pair's least distance is the gap between them, D - 1 m (found) or D + 1 m (not).
    d = 10.0
    ra_inner = R_EARTH + 700.0
    rp_outer = ra_inner + d + gap_offset_km
    a1, e1 = (R_EARTH + 500.0 + ra_inner) / 2, 0.0
    e1 = (ra_inner - (R_EARTH + 500.0)) / (ra_inner + R_EARTH + 500.0)
    a2, e2 = rp_outer / (1 - 0.02), 0.02
    tc = T0 + 2000.0
    # at tc: inner at apogee (nu = pi), outer at perigee (nu = 0), both on the +x axis
    inner = elements_to_state(a1, e1, math.radians(40.0), 0.0, math.pi, math.pi)
    outer = elements_to_state(a2, e2, math.radians(100.0), 0.0, 0.0, 0.0)
    back = StateEphemeris(["in", "out"], [inner, outer], [tc, tc], model="two_body")
    x0 = back.exact([0, 1], [T0, T0])
    rp, ra, _ = apsides.osculating_apsides(x0)
    assert ra[0] == pytest.approx(ra_inner, abs=1e-6)
    assert rp[1] == pytest.approx(rp_outer, abs=1e-6)
    eph = StateEphemeris(["in", "out"], x0, [T0, T0], model="two_body")
    found = screen(eph, T0, T0 + 3600.0, ScreeningConfig(distance_km=d))
    if gap_offset_km < 0:
        assert len(found) == 1
        assert found.miss_km[0] == pytest.approx(d + gap_offset_km, abs=1e-6)
        assert found.tca[0] == pytest.approx(tc, abs=1e-3)
    else:
        assert len(found) == 0


def test_radial_bands_hold_the_osculating_apsides():
    x = np.stack([elements_to_state(7000.0, 0.1, 0.5, 1.0, 2.0, nu) for nu in (0.0, 2.0, 4.0)])
    bands = apsides.radial_bands(x[None], pad_km=1.0)
    assert bands.lo[0] == pytest.approx(7000.0 * 0.9 - 1.0)
    assert bands.hi[0] == pytest.approx(7000.0 * 1.1 + 1.0)
    assert bands.vmax[0] == pytest.approx(1.01 * math.sqrt(MU_EARTH * 1.1 / 6300.0))
    meet = apsides.bands_meet((np.array([7000.0]), np.array([7100.0])),
                              (np.array([7110.0, 7110.001]), np.array([7200.0, 7200.0])), 10.0)
    assert meet.tolist() == [True, False]


def test_recall_is_complete_against_brute_force_on_a_planted_catalog():
    span, d = 86400.0, 10.0
    eph = planted(seed=3, n_background=120, n_pairs=40, span_s=span)
    ref = brute_force_approaches(eph, T0, T0 + span, d, step_s=10.0)
    found = screen(eph, T0, T0 + span, ScreeningConfig(distance_km=d))
    m = match(found, ref)
    assert len(ref) >= 20  # the planted ones within 10 km, at least
    assert m.recall == 1.0, (ref.i[~m.found], ref.j[~m.found], ref.tca[~m.found] - T0)
    assert m.extra == 0
    assert np.abs(m.dt_s).max() < 1e-3
    assert np.abs(m.dmiss_km).max() < 1e-5


def test_recall_is_complete_on_sgp4_element_sets_in_crowded_shells():
    bases = [e for e in read_catalog(REAL) if e.name.startswith(("STARLINK-3", "ONEWEB"))][:8]
    entries = []
    for k, base in enumerate(bases):
        entries += survey.synthetic_catalog(base, 15, seed=k, first_id=70000 + 15 * k)
    eph = ElementSetEphemeris(entries)
    t0 = survey.catalog_start(entries)
    span, d = 6 * 3600.0, 20.0
    ref = brute_force_approaches(eph, t0, t0 + span, d, step_s=5.0)
    found = screen(eph, t0, t0 + span, ScreeningConfig(distance_km=d))
    m = match(found, ref)
    assert len(ref) >= 10
    assert m.recall == 1.0, (ref.i[~m.found], ref.j[~m.found], ref.miss_km[~m.found])
    assert m.extra == 0
    assert np.abs(m.dmiss_km).max() < 1e-4


def test_primaries_chunks_and_threads_give_the_same_approaches():
    span, d = 43200.0, 10.0
    eph = planted(seed=5, n_background=60, n_pairs=25, span_s=span)
    full = screen(eph, T0, T0 + span, ScreeningConfig(distance_km=d))
    assert len(full) >= 10
    other = screen(eph, T0, T0 + span, ScreeningConfig(distance_km=d, chunk_nodes=5,
                                                         workers=2))
    assert other.tca.tolist() == pytest.approx(full.tca.tolist(), abs=1e-6)
    assert other.primary.tolist() == full.primary.tolist()
    some = np.unique(full.secondary)[::2]
    part = screen(eph, T0, T0 + span, ScreeningConfig(distance_km=d), primaries=some)
    want = np.isin(full.primary, some) | np.isin(full.secondary, some)
    assert sorted(part.tca.tolist()) == pytest.approx(sorted(full.tca[want].tolist()), abs=1e-6)
    assert np.isin(part.primary, some).all()


def test_covariances_are_carried_to_tca_and_decayed_objects_are_skipped():
    radius, tc = 7000.0, T0 + 3000.0
    n = math.sqrt(MU_EARTH / radius**3)
    xa = _circular(radius, 0.3, n * (T0 - tc))
    xb = _circular(radius, 1.3, n * (T0 - tc))
    bad = np.full(6, np.nan)
    p0 = np.stack([np.diag([1e-2, 1e-2, 1e-2, 1e-8, 1e-8, 1e-8])] * 3)
    eph = StateEphemeris(["a", "b", "nan"], [xa, xb, bad], [T0] * 3, model="two_body",
                         covariance=p0)
    found = screen(eph, T0 + 1000.0, T0 + 4000.0)
    assert len(found) == 1 and found.p1 is not None and found.p2 is not None
    assert found.tca[0] == pytest.approx(tc, abs=1e-4)
    # position variance along track grows with the velocity variance over 3000 s
    assert np.trace(found.p1[0, :3, :3]) > 3e-2
    np.testing.assert_allclose(found.p1[0], found.p1[0].T, atol=1e-12)
    # a head-on miss of ~0 with sigmas ~0.3 km and a 10 m circle: Pc ~ r^2 / (2 s1 s2)
    pc = 10 ** found.log10_pc(0.01)[0]
    s = np.sqrt(np.linalg.eigvalsh(found.p1[0, :3, :3] + found.p2[0, :3, :3]))
    assert 1e-4 / (2 * s[-1] * s[-1]) < pc < 1e-4 / (2 * s[0] * s[1])


def test_interpolation_error_bounds_hold_on_real_element_sets():
    from ssa_fusion.core.conjunction import hermite
    from ssa_fusion.core.earth.frames import cip_gcrs

    entries = read_catalog(REAL)  # LEO at 280 km to HEO at e = 0.87 (SDP4)
    eph = ElementSetEphemeris(entries)
    t0 = survey.catalog_start(entries)
    big_h = 300.0
    tn = t0 + big_h * np.arange(25)
    table = hermite.node_table(eph.sample(tn), t0, big_h, cip_gcrs(t0))
    eps, _ = hermite.interpolation_pad(table)
    frac = np.array([0.1, 0.25, 0.4, 0.6, 0.75, 0.9])
    tm = (t0 + big_h * (np.arange(24)[:, None] + frac)).ravel()
    truth = eph.sample(tm)
    out = np.empty(6)
    worst = np.zeros(len(entries))
    for i in range(len(entries)):
        for k, t in enumerate(tm):
            hermite.state_at(table.nodes, t0, big_h, i, float(t), out)
            worst[i] = max(worst[i], float(np.linalg.norm(out[:3] - truth[i, k, :3])))
    assert worst.max() > 0.1  # the HEO under SDP4: the bound has something to hold
    assert (worst <= eps).all(), [(entries[i].name, worst[i], eps[i])
                                  for i in np.flatnonzero(worst > eps)]

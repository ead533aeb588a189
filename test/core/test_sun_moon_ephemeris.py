"""The Sun and the Moon (core.earth.ephemeris, DE421 compiled) and the rotation grid.

* against skyfield with the DE430 excerpt its own tests ship (2015-02-27..03-07): another
  JPL ephemeris and another reader, < 1 km for both bodies;
* against jplephem's own evaluation of DE421 (the same series, another code, TDB of each
  epoch): < 5 mm (the Moon) over five days;
* `rotation_grid.gcrs_to_itrs_at` against `frames.gcrs_to_itrs_matrix`.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from ssa_fusion.core.earth import frames
from ssa_fusion.core.earth.ephemeris import _ephemeris, sun_moon_positions, sun_moon_span
from ssa_fusion.core.earth.rotation_grid import gcrs_to_itrs_at, rotation_grid
from ssa_fusion.core.earth.timescales import jd_tt, parse_utc

skyfield_api = pytest.importorskip("skyfield.api")


def _de430_excerpt() -> Path:
    import skyfield

    path = Path(skyfield.__file__).parent / "tests" / "data" / "de430-2015-03-02.bsp"
    if not path.exists():
        pytest.skip("skyfield's DE430 excerpt is not installed")
    return path


def test_sun_and_moon_agree_with_skyfield_de430() -> None:
    ts = skyfield_api.load.timescale(builtin=True)
    eph = skyfield_api.load_file(str(_de430_excerpt()))
    t = parse_utc("2015-02-28T00:00:00") + np.arange(0.0, 6 * 86400.0, 4321.0)
    sun, moon = sun_moon_positions(t)
    tt1, tt2 = jd_tt(t)
    st = ts.tt_jd(tt1, tt2)
    earth = eph["earth"]
    ref_sun = (eph["sun"].at(st) - earth.at(st)).position.km.T  # geometric, ICRF
    ref_moon = (eph["moon"].at(st) - earth.at(st)).position.km.T
    assert np.linalg.norm(sun - ref_sun, axis=1).max() < 1.0
    assert np.linalg.norm(moon - ref_moon, axis=1).max() < 1.0
    # and not by accident: the Sun an hour off is ~1e5 km away
    assert np.linalg.norm(sun[1:] - ref_sun[:-1], axis=1).min() > 1e4


def test_compiled_series_equal_jplephem() -> None:
    eph = _ephemeris()
    t0 = parse_utc("2016-02-13T00:00:00")
    t = t0 + np.linspace(-2 * 86400.0, 3 * 86400.0, 37)
    sun, moon = sun_moon_positions(t)
    span = sun_moon_span(t0, -3 * 86400.0, 4 * 86400.0)
    tt1, tt2 = jd_tt(t)
    import erfa

    d2 = tt2 + erfa.dtdb(tt1, tt2, 0.0, 0.0, 0.0, 0.0) / 86400.0  # TDB of each epoch
    ref_moon = eph.position("moon", tt1, d2).T
    ref_sun = (eph.position("sun", tt1, d2) - eph.position("earthmoon", tt1, d2)).T \
        + span.earth_share * ref_moon
    assert np.abs(moon - ref_moon).max() < 5e-6  # km (the linear TDB - TT: < 5 mm)
    assert np.abs(sun - ref_sun).max() < 5e-4  # 0.5 m: the Sun moves 30 km/s about the Earth
    assert span.gm_sun == pytest.approx(1.32712440e11, rel=1e-8)
    assert span.gm_moon == pytest.approx(4902.80, rel=1e-5)


def test_rotation_grid_equals_frames() -> None:
    t0 = parse_utc("2016-02-13T05:17:00")
    grid = rotation_grid(t0, -7200.0, 2 * 86400.0).packed()
    dt = np.array([-3600.0, 0.0, 1234.5, 86400.0, 1.5 * 86400.0 + 17.0])
    ref = frames.gcrs_to_itrs_matrix(t0 + dt)
    out = np.empty(9)
    for k, d in enumerate(dt):
        gcrs_to_itrs_at(grid, float(d), out)
        assert np.abs(out.reshape(3, 3) - ref[k]).max() < 1e-12

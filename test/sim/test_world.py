"""The high-fidelity world (`sim.world`, `sim.atmosphere`, `sim.space_weather`).

* the truth is the force model's own propagator: `world_truth` against
  `core.motion.high_fidelity.propagate` of the same spec and density table, from the same
  state, at epochs off the table's grid (the same code path, interpolated: bounded);
* the kernel's density factor scales the drag and nothing else (`derivatives` with a
  constant factor against the exponential atmosphere's drag, times that factor);
* NRLMSISE-00 through pymsis: denser air in a geomagnetic storm, and the textbook size at
  400 km (Vallado's table: 2.8e-12 .. 1.2e-11 kg/m^3 from low to high activity);
* the space weather's inputs: F10.7 of the day before, ap now and hours before;
* a manoeuvre: the same orbit before it, the velocity changed by it along track after;
* the degree-9 interpolation is exact on polynomials of degree 9.
"""

from __future__ import annotations

import numpy as np

from ssa_fusion.core.earth.frames import rtn_axes
from ssa_fusion.core.earth.timescales import parse_utc
from ssa_fusion.core.motion import high_fidelity as hf
from ssa_fusion.core.motion.force_spec import DragSpec, ForceSpec
from ssa_fusion.sim import atmosphere, sky, world
from ssa_fusion.sim.space_weather import SpaceWeather, synthetic_weather

T0 = parse_utc("2025-01-01T00:00:00")
ISS = sky.SKY_SCENARIOS["iss_radar_columbus"].x0
SMALL = world.World(degree=8, storm_every_days=2.0)  # a storm likely over the span
SPAN_S = 6 * 3600.0


def test_truth_is_the_force_models_own_propagation() -> None:
    truth = world.world_truth(ISS, T0, SPAN_S, SMALL)
    assert truth.converged_km < world.CONVERGED_KM
    f = truth.density.factor
    assert f.min() > 0.1 and f.max() / f.min() > 1.2  # the air varies along the orbit
    t = T0 + np.linspace(-600.0, SPAN_S + 600.0, 37) + 17.3  # off the 60 s grid
    ctx = hf.setup(world.force_spec(SMALL), T0, -1800.0, SPAN_S + 1800.0,
                   density=truth.density)
    direct = hf.propagate(ctx, np.array(ISS), T0, t, stm=False).x
    got = truth.states(t)
    assert np.abs(got[:, :3] - direct[:, :3]).max() < 1e-6  # km: below a millimetre
    assert np.abs(got[:, 3:] - direct[:, 3:]).max() < 1e-8  # km/s
    # and the density matters: the same world in the exponential air is elsewhere
    plain = hf.propagate(world.force_spec(SMALL), np.array(ISS), T0, t[-1:], stm=False).x
    assert np.linalg.norm(plain[0, :3] - got[-1, :3]) > 0.01


def test_density_factor_scales_the_drag_alone() -> None:
    spec = ForceSpec(degree=0, sun=False, moon=False, drag=DragSpec(bc=100.0))
    x = np.array(ISS)
    a1 = hf.derivatives(hf.setup(spec, T0), x, T0 + 50.0)[0][3:]
    table = hf.DensityTable(T0 - 600.0, 60.0, np.full(30, 2.5))
    a2 = hf.derivatives(hf.setup(spec, T0, density=table), x, T0 + 50.0)[0][3:]
    gravity = hf.derivatives(hf.setup(ForceSpec(degree=0, sun=False, moon=False), T0), x,
                             T0 + 50.0)[0][3:]
    assert np.allclose(a2 - gravity, 2.5 * (a1 - gravity), rtol=1e-6, atol=0.0)
    assert np.linalg.norm(a1 - gravity) > 1e-10  # drag was there to scale


def _weather(ap: float) -> SpaceWeather:
    days = 8
    return SpaceWeather(T0 - 3 * 86400.0, np.full(days, 150.0), np.full(days, 150.0),
                        np.full(8 * days, ap))


def test_msis_density_textbook_size_and_storm() -> None:
    r = np.array([[6378.137 + 400.0, 0.0, 0.0]] * 4)
    t = T0 + np.array([0.0, 21600.0, 43200.0, 64800.0])
    quiet = atmosphere.msis_density(t, r, _weather(4.0))
    storm = atmosphere.msis_density(t, r, _weather(150.0))
    assert np.all((quiet > 2e-12) & (quiet < 1.5e-11))
    assert np.all(storm > 1.3 * quiet)


def test_space_weather_inputs_are_what_msis_reads() -> None:
    w = synthetic_weather(T0, T0 + 2 * 86400.0, seed=3)
    t = T0 + 86400.0 + 4 * 3600.0  # day 4 of the series, 3-hourly slot 1 of that day
    f107, f107a, ap = w.msis_inputs(np.array([t]))
    day, k = 4, 8 * 4 + 1
    assert f107[0] == w.f107[day - 1] and f107a[0] == w.f107a[day]
    assert ap[0, 0] == np.mean(w.ap[8 * day:8 * day + 8])
    assert list(ap[0, 1:5]) == [w.ap[k], w.ap[k - 1], w.ap[k - 2], w.ap[k - 3]]
    assert ap[0, 5] == np.mean(w.ap[k - 11:k - 3])
    assert ap[0, 6] == np.mean(w.ap[k - 19:k - 11])


def test_manoeuvre_changes_the_velocity_along_track_then() -> None:
    m = world.Manoeuvre(3 * 3600.0, (0.0, 1.0, 0.0))
    free = world.World(degree=4, sun_moon=False, area_to_mass=0.0, bc=0.0)
    burnt = free.with_(manoeuvres=(m,))
    a = world.world_truth(ISS, T0, SPAN_S, free)
    b = world.world_truth(ISS, T0, SPAN_S, burnt)
    tm = T0 + m.t_s
    before = T0 + np.array([0.0, 3600.0, m.t_s - 1.0])
    assert np.abs(a.states(before) - b.states(before)).max() < 1e-9
    xa, xb = a.states([tm])[0], b.states([tm])[0]
    dv = rtn_axes(xa[None])[0] @ (xb[3:] - xa[3:]) * 1e3  # m/s in R, T, N
    assert np.allclose(dv, [0.0, 1.0, 0.0], atol=1e-9)
    later = T0 + SPAN_S
    assert np.linalg.norm(a.states([later])[0, :3] - b.states([later])[0, :3]) > 5.0  # km


def test_lagrange_is_exact_on_degree_nine() -> None:
    u = np.arange(40, dtype=float)
    table = np.stack([u**9 * 1e-12 - 3 * u**4, np.cos(0.0 * u) + u], axis=1)
    q = np.array([0.3, 4.5, 17.25, 38.9, 39.0])
    want = np.stack([q**9 * 1e-12 - 3 * q**4, 1.0 + q], axis=1)
    assert np.allclose(world.lagrange(table, q), want, rtol=1e-9, atol=1e-9)

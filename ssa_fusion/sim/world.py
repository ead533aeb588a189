"""The high-fidelity world an object moves in: a truth richer than any filter's model.

`TruthModel` says which truth a real-sky scenario (`sky.SkyScenario.truth`) has: SGP4 (an
analytic theory, the simulator's historic truth) or `TruthModel.HIGH_FIDELITY`, a numerical
propagation by the force model's own propagator (`core.motion.high_fidelity.propagate`,
the same compiled code an orbit fit with a `ForceSpec` runs) of everything `World` lists:

* the geopotential EGM96 to ``degree`` x ``degree`` (default 20 x 20), about the real
  Earth's orientation (IAU 2006/2000A + EOP);
* the Sun and the Moon (DE421);
* solar radiation pressure on a cannonball with the Earth's conical shadow;
* drag in NRLMSISE-00's atmosphere (`atmosphere`), driven by space weather
  (`space_weather`: synthetic F10.7 and ap drawn from ``weather_seed``, storms included):
  the propagator's drag is the exponential atmosphere's times a density factor tabulated
  in time (`high_fidelity.DensityTable`), the factor NRLMSISE-00's density along the
  orbit over the exponential one's. The orbit depends on the density and the density on
  the orbit: the truth is propagated with the factor 1, the factor evaluated along it,
  propagated again on that factor, `density_iterations` times (`world_truth`); the last
  two orbits differ by `WorldTruth.converged_km`, which `world_truth` bounds
  (`CONVERGED_KM`);
* optionally, small unannounced manoeuvres (`Manoeuvre`: an impulsive velocity change in
  R, T, N at an epoch), of which no filter is told.

The truth is tabulated on a grid (`step_s`) over the scenario's span with a margin and
interpolated (Lagrange, degree 9 over the ten nodes around an epoch, positions and
velocities each: below a millimetre at 60 s nodes in LEO, `test_world`), one table per arc
between manoeuvres.

Units: km, km/s, s; m/s for a manoeuvre's velocity change; GCRF; Unix s UTC.
"""

from __future__ import annotations

import enum
import functools
import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ssa_fusion.core.earth.frames import rtn_axes
from ssa_fusion.core.motion import high_fidelity as hf
from ssa_fusion.core.motion.force_spec import DragSpec, ForceSpec, SrpSpec
from ssa_fusion.formats.icgem import egm96
from ssa_fusion.sim import atmosphere
from ssa_fusion.sim.space_weather import SpaceWeather, synthetic_weather

__all__ = ["CONVERGED_KM", "Manoeuvre", "TruthModel", "World", "WorldTruth", "force_spec",
           "lagrange", "random_manoeuvres", "world_truth"]

Array = NDArray[np.float64]

MARGIN_S = 1800.0
"""Span tabulated before a scenario's start and after its end (light time, rounding), s."""
CONVERGED_KM = 1e-3
"""The most the last two density iterations' orbits may differ, km (else ValueError)."""


class TruthModel(enum.StrEnum):
    """Which truth a real-sky scenario's object follows."""

    SGP4 = "sgp4"
    """SGP4/SDP4 with the scenario's B* (the analytic theory of element sets)."""
    HIGH_FIDELITY = "high_fidelity"
    """The numerical propagation of everything `World` lists (module docstring)."""


@dataclass(frozen=True)
class Manoeuvre:
    """An impulsive velocity change ``dv_rtn_m_s`` (R, T, N, m/s) ``t_s`` s after the start."""

    t_s: float
    dv_rtn_m_s: tuple[float, float, float]


@dataclass(frozen=True)
class World:
    """The forces on the object of a high-fidelity truth (module docstring).

    Attributes
    ----------
    degree : int
        Degree and order of the EGM96 geopotential.
    sun_moon : bool
        The Sun and the Moon.
    area_to_mass, cr : float
        Solar radiation pressure's A/m (m^2/kg; 0: none) and Cr.
    bc : float
        Ballistic coefficient m / (Cd A), kg/m^2 (0: no drag).
    weather_seed : int
        Seed of the synthetic space weather (`space_weather.synthetic_weather`).
    f107_level : float
        Its mean F10.7, sfu.
    storm_every_days : float
        Its mean days between geomagnetic storms (0: none).
    manoeuvres : tuple of Manoeuvre
        Unannounced impulsive manoeuvres.
    step_s : float
        The table's and the integration's step, s.
    density_iterations : int
        Propagations on the density factor of the one before (after the first, on 1).
    """

    degree: int = 20
    sun_moon: bool = True
    area_to_mass: float = 0.004
    cr: float = 1.3
    bc: float = 120.0
    weather_seed: int = 0
    f107_level: float = 150.0
    storm_every_days: float = 9.0
    manoeuvres: tuple[Manoeuvre, ...] = ()
    step_s: float = 60.0
    density_iterations: int = 3

    def with_(self, **changes: object) -> World:
        """Return a copy with ``changes`` (`dataclasses.replace`)."""
        from dataclasses import replace

        # arg-type: fields of different types by name; replace rejects an unknown one
        return replace(self, **changes)  # type: ignore[arg-type]

    def weather(self, t0_unix: float, t1_unix: float) -> SpaceWeather:
        """Return the space weather of this world over ``t0_unix`` .. ``t1_unix``."""
        return synthetic_weather(t0_unix, t1_unix, self.weather_seed, self.f107_level,
                                 self.storm_every_days)


def force_spec(world: World) -> ForceSpec:
    """Return the force model of ``world`` (its drag: the exponential atmosphere, factor 1)."""
    return ForceSpec(egm96(), world.degree, sun=world.sun_moon, moon=world.sun_moon,
                     srp=SrpSpec(world.area_to_mass, world.cr) if world.area_to_mass > 0
                     else None,
                     drag=DragSpec(bc=world.bc) if world.bc > 0 else None)


def random_manoeuvres(seed: int, duration_s: float, count: int,
                      dv_m_s: float = 0.3) -> tuple[Manoeuvre, ...]:
    """Return ``count`` along-track manoeuvres of +-``dv_m_s`` m/s at random epochs.

    Drawn from ``seed`` (a generator of its own) between 10 % and 90 % of ``duration_s``,
    at least an hour apart (fewer when they do not fit), in time order.
    """
    rng = np.random.default_rng([seed, 5309])
    out: list[float] = []
    for t in rng.uniform(0.1 * duration_s, 0.9 * duration_s, 10 * max(count, 1)):
        if len(out) < count and all(abs(t - o) >= 3600.0 for o in out):
            out.append(float(t))
    signs = rng.choice([-1.0, 1.0], size=len(out))
    return tuple(Manoeuvre(t, (0.0, float(s * dv_m_s), 0.0))
                 for t, s in sorted(zip(out, signs, strict=True)))


@dataclass(frozen=True)
class WorldTruth:
    """A high-fidelity truth tabulated: arcs between manoeuvres, interpolated.

    Attributes
    ----------
    arcs : tuple of (float, ndarray (n_k, 6))
        One table per arc, in time order (its first epoch, Unix s, and its states every
        ``step_s``); arc k + 1 starts at manoeuvre k.
    step_s : float
        The tables' step, s.
    starts : ndarray (K,)
        The manoeuvres' epochs (Unix s): where each arc after the first starts.
    density : high_fidelity.DensityTable
        The density factor the last propagation used.
    converged_km : float
        The largest position difference between the last two propagations, km.
    """

    arcs: tuple[tuple[float, Array], ...]
    step_s: float
    starts: Array
    density: hf.DensityTable
    converged_km: float

    def states(self, t_unix: ArrayLike) -> Array:
        """Return the GCRF states (n, 6) at ``t_unix`` (at a manoeuvre: after it).

        ValueError outside the tabulated span.
        """
        t = np.atleast_1d(np.asarray(t_unix, dtype=float))
        arc = np.searchsorted(self.starts, t, side="right")
        out = np.empty((t.size, 6))
        for k in np.unique(arc):
            mine = arc == k
            first, table = self.arcs[int(k)]
            out[mine] = lagrange(table, (t[mine] - first) / self.step_s)
        return out


NODES = 10
"""Interpolation nodes (degree 9)."""


def lagrange(table: Array, u: Array) -> Array:
    """Return ``table`` (n, m) interpolated at fractional indices ``u`` (k,) (degree 9).

    Over the `NODES` nodes around each index (shifted inwards at the table's ends).
    ValueError outside the table.
    """
    n = table.shape[0]
    if n < NODES or (u.size and (u.min() < 0.0 or u.max() > n - 1)):
        raise ValueError("epochs outside the truth's table")
    i0 = np.clip(np.floor(u).astype(int) - NODES // 2 + 1, 0, n - NODES)
    x = u - i0
    w = np.ones((u.size, NODES))
    for j in range(NODES):
        for m in range(NODES):
            if m != j:
                w[:, j] *= (x - m) / (j - m)
    idx = i0[:, None] + np.arange(NODES)[None, :]
    out: Array = np.einsum("kj,kjm->km", w, table[idx])
    return out


def _propagate(spec: ForceSpec, world: World, x0: Array, t0: float, grid: Array,
               density: hf.DensityTable | None) -> list[Array]:
    """Return the states on ``grid`` per arc (the manoeuvres' epochs are grid nodes)."""
    ctx = hf.setup(spec, t0, float(grid[0] - t0), float(grid[-1] - t0), density=density)
    cuts = [int(np.argmin(np.abs(grid - (t0 + m.t_s)))) for m in world.manoeuvres]
    bounds = [0, *cuts, len(grid) - 1]
    arcs: list[Array] = []
    x_start, t_start = x0, t0
    for k in range(len(bounds) - 1):
        nodes = grid[bounds[k]:bounds[k + 1] + 1]
        xs = hf.propagate(ctx, x_start, t_start, nodes, stm=False).x
        if not np.isfinite(xs).all():
            raise ValueError("the high-fidelity truth cannot be propagated over its span "
                             "(decayed?)")
        arcs.append(xs)
        if k < len(world.manoeuvres):
            x_end = xs[-1].copy()
            dv = np.asarray(world.manoeuvres[k].dv_rtn_m_s, dtype=float) * 1e-3
            x_end[3:] += rtn_axes(x_end[None])[0].T @ dv
            x_start, t_start = x_end, float(nodes[-1])
    return arcs


@functools.lru_cache(maxsize=8)
def world_truth(x0: tuple[float, ...], t0_unix: float, duration_s: float,
                world: World) -> WorldTruth:
    """Return the high-fidelity truth of the GCRF state ``x0`` at ``t0_unix`` (module docstring).

    Tabulated from `MARGIN_S` before ``t0_unix`` to `MARGIN_S` after its end (cached: the
    same arguments, the same table). ValueError when the orbit cannot be propagated, a
    manoeuvre is within ten steps of another or of the span's ends, or the density
    iterations did not converge to `CONVERGED_KM`.
    """
    step = world.step_s
    n0 = math.ceil(MARGIN_S / step)
    n1 = math.ceil((duration_s + MARGIN_S) / step)
    grid = t0_unix + step * np.arange(-n0, n1 + 1, dtype=float)
    cut_t = sorted(t0_unix + m.t_s for m in world.manoeuvres)
    if any(b - a < 10 * step for a, b in zip([grid[0], *cut_t], [*cut_t, grid[-1]],
                                             strict=True)):
        raise ValueError("manoeuvres must be at least ten steps apart and from the span's ends")
    spec = force_spec(world)
    weather = world.weather(float(grid[0]), float(grid[-1]))
    x = np.asarray(x0, dtype=float)
    density: hf.DensityTable | None = None
    arcs = _propagate(spec, world, x, t0_unix, grid, density)
    moved = math.inf
    for _ in range(world.density_iterations if spec.drag is not None else 0):
        r = _on_grid(arcs)[:, :3]
        assert spec.drag is not None
        density = hf.DensityTable(float(grid[0]), step,
                                  atmosphere.density_factor(grid, r, weather, spec.drag))
        again = _propagate(spec, world, x, t0_unix, grid, density)
        moved = max(float(np.max(np.linalg.norm(a[:, :3] - b[:, :3], axis=1)))
                    for a, b in zip(arcs, again, strict=True))
        arcs = again
    if spec.drag is None:
        moved = 0.0
    if not moved <= CONVERGED_KM:
        raise ValueError(f"the truth's density iterations moved it by {moved:.3g} km "
                         f"(> {CONVERGED_KM} km): more iterations")
    bounds = [0, *[int(np.argmin(np.abs(grid - t))) for t in cut_t], len(grid) - 1]
    tables = tuple((float(grid[bounds[k]]), a) for k, a in enumerate(arcs))
    return WorldTruth(tables, step, np.asarray(cut_t, dtype=float),
                      density or hf.DensityTable(float(grid[0]), step, np.ones(len(grid))),
                      moved)


def _on_grid(arcs: list[Array]) -> Array:
    """Return the arcs' states on the whole grid (a manoeuvre's node: the state before it)."""
    return np.concatenate([arcs[0], *(a[1:] for a in arcs[1:])])

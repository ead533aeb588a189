"""Screening a catalog for close approaches: every pair, a window of days, nothing missed.

`screen` finds every pair of objects of an `ephemeris.Ephemeris` that comes within
``distance_km`` of each other between two epochs, with the time of closest approach (TCA)
and the miss distance of the objects' own propagation (SGP4, or the filter's model), in
chunks of time (memory bounded by the chunk, not the window):

1. every object is sampled at nodes every ``node_step_s`` (300 s) over the chunk, with one
   node more on either side (`Ephemeris.sample`, vectorised); accelerations at the nodes
   from two-body + J2 (`hermite.node_table`); each object's interpolation error bounds,
   measured on the nodes (`hermite.interpolation_pad`), its radial band, largest speed and
   acceleration (`apsides.radial_bands`: the apogee/perigee filter, with ``band_pad_km``);
2. at fine epochs ``fine_step_s`` apart (20 s) every object is interpolated and binned in a
   spatial grid; the pairs near each other pass a test that cannot miss an approach within
   the screening distance (`sieve`: no loop over pairs, compiled);
3. near each hit, the local minima of the interpolated distance (`tca.hit_roots`: Brent on
   the range rate), then Newton on the ephemeris's own states (`tca.newton_tca`); an
   approach is kept when its TCA is in the window and its miss distance at most
   ``distance_km``. The same approach found from two hits is kept once.

A screening of ``primaries`` (indices of a few objects) tests only the pairs with one of
them (a re-screening when their estimates change): objects whose radial band meets none of
theirs are not even binned.

Units: epochs Unix s (UTC), km, km/s, s.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ssa_fusion.core.base.constants import MU_EARTH
from ssa_fusion.core.conjunction import apsides, hermite, sieve, tca
from ssa_fusion.core.conjunction.close_approach import ApproachBuffer, CloseApproaches, once
from ssa_fusion.core.conjunction.ephemeris import Covariances, Ephemeris
from ssa_fusion.core.earth.frames import cip_gcrs

__all__ = ["ScreeningConfig", "screen"]

Array = NDArray[np.float64]
BoolArray = NDArray[np.bool_]
IntArray = NDArray[np.int64]

ACCEL_MARGIN = 1.01
"""Largest acceleration over the two-body one at the smallest radius (J2 adds < 0.5 %)."""

POLISH_BATCH = 1 << 20
"""Roots moved to the ephemeris's trajectories at a time (`_polish`)."""



@dataclass(frozen=True)
class ScreeningConfig:
    """How a catalog is screened (`screen`).

    Attributes
    ----------
    distance_km : float
        Screening distance: approaches closer than it are reported, km.
    node_step_s : float
        Spacing of the sampled states (the interpolation nodes), s.
    fine_steps : int
        Fine epochs per node interval (fine spacing = node_step_s / fine_steps), where the
        grid is built: the pair test's slack grows as its square, its cells as it.
    chunk_nodes : int
        Node intervals per chunk of time (memory: ~(chunk_nodes + 3) x 72 B per object).
    band_pad_km : float
        Pad of the radial bands (`apsides`), km.
    newton_iterations : int
        Newton steps on the ephemeris's own states (`tca.newton_tca`).
    workers : int
        Threads testing the fine epochs of a chunk (`sieve.sieve`).
    """

    distance_km: float = 10.0
    node_step_s: float = 300.0
    fine_steps: int = 15
    chunk_nodes: int = 24
    band_pad_km: float = 2.0
    newton_iterations: int = 2
    workers: int = 1

    @property
    def fine_step_s(self) -> float:
        """Spacing of the fine epochs, s."""
        return self.node_step_s / self.fine_steps

    def __post_init__(self) -> None:
        """Refuse a configuration that cannot screen (ValueError naming the field)."""
        for name in ("distance_km", "node_step_s", "band_pad_km"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0):
                raise ValueError(f"{name} must be a positive number, not {value!r}")
        for name in ("fine_steps", "chunk_nodes", "workers"):
            if getattr(self, name) < 1:
                raise ValueError(f"{name} must be at least 1")


def _limits(x: Array, table: hermite.NodeTable, pad_km: float,
            primary: BoolArray) -> sieve.PairLimits:
    """Each object's bounds over a chunk, from its node states ``x`` (N, K, 6)."""
    bands = apsides.radial_bands(x, pad_km)
    eps, eps_v = hermite.interpolation_pad(table)
    with np.errstate(divide="ignore", invalid="ignore"):
        amax = ACCEL_MARGIN * MU_EARTH / np.maximum(bands.lo, 1.0) ** 2
    return sieve.PairLimits(bands.lo, bands.hi, bands.vmax, amax, eps, eps_v, primary)


def _chunk(nodes_x: Array, t_nodes: Array, config: ScreeningConfig,
           window: tuple[float, float], n_steps: int, primary: BoolArray) -> tca.Roots:
    """Screen one chunk: nodes ``t_nodes`` (one before its first fine epoch); its roots.

    The fine epochs are ``t_nodes[1] + s h`` for s < ``n_steps``: the local minima of the
    interpolated distances near them (`tca.hit_roots`), before Newton.
    """
    h, m = config.fine_step_s, config.fine_steps
    table = hermite.node_table(nodes_x, float(t_nodes[0]), config.node_step_s,
                               cip_gcrs(float(np.mean(t_nodes))))
    limits = _limits(nodes_x, table, config.band_pad_km, primary)
    hits = sieve.sieve(table, m, m, n_steps, config.distance_km, limits, config.workers)
    limit = config.distance_km + limits.eps[hits.i] + limits.eps[hits.j]
    return tca.hit_roots(table, hits, float(t_nodes[1]), h, window, limit)


def _polish(eph: Ephemeris, roots: tca.Roots, config: ScreeningConfig,
            window: tuple[float, float], out: ApproachBuffer) -> None:
    """Move roots to the ephemeris's trajectories; add those that are approaches to ``out``.

    In the window and within the screening distance. `POLISH_BATCH` roots at a time
    (memory ~1 kB a root).
    """
    out.reserve(out.n + roots.t.size)
    for a in range(0, roots.t.size, POLISH_BATCH):
        part = roots.take(slice(a, a + POLISH_BATCH))
        t, xi, xj = tca.newton_tca(eph, part, config.fine_step_s, config.newton_iterations)
        miss = np.linalg.norm(xj[:, :3] - xi[:, :3], axis=1)
        with np.errstate(invalid="ignore"):
            keep = (t >= window[0]) & (t <= window[1]) & (miss <= config.distance_km)
        out.add(part.i[keep], part.j[keep], t[keep], miss[keep], xi[keep], xj[keep])


def _primaries(n: int, primaries: ArrayLike | None) -> BoolArray:
    """Return the primary mask (N,) of indices or a mask ``primaries`` (None: every object)."""
    if primaries is None:
        return np.ones(n, dtype=np.bool_)
    p = np.asarray(primaries)
    if p.dtype == np.bool_:
        return np.array(p, dtype=np.bool_).reshape(n)
    mask = np.zeros(n, dtype=np.bool_)
    mask[p.astype(np.int64)] = True
    return mask


def screen(eph: Ephemeris, t_start: float, t_end: float,
           config: ScreeningConfig | None = None,
           primaries: ArrayLike | None = None) -> CloseApproaches:
    """Find every close approach of the catalog ``eph`` between two epochs.

    Parameters
    ----------
    eph : Ephemeris
        The catalog's trajectories (`ElementSetEphemeris`, `StateEphemeris`).
    t_start, t_end : float
        The window, Unix s (UTC): approaches whose TCA lies in it (a distance still
        shrinking at an end of the window is not an approach).
    config : ScreeningConfig, optional
        Screening distance and sampling (defaults: 10 km, nodes every 300 s, fine epochs
        every 20 s, chunks of 2 h).
    primaries : array_like of int or bool, optional
        Screen only the pairs with one of these objects (indices into ``eph.object_ids``,
        or a mask); None: every pair.

    Returns
    -------
    CloseApproaches
        By TCA; ``primary`` is one of ``primaries`` (the lower index when both are), the
        states are the ephemeris's at TCA, and the covariances those a `Covariances`
        ephemeris carries to TCA (when it holds them).
    """
    cfg = config or ScreeningConfig()
    if not t_end > t_start:
        raise ValueError(f"the window must end after it starts ({t_start} .. {t_end})")
    primary = _primaries(len(eph.object_ids), primaries)
    big_h, m, c = cfg.node_step_s, cfg.fine_steps, cfg.chunk_nodes
    n_fine = math.ceil((t_end - t_start) / cfg.fine_step_s) + 1  # the last >= t_end
    window = (t_start, t_end)
    found = ApproachBuffer(eph.object_ids)
    waiting: list[tca.Roots] = []
    kept_t: Array = np.zeros(0)
    kept_x: Array = np.zeros((len(eph.object_ids), 0, 6))
    for first in range(0, n_fine, c * m):
        steps = min(c * m, n_fine - first)
        k0 = first // m - 1  # node index (0 at t_start) of the chunk's first node
        k1 = (first + steps - 1) // m + 2  # one node after the node interval of its last
        t_nodes: Array = t_start + big_h * np.arange(k0, k1 + 1, dtype=float)
        old = int(np.count_nonzero(t_nodes <= (kept_t[-1] if kept_t.size else -np.inf)))
        x = np.concatenate([kept_x[:, kept_x.shape[1] - old:], eph.sample(t_nodes[old:])],
                           axis=1)
        kept_t, kept_x = np.asarray(t_nodes[-3:], dtype=float), x[:, -3:]
        roots = _chunk(np.ascontiguousarray(x), t_nodes, cfg, window, steps, primary)
        roots = roots.take(once(roots.i, roots.j, roots.t))  # a root from two hits once
        if eph.local_exact:
            _polish(eph, roots, cfg, window, found)
        else:
            waiting.append(roots)
    if waiting:
        _polish(eph, tca.Roots.concat(waiting), cfg, window, found)
    out = found.result()
    if isinstance(eph, Covariances) and eph.p0 is not None:
        both = eph.covariance(np.concatenate([out.primary, out.secondary]),
                              np.concatenate([out.tca, out.tca]))  # each object flown once
        out = replace(out, p1=both[:len(out)], p2=both[len(out):])
    return out

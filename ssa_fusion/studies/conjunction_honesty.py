"""Is the collision probability honest? Simulated close approaches where the truth is known.

`run_honesty` plants ``pairs`` close approaches among LEO objects: at a TCA ``lead_s`` after
the estimates' epoch, the *estimated* states of each pair pass with a miss vector drawn
uniformly in a disk of ``miss_disk_km`` (in the plane across their relative velocity,
crossing at 20 to 160 degrees). The estimates are flown back to their epoch with the
filter's model; each object gets a covariance there (RTN standard deviations drawn per
object around ``sigma_pos_km`` and ``sigma_vel_km_s``, reported with the estimate), and its
*truth* is a draw from it around the estimate (so the estimate's distribution of the truth
is the covariance it reports: a Pc that uses it should come true at its own rate), flown
with ``truth_model``.

The estimated catalog (`core.conjunction.ephemeris.StateEphemeris`, the covariances carried
by its state transition matrices) is screened (`core.conjunction.screening`) around the
planted TCAs; each planted pair found is scored:

* the true relative position at the estimated TCA, projected on the estimated encounter
  plane (`core.conjunction.encounter.encounter_plane`), against the estimated miss vector,
  normalised by the combined covariance there: chi-square with 2 degrees of freedom when the
  covariances are honest (``coverage95``: the fraction within chi2_2's 95 % point, 5.991);
* the 2D Pc (Foster, `CloseApproaches.log10_pc`, hard-body radius ``hbr_km``) against
  whether the truth collided (its least distance, by Newton on the truth's own range rate,
  below the radius): `reliability` bins the Pc and compares the mean Pc of each bin with
  the rate of collisions in it (Wilson 95 % interval).

A covariance reported ``cov_scale`` times the one the truth was drawn from (< 1:
overconfident) shows what a dishonest one does. Units: km, km/s, s.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy.stats import chi2

from ssa_fusion.core.base.constants import R_EARTH
from ssa_fusion.core.base.types import MotionModel
from ssa_fusion.core.conjunction import tca
from ssa_fusion.core.conjunction.close_approach import CloseApproaches
from ssa_fusion.core.conjunction.encounter import encounter_plane
from ssa_fusion.core.conjunction.ephemeris import StateEphemeris
from ssa_fusion.core.conjunction.screening import ScreeningConfig, screen
from ssa_fusion.core.earth.frames import rtn_axes
from ssa_fusion.core.motion.dynamics import elements_to_state

__all__ = ["HonestyConfig", "HonestyResult", "ReliabilityRow", "reliability", "run_honesty"]

Array = NDArray[np.float64]
BoolArray = NDArray[np.bool_]

T0 = 1.7536e9
"""Epoch of the estimates (2025-07-28 UTC), Unix s."""
CHI2_2_95 = float(chi2.ppf(0.95, 2))
"""The 95 % point of chi-square with 2 degrees of freedom (5.991)."""
PC_BINS = (0.0, 1e-3, 1e-2, 3e-2, 0.1, 0.2, 1.0)
"""Edges of the Pc bins of the reliability table."""


@dataclass(frozen=True)
class HonestyConfig:
    """The simulated close approaches (module docstring).

    Attributes
    ----------
    pairs : int
        Close approaches planted.
    lead_s : float
        From the estimates' epoch to the TCAs, s.
    miss_disk_km : float
        Estimated miss vectors uniform in a disk of this radius, km.
    hbr_km : float
        Combined hard-body radius, km.
    sigma_pos_km, sigma_vel_km_s : tuple of 3 floats
        RTN standard deviations of position and velocity at the epoch (each object's drawn
        between half and twice these).
    truth_model, filter_model : MotionModel
        What the truth follows and what the estimates are flown with.
    cov_scale : float
        Reported covariance over the one the truth is drawn from.
    seed : int
    """

    pairs: int = 4000
    lead_s: float = 1800.0
    miss_disk_km: float = 0.1
    hbr_km: float = 0.03
    sigma_pos_km: tuple[float, float, float] = (0.01, 0.02, 0.01)
    sigma_vel_km_s: tuple[float, float, float] = (2e-6, 4e-6, 2e-6)
    truth_model: MotionModel = MotionModel.J2
    filter_model: MotionModel = MotionModel.J2
    cov_scale: float = 1.0
    seed: int = 1


@dataclass(frozen=True)
class ReliabilityRow:
    """One Pc bin: approaches, their mean Pc, collisions and the Wilson 95 % interval."""

    lo: float
    hi: float
    n: int
    mean_pc: float
    collisions: int
    rate_lo: float
    rate_hi: float

    @property
    def consistent(self) -> bool:
        """Whether the mean Pc lies in the collision rate's 95 % interval."""
        return self.rate_lo <= self.mean_pc <= self.rate_hi


@dataclass(frozen=True)
class HonestyResult:
    """Scores of the planted approaches found (M of ``planted``).

    Attributes
    ----------
    planted : int
        Approaches planted.
    epsilon : ndarray (M,)
        Normalised squared miss error in the encounter plane (chi2_2 when honest).
    pc : ndarray (M,)
        2D Pc of each.
    collided : ndarray (M,) of bool
        Whether the truth came within the hard-body radius.
    true_miss_km : ndarray (M,)
        The truth's least distance, km.
    """

    planted: int
    epsilon: Array
    pc: Array
    collided: BoolArray
    true_miss_km: Array

    @property
    def coverage95(self) -> float:
        """Fraction of epsilon within chi2_2's 95 % point (0.95 when honest)."""
        return float(np.mean(self.epsilon <= CHI2_2_95))


def _wilson(k: int, n: int, z: float = 1.959964) -> tuple[float, float]:
    """Wilson score interval of a rate k / n (95 % by default)."""
    if n == 0:
        return 0.0, 1.0
    p = k / n
    c = (p + z * z / (2 * n)) / (1 + z * z / n)
    h = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / (1 + z * z / n)
    return max(0.0, c - h), min(1.0, c + h)


def reliability(pc: Array, collided: BoolArray,
                edges: tuple[float, ...] = PC_BINS) -> list[ReliabilityRow]:
    """Return the reliability table: per Pc bin ``[lo, hi)``, mean Pc against the rate."""
    rows = []
    for lo, hi in itertools.pairwise(edges):
        sel = (pc >= lo) & ((pc < hi) if hi < 1.0 else (pc <= hi))
        n, k = int(sel.sum()), int(collided[sel].sum())
        rows.append(ReliabilityRow(lo, hi, n, float(pc[sel].mean()) if n else math.nan, k,
                                   *_wilson(k, n)))
    return rows


def _rtn_covariance(x: Array, sig_pos: Array, sig_vel: Array) -> Array:
    """GCRF covariances (n, 6, 6) of diagonal RTN ones (standard deviations (n, 3) each)."""
    m = np.swapaxes(rtn_axes(x), 1, 2)  # columns R, T, N
    b = np.zeros((len(x), 6, 6))
    b[:, :3, :3] = b[:, 3:, 3:] = m
    d = np.zeros((len(x), 6, 6))
    idx = np.arange(6)
    d[:, idx, idx] = np.concatenate([sig_pos, sig_vel], axis=1) ** 2
    out: Array = b @ d @ np.swapaxes(b, 1, 2)
    return out


def _planted_estimates(cfg: HonestyConfig, rng: np.random.Generator) -> tuple[Array, Array]:
    """Return the estimated states of the pairs at their TCAs (2P, 6) and the TCAs (P,)."""
    states = np.empty((2 * cfg.pairs, 6))
    t_c = T0 + cfg.lead_s + rng.uniform(-30.0, 30.0, cfg.pairs)
    for k in range(cfg.pairs):
        a = elements_to_state(R_EARTH + rng.uniform(450.0, 850.0), rng.uniform(0.0, 0.005),
                              rng.uniform(0.1, math.pi - 0.1), *rng.uniform(0, 2 * math.pi, 3))
        r_hat = a[:3] / np.linalg.norm(a[:3])
        th = math.radians(rng.uniform(20.0, 160.0))
        v = a[3:] * math.cos(th) + np.cross(r_hat, a[3:]) * math.sin(th)
        rel = v - a[3:]
        e1 = np.cross(rel, r_hat)
        e1 /= np.linalg.norm(e1)
        e2 = np.cross(rel / np.linalg.norm(rel), e1)
        rho, phi = cfg.miss_disk_km * math.sqrt(rng.uniform()), rng.uniform(0, 2 * math.pi)
        states[2 * k] = a
        states[2 * k + 1] = np.r_[a[:3] + rho * (math.cos(phi) * e1 + math.sin(phi) * e2), v]
    return states, t_c


def _catalogs(cfg: HonestyConfig) -> tuple[StateEphemeris, StateEphemeris, Array]:
    """Return the estimated catalog (with covariances), the truth and the planted TCAs."""
    rng = np.random.default_rng(cfg.seed)
    at_tca, t_c = _planted_estimates(cfg, rng)
    n = len(at_tca)
    ids = [str(k) for k in range(n)]
    back = StateEphemeris(ids, at_tca, np.repeat(t_c, 2), model=cfg.filter_model)
    x_hat = back.exact(np.arange(n), np.full(n, T0))
    scale = rng.uniform(0.5, 2.0, (n, 2))
    p = _rtn_covariance(x_hat, np.asarray(cfg.sigma_pos_km) * scale[:, :1],
                        np.asarray(cfg.sigma_vel_km_s) * scale[:, 1:])
    truth = x_hat + np.einsum("nij,nj->ni", np.linalg.cholesky(p), rng.standard_normal((n, 6)))
    estimated = StateEphemeris(ids, x_hat, np.full(n, T0), model=cfg.filter_model,
                               covariance=cfg.cov_scale * p)
    return estimated, StateEphemeris(ids, truth, np.full(n, T0), model=cfg.truth_model), t_c


def _planted_found(found: CloseApproaches, pairs: int) -> CloseApproaches:
    """Return the approaches of planted pairs (2k, 2k + 1), the first of each pair only."""
    lo = np.minimum(found.primary, found.secondary)
    hi = np.maximum(found.primary, found.secondary)
    ok = (lo % 2 == 0) & (hi == lo + 1) & (lo < 2 * pairs)
    first = np.zeros(len(found), dtype=bool)
    _, at = np.unique(lo[ok], return_index=True)
    first[np.flatnonzero(ok)[at]] = True
    return found.take(first)


def run_honesty(cfg: HonestyConfig | None = None) -> HonestyResult:
    """Plant, screen and score the approaches (module docstring)."""
    cfg = cfg or HonestyConfig()
    estimated, truth, t_c = _catalogs(cfg)
    window = (float(t_c.min()) - 300.0, float(t_c.max()) + 300.0)
    found = screen(estimated, *window, ScreeningConfig(distance_km=5.0, chunk_nodes=4))
    found = _planted_found(found, cfg.pairs)
    if found.p1 is None or found.p2 is None:  # a StateEphemeris with covariances carries them
        raise RuntimeError("the screening lost the covariances")
    enc = encounter_plane(found.x1, found.p1, found.x2, found.p2)
    truth.sample(np.arange(window[0], window[1] + 300.0, 300.0))  # `exact` starts near
    t1, t2 = truth.exact(found.primary, found.tca), truth.exact(found.secondary, found.tca)
    plane = enc.axes[:, [0, 2], :]
    err = np.einsum("nij,nj->ni", plane, t2[:, :3] - t1[:, :3]) - enc.miss
    epsilon = np.einsum("ni,ni->n", err, np.linalg.solve(enc.cov, err[..., None])[..., 0])
    roots = tca.Roots(found.primary, found.secondary, found.tca)
    _, y1, y2 = tca.newton_tca(truth, roots, 60.0, iterations=4)
    true_miss = np.linalg.norm(y2[:, :3] - y1[:, :3], axis=1)
    pc = np.minimum(10.0 ** found.log10_pc(cfg.hbr_km), 1.0)
    return HonestyResult(cfg.pairs, epsilon, pc, true_miss < cfg.hbr_km, true_miss)

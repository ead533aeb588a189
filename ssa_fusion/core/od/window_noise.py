"""Process noise through a batch fit's window and its predictions (realistic covariance).

`batch_ls`'s realistic covariance: state-noise compensation in RTN (`process_noise.snc`),
white accelerations along the fit's reference trajectory, on a grid of ``noise_step_s``
(`with_grid`) outwards from the epoch on either side (`outward`): each step's noise mapped
to the epoch (`noise_increments`); through a prediction it accumulates from the epoch on
(`accumulated_noise`); in the window it makes the measurements' errors correlated, and
gives the estimate ``P (J^T C_e J) P`` (`window_noise`). Units: km, km/s, s; GCRF.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

from ssa_fusion.core.filter.process_noise import snc_batch
from ssa_fusion.core.motion.force_model import ForceModel, trajectory

if TYPE_CHECKING:
    from ssa_fusion.core.motion.force_spec import ForceSpec

__all__ = ["accumulated_noise", "noise_increments", "outward", "window_noise", "with_grid"]

Array = NDArray[np.float64]
IntArray = NDArray[np.int64]


def with_grid(t0: float, t: Array, step: float) -> Array:
    """Sorted union of the epochs ``t`` and the grid of ``step`` from t0 out to them."""
    parts = [t, np.array([t0])]
    for sign in (1.0, -1.0):
        reach = float(np.max(sign * (t - t0), initial=0.0))
        if reach > 0.0:
            parts.append(t0 + sign * np.arange(1, math.ceil(reach / step)) * step)
    return np.unique(np.concatenate(parts))


def outward(t0: float, t: Array) -> list[IntArray]:
    """Return the indices of ``t`` after and before ``t0`` (not at it), ordered outwards."""
    out = []
    for side in (t > t0, t < t0):
        idx = np.flatnonzero(side)
        out.append(idx[np.argsort(np.abs(t[idx] - t0), kind="stable")])
    return out


def noise_increments(t0: float, t: Array, x: Array, phi: Array, psd: Array,
                      idx: IntArray) -> Array:
    """Process noise of each step outwards along ``idx``, in epoch coordinates (L, 6, 6).

    Step l runs from the previous node (or t0) to node ``idx[l]``: SNC (`process_noise.snc`)
    with the axes of that node's state, mapped to the epoch by ``Phi_l^-1``.
    """
    tl = t[idx]
    dts = np.diff(tl, prepend=t0)
    q = snc_batch(x[idx], dts, psd)
    inv = np.linalg.inv(phi[idx])
    out: Array = inv @ q @ np.swapaxes(inv, 1, 2)
    return out


def accumulated_noise(t0: float, t: Array, x: Array, phi: Array, psd: Array) -> Array:
    """Process noise accumulated from t0 to each epoch (K, 6, 6), GCRF (module docstring)."""
    out = np.zeros((t.size, 6, 6))
    for idx in outward(t0, t):
        if not idx.size:
            continue
        c = np.cumsum(noise_increments(t0, t, x, phi, psd, idx), axis=0)
        p = phi[idx]
        out[idx] = p @ c @ np.swapaxes(p, 1, 2)
    return out


def window_noise(force: ForceModel | ForceSpec, x0: Array, t0: float, params: Array,
                 max_step_s: float, pole: Array, noise_step_s: float, t: Array, J: Array,
                 group: IntArray, psd: Array) -> Array:
    """``J^T C_e J`` (n, n) of the process noise between the measurements and the epoch.

    The fit's reference trajectory from ``x0`` (GCRF km, km/s at ``t0``, s) by ``force`` with
    the parameters ``params`` (`PARAMETERS` order), integrated at steps of at most
    ``max_step_s`` with J2 about ``pole``; the noise on the grid of ``noise_step_s`` (s) out
    to the measurements' epochs ``t`` (M,). ``J`` (rows, n) the accepted whitened partials
    (the state's columns first), ``group`` their measurements (module docstring).
    """
    epochs = with_grid(t0, t, noise_step_s)
    tr = trajectory(force, x0, t0, epochs, params, (), max_step_s, pole)
    n = J.shape[1]
    a = np.zeros((t.size, 6, n))  # a_i = U_i^T J_i, U_i = the state columns of J_i
    np.add.at(a, group, J[:, :6, None] * J[:, None, :])
    node = np.searchsorted(epochs, t)
    K = np.zeros((n, n))
    for idx in outward(t0, epochs):
        if not idx.size:
            continue
        qbar = noise_increments(t0, epochs, tr.x, tr.phi, psd, idx)
        pos = np.empty(epochs.size, dtype=np.int64)
        pos[idx] = np.arange(idx.size)
        side = (t > t0) if epochs[idx[0]] > t0 else (t < t0)
        a_node = np.zeros((idx.size, 6, n))
        np.add.at(a_node, pos[node[side]], a[side])
        A = np.cumsum(a_node[::-1], axis=0)[::-1]  # measurements at or beyond each node
        K += np.einsum("lia,lij,ljb->ab", A, qbar, A)
    return 0.5 * (K + K.T)

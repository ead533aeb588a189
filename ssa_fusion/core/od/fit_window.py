"""The measurements of one orbit fit: grouped, whitened, predicted, and their parameters.

`FitWindow` holds the window `batch_ls.fit` fits: every measurement with the model that
predicts it (a station network's picked per measurement), grouped by dimension and angle
channels, each group's whitening matrices ``L^-1`` (the Cholesky factor of R), and, for a
laser network's ranges (`laser_model.LaserModels`), the geometry and air of every range
computed once (`LaserModels.points`: they do not depend on the orbit) and the range biases
of the stations present as *measurement parameters*: solve-for parameters of the fit that
enter the measurements, not the motion.

`FitWindow.residuals` returns, at the states of the reference trajectory at the measurement
epochs and their partials ``G`` with respect to the fit's unknowns, the whitened residuals
``L^-1 (z - h)`` (angles wrapped), the whitened partials ``L^-1 [H G | H_p]`` (the
measurement parameters' columns last) and the raw residuals per measurement.

Units: km, km/s, rad, s; states GCRF.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ssa_fusion.core.base.types import Kind, Measurement
from ssa_fusion.core.earth.frames import wrap_angle
from ssa_fusion.core.measure.laser_model import LaserModels, LaserPoints
from ssa_fusion.core.measure.measurement import (
    MeasurementModel,
    PositionModel,
    RadecModel,
    RazelModel,
    StationModels,
)

__all__ = ["FitModel", "FitWindow"]

Array = NDArray[np.float64]
IntArray = NDArray[np.int64]
BoolArray = NDArray[np.bool_]

FitModel = MeasurementModel
"""What a fit predicts its measurements with (a laser network's `LaserModels` included)."""
_OneModel = PositionModel | RazelModel | RadecModel
"""The model of one measurement (a station network's picked per measurement)."""


def _model_for(model: MeasurementModel, m: Measurement) -> _OneModel:
    """Return the model that predicts ``m`` (its station's; ValueError if none)."""
    assert not isinstance(model, LaserModels)  # the window takes them whole
    if isinstance(model, StationModels):
        got = model.get(m.kind, m.frame_id)
        if got is None:
            raise ValueError(f"no model for a measurement of kind {m.kind} from "
                             f"{m.frame_id!r} (stations: {', '.join(model.stations)})")
        return got
    if int(m.kind) != int(model.kind):
        raise ValueError(f"measurement of kind {m.kind} for a model of kind {model.kind}")
    return model


class FitWindow:
    """The measurements of a fit (module docstring).

    Attributes
    ----------
    m : list of Measurement
        The measurements, in the order given.
    t : ndarray (N,)
        Their epochs, s.
    params : tuple of str
        The measurement parameters (a laser network's biases of the stations present).
    prior_mean, prior_sigma : ndarray (len(params),)
        Their a-priori values and standard deviations.
    """

    def __init__(self, measurements: Sequence[Measurement], model: FitModel) -> None:
        self.m = list(measurements)
        self.t = np.array([m.t for m in self.m], dtype=float)
        self.groups: list[tuple[IntArray, Array, Array, BoolArray]] = []
        self.params: tuple[str, ...] = ()
        self.prior_mean, self.prior_sigma = np.zeros(0), np.zeros(0)
        self.laser: LaserPoints | None = None
        self._present = np.zeros(0, dtype=np.intp)
        self.models: list[_OneModel] = []
        if isinstance(model, LaserModels):
            self._laser(model)
            keys: list[tuple[int, tuple[bool, ...]]] = [(1, (False,))] * len(self.m)
        else:
            self.models = [_model_for(model, m) for m in self.m]
            keys = [(len(m.z), tuple(md.angle_mask)) for m, md in zip(self.m, self.models,
                                                                      strict=True)]
        for key in dict.fromkeys(keys):  # one group per dimension and angle channels
            idx = np.array([i for i, k in enumerate(keys) if k == key], dtype=np.int64)
            R = np.array([np.asarray(self.m[i].R, dtype=float)[:key[0], :key[0]] for i in idx])
            W = np.linalg.inv(np.linalg.cholesky(0.5 * (R + np.swapaxes(R, 1, 2))))
            z = np.array([np.asarray(self.m[i].z, dtype=float)[:key[0]] for i in idx])
            self.groups.append((idx, W, z, np.array(key[1], dtype=bool)))

    def _laser(self, model: LaserModels) -> None:
        """Make the laser ranges ready (their geometry and air) and their bias parameters."""
        bad = [m for m in self.m if int(m.kind) != Kind.LASER_RANGE]
        if bad:
            raise ValueError(f"a measurement of kind {bad[0].kind} among laser ranges: fit "
                             f"laser ranges alone")
        frames = [m.frame_id for m in self.m]
        self.laser = model.points(self.t, frames)
        self.params = model.parameters(frames)
        self.prior_mean, self.prior_sigma = model.prior(self.params)
        self._present = model.station_index([p.removeprefix("bias_") for p in self.params])
        self._nb = len(model.network.ids)

    def rows(self) -> IntArray:
        """Return the measurement of every row, in the order `residuals` stacks them."""
        out: IntArray = np.concatenate([np.repeat(idx, W.shape[1])
                                        for idx, W, _, _ in self.groups])
        return out

    def _predict(self, idx: IntArray, x: Array, p: Array) -> tuple[Array, Array, Array]:
        """Return (z (k, m), H (k, m, 6), H_p (k, m, len(params))) of measurements ``idx``."""
        if self.laser is not None:
            bias = np.zeros(self._nb)
            bias[self._present] = p
            got = self.laser.predict(x, bias)
            hp = (self.laser.station[:, None] == self._present[None, :]).astype(float)
            return got.range_km[:, None], got.H[:, None, :], hp[:, None, :]
        zp = np.empty((idx.size, len(self.m[idx[0]].z)))
        H = np.empty((idx.size, zp.shape[1], 6))
        for k, i in enumerate(idx):
            zp[k], H[k] = self.models[i].h_and_H(x[k], float(self.t[i]))
        return zp, H, np.zeros((idx.size, zp.shape[1], 0))

    def residuals(self, x: Array, G: Array, p: ArrayLike = ()) -> tuple[Array, Array,
                                                                      list[Array]]:
        """Whitened residuals (rows,), partials (rows, c + len(params)) and raw residuals.

        ``x`` (N, 6) the states at the measurements, ``G`` (N, 6, c) their partials with
        respect to the fit's unknowns, ``p`` the measurement parameters' values.
        """
        pv = np.asarray(p, dtype=float).reshape(-1)
        rs, js = [], []
        raw: list[Array] = [np.zeros(0)] * len(self.m)
        for idx, W, z, mask in self.groups:
            zp, H, Hp = self._predict(idx, x[idx], pv)
            res = z - zp
            if mask.any():
                res[:, mask] = wrap_angle(res[:, mask])
            for k, i in enumerate(idx):
                raw[i] = res[k]
            rs.append(np.einsum("kij,kj->ki", W, res).reshape(-1))
            jg = (W @ H @ G[idx]).reshape(-1, G.shape[2])
            jp = (W @ Hp).reshape(jg.shape[0], Hp.shape[2])
            js.append(np.concatenate([jg, jp], axis=1))
        return np.concatenate(rs), np.concatenate(js), raw

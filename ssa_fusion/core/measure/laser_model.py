"""The laser ranges of one object from a station network: `LaserModels`, one measurement model.

`laser_range` models n two-way ranges given where the stations are and the air they look
through; this module holds what that needs for a network over a whole run and hands it to
the two estimators:

* `LaserNetwork`: the stations (`laser_station.LaserStation`, by id: the measurements'
  frame_id), the object's centre-of-mass offset, and each station's range-bias prior (mean
  and sigma): the set-up `ssa-fusion import crd` records with a bag;
* `LaserModels`: the network with the surface meteorological records heard so far
  (`add_meteo`; a station's air at an epoch is its records' (`troposphere.MeteoSeries`),
  else the standard atmosphere at its height) and the Earth's orientation. For the batch fit,
  `points` precomputes the geometry and the air of many ranges once (they do not depend on
  the orbit) and `LaserPoints.predict` evaluates them at any states; its parameters are the
  range biases of the stations present (`parameters`, `prior`). For the sequential filter,
  `get` returns one station's `LaserStationModel`, whose ``h_and_H`` takes the filter's
  augmented state ``[r, v, bias_1 .. bias_nb, ...]`` (the biases at columns ``6 + k`` in the
  network's station order).

Units: km, km/s, s; epochs Unix s (UTC); pressure hPa, temperature K, humidity %.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ssa_fusion.core.base.types import Kind
from ssa_fusion.core.earth import eop as eop_
from ssa_fusion.core.measure import laser_range as lr
from ssa_fusion.core.measure.laser_station import LaserStation
from ssa_fusion.core.measure.troposphere import MeteoSample, MeteoSeries, standard_atmosphere

__all__ = ["BIAS_PREFIX", "LaserModels", "LaserNetwork", "LaserPoints", "LaserStationModel",
           "bias_name"]

Array = NDArray[np.float64]
IntArray = NDArray[np.intp]

BIAS_PREFIX = "bias_"
"""A station's range-bias parameter is named ``bias_<station id>``."""


def bias_name(station_id: str) -> str:
    """Return the name of a station's range-bias parameter (``bias_7090``)."""
    return BIAS_PREFIX + station_id


@dataclass(frozen=True)
class LaserNetwork:
    """Laser stations and the object they range (module docstring).

    Attributes
    ----------
    stations : mapping of str to LaserStation
        By station id, in the order of the biases in a filter's state.
    com_km : float
        The object's centre-of-mass offset, km (subtracted from every range).
    bias_km, bias_sigma_km : mapping of str to float
        Each station's range-bias prior: mean and sigma, km (missing: 0 and 1 m).
    """

    stations: Mapping[str, LaserStation]
    com_km: float = lr.LAGEOS_COM_KM
    bias_km: Mapping[str, float] = field(default_factory=dict)
    bias_sigma_km: Mapping[str, float] = field(default_factory=dict)

    @property
    def ids(self) -> tuple[str, ...]:
        """The station ids, in order."""
        return tuple(self.stations)

    def prior(self, station_ids: Sequence[str]) -> tuple[Array, Array]:
        """Return the range-bias priors (mean, sigma) (k,) km of ``station_ids``."""
        mean = np.array([self.bias_km.get(s, 0.0) for s in station_ids], dtype=float)
        sigma = np.array([self.bias_sigma_km.get(s, 1e-3) for s in station_ids], dtype=float)
        return mean, sigma


@dataclass(frozen=True)
class LaserPoints:
    """n ranges made ready for `predict`: where the stations are and the air (`LaserModels`)."""

    geometry: lr.LaserGeometry
    air: lr.LaserAtmosphere
    station: IntArray
    """Each range's station, its index in the network's ids (n,)."""
    com_km: float

    def predict(self, x: ArrayLike, bias_km: ArrayLike) -> lr.LaserRange:
        """Return the ranges' model at GCRF states ``x`` (n, 6) with the biases (nb,) km.

        ``bias_km`` holds the network's biases; each range takes its station's.
        """
        b = np.asarray(bias_km, dtype=float)[self.station]
        return lr.two_way_range(self.geometry, self.air, x, self.com_km, b)


class LaserModels:
    """The measurement model of one object's laser ranges from a network (module docstring).

    Parameters
    ----------
    network : LaserNetwork
        Stations, the object's centre-of-mass offset, bias priors.
    meteo : iterable of MeteoSample
        Surface meteorological records known from the start (more with `add_meteo`).
    eop : EarthOrientation, optional
        The Earth's orientation (default `eop.default()`).
    """

    kind = Kind.LASER_RANGE
    angle_mask = (False,)

    def __init__(self, network: LaserNetwork, meteo: Iterable[MeteoSample] = (),
                 eop: eop_.EarthOrientation | None = None) -> None:
        self.network = network
        self.eop = eop_.default() if eop is None else eop
        self._records: dict[str, list[MeteoSample]] = {s: [] for s in network.ids}
        self._series: dict[str, MeteoSeries] = {}
        self._models: dict[str, LaserStationModel] = {}
        self.add_meteo(meteo)

    @property
    def stations(self) -> Mapping[str, LaserStation]:
        """The network's stations by id."""
        return self.network.stations

    def add_meteo(self, samples: Iterable[MeteoSample]) -> None:
        """Take surface meteorological records (other stations' are ignored)."""
        for m in samples:
            if m.station in self._records:
                self._records[m.station].append(m)
                self._series.pop(m.station, None)

    def _meteo(self, station_id: str) -> MeteoSeries:
        s = self._series.get(station_id)
        if s is None:
            r = self._records[station_id]
            s = MeteoSeries.of([m.t for m in r], [m.pressure_hpa for m in r],
                               [m.temperature_k for m in r], [m.humidity_pct for m in r])
            self._series[station_id] = s
        return s

    def station_index(self, frame_ids: Sequence[str]) -> IntArray:
        """Return each id's index in the network (KeyError naming an unknown one)."""
        ids = {s: k for k, s in enumerate(self.network.ids)}
        unknown = sorted(set(frame_ids) - set(ids))
        if unknown:
            raise KeyError(f"station(s) {', '.join(unknown)} not in the laser network "
                           f"({', '.join(self.network.ids)})")
        return np.array([ids[f] for f in frame_ids], dtype=np.intp)

    def points(self, t: ArrayLike, frame_ids: Sequence[str]) -> LaserPoints:
        """Return `LaserPoints` of ranges at transmit epochs ``t`` from stations ``frame_ids``."""
        tt = np.atleast_1d(np.asarray(t, dtype=float))
        idx = self.station_index(frame_ids)
        stations = list(self.network.stations.values())
        g = lr.geometry(stations, idx, tt, self.eop)
        met = np.empty((3, tt.size))
        for k, sid in enumerate(self.network.ids):
            mine = idx == k
            if mine.any():
                *values, found = self._meteo(sid).at(tt[mine])
                fallback = standard_atmosphere(g.height_km[mine])
                met[:, mine] = np.where(found, values, fallback)
        wavelength = np.array([stations[k].wavelength_um for k in idx])
        air = lr.atmosphere(met[0], met[1], met[2], wavelength)
        return LaserPoints(g, air, idx, self.network.com_km)

    def parameters(self, frame_ids: Sequence[str]) -> tuple[str, ...]:
        """Return the bias parameters of the stations among ``frame_ids``, network order."""
        present = set(frame_ids)
        return tuple(bias_name(s) for s in self.network.ids if s in present)

    def prior(self, names: Sequence[str]) -> tuple[Array, Array]:
        """Return the priors (mean, sigma) km of the bias parameters ``names``."""
        return self.network.prior([n.removeprefix(BIAS_PREFIX) for n in names])

    def get(self, kind: int, frame_id: str) -> LaserStationModel | None:
        """Return station ``frame_id``'s model for the filter (None: unknown, other kind)."""
        if int(kind) != Kind.LASER_RANGE or frame_id not in self.network.stations:
            return None
        model = self._models.get(frame_id)
        if model is None:
            model = LaserStationModel(self, frame_id)
            self._models[frame_id] = model
        return model


class LaserStationModel:
    """One station's laser range for the sequential filter: ``h_and_H(x, t)``.

    ``x`` is the filter's state ``[r, v, bias_1 .. bias_nb, ...]`` (GCRF km, km/s, the
    network's biases km, then any further states); ``H`` has its length, 1 at this station's
    bias and 0 at the other states.
    """

    kind = Kind.LASER_RANGE
    angle_mask = (False,)

    def __init__(self, models: LaserModels, station_id: str) -> None:
        self.models = models
        self.station_id = station_id
        self.column = 6 + models.network.ids.index(station_id)

    def h_and_H(self, x: Array, t_s: float) -> tuple[Array, Array]:
        """Return (z (1,) km, H (1, len(x))) at the filter's state ``x`` at epoch ``t_s``."""
        p = self.models.points([t_s], [self.station_id])
        nb = len(self.models.network.ids)
        got = p.predict(x[None, :6], x[6:6 + nb])
        H = np.zeros((1, x.shape[0]))
        H[0, :6] = got.H[0]
        H[0, self.column] = 1.0
        return got.range_km, H

    def h(self, x: Array, t_s: float) -> Array:
        """Predicted range (1,) km."""
        return self.h_and_H(x, t_s)[0]

    def H(self, x: Array, t_s: float) -> Array:
        """Jacobian (1, len(x))."""
        return self.h_and_H(x, t_s)[1]

"""The troposphere's delay of laser light: Mendes-Pavlis zenith delay and FCULa mapping.

IERS Conventions (2010), section 9.2 (Petit and Luzum, IERS Technical Note 36), the ILRS
standard since 2007: the zenith delay of Mendes and Pavlis (2004, GRL 31, L14602) at the
laser's wavelength from the surface pressure, temperature and humidity,

    d_z = 0.002416579 f_h(lambda) P / f_s(phi, H)
          + 1e-4 (5.316 f_nh(lambda) - 3.759 f_h(lambda)) e / f_s(phi, H)     [m; P, e in hPa]

(f_h, f_nh the dispersion of the hydrostatic and non-hydrostatic parts, CO2 at 375 ppm;
f_s = 1 - 0.00266 cos 2 phi - 2.8e-7 H the gravity at the site), times the FCULa mapping
function of Mendes et al. (2002) of the elevation, the temperature, the latitude and the
height (a continued fraction of three terms, Table 9.1's coefficients). The water vapour
pressure is e = RH/100 x 6.11 x 10^(7.5 t / (237.3 + t)) hPa (t in deg C; Marini and
Murray 1973): its uncertainty moves the ~3 mm wet part of an optical delay by < 0.1 mm.

Meteorological data come with the measurements (CRD record 20): `MeteoSeries` holds a
station's and gives the values at any epoch, interpolated linearly between the records on
either side when both are within `MAX_METEO_AGE_S`, else the nearest one within it. Where
there is none (a session without record 20), the fallback is a standard atmosphere at the
station's height (`standard_atmosphere`: 1013.25 hPa and 15 deg C at sea level, a
6.5 K/km lapse rate, 50 % humidity), good to a few percent of the delay (~0.1 m at 20 deg
elevation): such points are counted by whoever makes them.

Units: the delay in km (the core's); pressure in hPa (= mbar, as CRD writes), temperature
in K, humidity in %, wavelength in um, heights in km, angles in rad.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

Array = NDArray[np.float64]

MAX_METEO_AGE_S = 1800.0
"""How far (s) a meteorological record is used from its epoch."""
CO2_PPM = 375.0
"""CO2 content of the air, ppm (the IAG value IERS 2010 recommends)."""
_K = (238.0185, 19990.975, 57.362, 579.55174)
"""Dispersion coefficients of the hydrostatic part, um^-2 (Mendes and Pavlis 2004)."""
_W = (295.235, 2.6422, -0.032380, 0.004028)
"""Dispersion coefficients of the non-hydrostatic part (um^0, um^2, um^4, um^6)."""
_FCULA = np.array([[12100.8e-7, 1729.5e-9, 319.1e-7, -1847.8e-11],
                   [30496.5e-7, 234.6e-8, -103.5e-6, -185.6e-10],
                   [6877.7e-5, 197.2e-7, -345.8e-5, 106.0e-9]])
"""FCULa coefficients a_ij (IERS 2010 Table 9.1): a_i = a_i0 + a_i1 t + a_i2 cos phi + a_i3 H
with t in deg C, H in m."""


def dispersion(wavelength_um: ArrayLike) -> tuple[Array, Array]:
    """Return f_h and f_nh, the hydrostatic and non-hydrostatic dispersion at a wavelength.

    Both about 1.0 at 532 nm (IERS 2010 eq. 9.14-9.15; `wavelength_um` in um).
    """
    s2 = 1.0 / np.asarray(wavelength_um, dtype=float) ** 2
    k0, k1, k2, k3 = _K
    co2 = 1.0 + 0.534e-6 * (CO2_PPM - 450.0)
    f_h = 0.01 * (k1 * (k0 + s2) / (k0 - s2) ** 2 + k3 * (k2 + s2) / (k2 - s2) ** 2) * co2
    w0, w1, w2, w3 = _W
    f_nh = 0.003101 * (w0 + 3.0 * w1 * s2 + 5.0 * w2 * s2**2 + 7.0 * w3 * s2**3)
    return f_h, f_nh


def water_vapour_hpa(temperature_k: ArrayLike, humidity_pct: ArrayLike) -> Array:
    """Return the water vapour pressure (hPa) of air at a temperature (K) and humidity (%)."""
    t = np.asarray(temperature_k, dtype=float) - 273.15
    out: Array = np.asarray(humidity_pct, dtype=float) / 100.0 * 6.11 * 10.0 ** (
        7.5 * t / (237.3 + t))
    return out


def zenith_delay_km(pressure_hpa: ArrayLike, vapour_hpa: ArrayLike, wavelength_um: ArrayLike,
                    lat_rad: ArrayLike, height_km: ArrayLike) -> Array:
    """Return the Mendes-Pavlis zenith delay (km) at a site (module docstring).

    Surface pressure and water vapour pressure in hPa (`water_vapour_hpa`), the laser's
    wavelength in um, the site's geodetic latitude (rad) and height (km). About 2.4 m at
    sea level.
    """
    f_h, f_nh = dispersion(wavelength_um)
    h_m = np.asarray(height_km, dtype=float) * 1000.0
    f_s = 1.0 - 0.00266 * np.cos(2.0 * np.asarray(lat_rad, dtype=float)) - 0.28e-6 * h_m
    d_m = (0.002416579 * f_h * np.asarray(pressure_hpa, dtype=float)
           + 1e-4 * (5.316 * f_nh - 3.759 * f_h) * np.asarray(vapour_hpa, dtype=float)) / f_s
    out: Array = d_m / 1000.0
    return out


def mapping(elevation_rad: ArrayLike, temperature_k: ArrayLike, lat_rad: ArrayLike,
            height_km: ArrayLike) -> Array:
    """Return the FCULa mapping function (slant / zenith delay) at an elevation (rad).

    Of the site's temperature (K), geodetic latitude (rad) and height (km); about 1/sin(el)
    (2.9 at 20 deg).
    """
    t_c = np.asarray(temperature_k, dtype=float) - 273.15
    cos_phi = np.cos(np.asarray(lat_rad, dtype=float))
    h_m = np.asarray(height_km, dtype=float) * 1000.0
    a1, a2, a3 = (c[0] + c[1] * t_c + c[2] * cos_phi + c[3] * h_m for c in _FCULA)
    s = np.sin(np.asarray(elevation_rad, dtype=float))
    out: Array = (1.0 + a1 / (1.0 + a2 / (1.0 + a3))) / (s + a1 / (s + a2 / (s + a3)))
    return out


def slant_delay_km(elevation_rad: ArrayLike, pressure_hpa: ArrayLike,
                   temperature_k: ArrayLike, humidity_pct: ArrayLike,
                   wavelength_um: ArrayLike, lat_rad: ArrayLike, height_km: ArrayLike) -> Array:
    """Return the one-way delay (km) of laser light at an elevation: zenith x mapping."""
    e = water_vapour_hpa(temperature_k, humidity_pct)
    out: Array = zenith_delay_km(pressure_hpa, e, wavelength_um, lat_rad, height_km) * \
        mapping(elevation_rad, temperature_k, lat_rad, height_km)
    return out


def standard_atmosphere(height_km: ArrayLike) -> tuple[Array, Array, Array]:
    """Return (pressure hPa, temperature K, humidity %) of a standard atmosphere at heights.

    The fallback when a station's meteorological data are missing: 1013.25 hPa and
    288.15 K at sea level, 6.5 K/km, 50 % relative humidity (the 1976 US standard
    atmosphere's troposphere).
    """
    h = np.asarray(height_km, dtype=float)
    t = 288.15 - 6.5 * h
    p = 1013.25 * (t / 288.15) ** 5.25588
    return p, t, np.full_like(h, 50.0)


@dataclass(frozen=True)
class MeteoSample:
    """Surface meteorological values at a station at one epoch (a CRD record 20).

    `t` Unix s (UTC), `station` the station id (its measurements' frame_id), pressure in
    hPa, temperature in K, relative humidity in %.
    """

    t: float
    station: str
    pressure_hpa: float
    temperature_k: float
    humidity_pct: float


@dataclass(frozen=True)
class MeteoSeries:
    """A station's surface meteorological records: epochs (Unix s, sorted) and values.

    `pressure_hpa`, `temperature_k`, `humidity_pct` are arrays of the epochs' length.
    """

    t: Array
    pressure_hpa: Array
    temperature_k: Array
    humidity_pct: Array

    @staticmethod
    def of(t: ArrayLike, pressure_hpa: ArrayLike, temperature_k: ArrayLike,
           humidity_pct: ArrayLike) -> MeteoSeries:
        """Return the series of records in any order (sorted by epoch; ties: the first)."""
        tt = np.asarray(t, dtype=float)
        order = np.argsort(tt, kind="stable")
        keep = np.ones(len(tt), bool)
        keep[1:] = np.diff(tt[order]) > 0
        idx = order[keep]
        return MeteoSeries(tt[idx], np.asarray(pressure_hpa, dtype=float)[idx],
                           np.asarray(temperature_k, dtype=float)[idx],
                           np.asarray(humidity_pct, dtype=float)[idx])

    def at(self, t: ArrayLike) -> tuple[Array, Array, Array, NDArray[np.bool_]]:
        """Return (pressure, temperature, humidity, found) at epochs `t` (module docstring).

        `found` is False where no record is within `MAX_METEO_AGE_S`; the values there
        are NaN (the caller's fallback fills them).
        """
        q = np.asarray(t, dtype=float)
        n = len(self.t)
        out = [np.full(q.shape, np.nan) for _ in range(3)]
        if n == 0:
            return out[0], out[1], out[2], np.zeros(q.shape, bool)
        j = np.searchsorted(self.t, q)  # self.t[j - 1] < q <= self.t[j]
        lo, hi = np.clip(j - 1, 0, n - 1), np.clip(j, 0, n - 1)
        age_lo, age_hi = np.abs(q - self.t[lo]), np.abs(self.t[hi] - q)
        ok_lo, ok_hi = age_lo <= MAX_METEO_AGE_S, age_hi <= MAX_METEO_AGE_S
        span = self.t[hi] - self.t[lo]
        w = np.where(span > 0, (q - self.t[lo]) / np.where(span > 0, span, 1.0), 0.0)
        w = np.where(ok_lo & ok_hi, np.clip(w, 0.0, 1.0),
                     np.where(ok_hi & ~ok_lo, 1.0, 0.0))
        found = ok_lo | ok_hi
        for k, v in enumerate((self.pressure_hpa, self.temperature_k, self.humidity_pct)):
            out[k] = np.where(found, v[lo] + w * (v[hi] - v[lo]), np.nan)
        return out[0], out[1], out[2], found

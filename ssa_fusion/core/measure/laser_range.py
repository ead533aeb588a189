"""Two-way laser range: the model of a normal point, vectorised over many points.

A laser station fires at the transmit epoch t (the measurement's stamp, UTC); the pulse
reaches the satellite's retro-reflectors after tau_up, and the station again after
tau_down, the station having moved with the Earth in between (~20 m in the 45 ms of a
LAGEOS range; ignoring it costs ~27 m). The measured "range" is half the two-way time of
flight times c (the ILRS convention). Its model at GCRF state x = (r, v) of the satellite's
centre of mass at t:

    c tau_up   = |r_b - s(t)|,                 r_b = r + v tau_up + a tau_up^2 / 2
    c tau_down = |r_b - s(t + tau_up + tau_down)|
    range      = c (tau_up + tau_down) / 2 + d_trop(el) + d_shapiro - com + bias

solved by fixed-point iteration (each step gains a factor |v|/c ~ 2e-5: 5 steps reach 1e-15
s), with a = -mu r / |r|^3 (the rest of the acceleration moves r_b by < 1 um) and the
station's GCRF position s(t) from its ITRF position at t (`laser_station`,
`frames.itrs_to_gcrs`) displaced by the solid Earth tides (`station_tides`), moved on by its
velocity and acceleration of the Earth's rotation (third order: < 1e-10 m). d_trop is the
one-way Mendes-Pavlis delay at the elevation of r_b seen from the station (`troposphere`;
the two legs' elevations differ by ~1e-5 rad), d_shapiro the mean of the two legs'
relativistic delays in the Earth's field, (1 + gamma) GM/c^2 ln((|s| + |r_b| + rho) / (|s| +
|r_b| - rho)) with gamma = 1 (~6 mm for LAGEOS), com the satellite's centre-of-mass offset
(the reflectors face the station: 0.251 m for LAGEOS, `LAGEOS_COM_KM`), bias a per-station
range bias (a parameter).

Jacobian: of the geometric part with respect to x (the light-time equations differentiated,
the station's motion included); the troposphere's and Shapiro's dependence on x (< 1e-5 of
the geometric one: a 7 m delay whose elevation moves by 1/6000 rad per km) is left out,
and the bias's column is 1. Units: km, km/s, s, rad; epochs Unix s (UTC).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ssa_fusion.core.base.constants import C_KM_S, MU_EARTH
from ssa_fusion.core.earth import eop as eop_
from ssa_fusion.core.earth.frames import ERA_RATE, cip_gcrs, gcrs_to_itrs_matrix, itrs_to_gcrs
from ssa_fusion.core.measure import troposphere
from ssa_fusion.core.measure.laser_station import LaserStation, geodetic_of
from ssa_fusion.core.measure.station_tides import solid_tide_displacement

Array = NDArray[np.float64]

LAGEOS_COM_KM = 0.251e-3
"""Centre-of-mass offset of LAGEOS-1 and -2 (retro-reflector array to centre), km."""
COM_OFFSETS_KM = {7603901: 0.251e-3, 9207002: 0.251e-3, 8606101: 1.010e-3,
                  7501001: 0.075e-3, 9306102: 0.075e-3, 8900103: 0.576e-3, 8903903: 0.576e-3,
                  1200601: 0.133e-3}
"""The ILRS's standard centre-of-mass offsets of the spherical geodetic satellites, km, by
ILRS id: LAGEOS-1 and -2, Ajisai, Starlette, Stella, Etalon-1 and -2, LARES."""
SHAPIRO_KM = 2.0 * MU_EARTH / C_KM_S**2
"""(1 + gamma) GM_Earth / c^2 with gamma = 1, km (8.87 mm)."""
ITERATIONS = 6
"""Fixed-point steps of each leg's light time."""


@dataclass(frozen=True)
class LaserGeometry:
    """Where the stations of n laser ranges are, at their transmit epochs.

    Attributes
    ----------
    t
        Transmit epochs (n,), Unix s (UTC).
    site
        The stations' reference points in the GCRF at `t`: position and velocity (n, 6),
        km, km/s.
    site_acceleration
        Their GCRF acceleration (the Earth's rotation), (n, 3) km/s^2.
    gcrs_to_itrs
        The GCRF -> ITRF rotation at `t`, (n, 3, 3).
    site_itrs
        The reference points in the ITRF (n, 3), km.
    lat, height_km
        Their geodetic latitude (rad) and height (km), (n,).
    """

    t: Array
    site: Array
    site_acceleration: Array
    gcrs_to_itrs: Array
    site_itrs: Array
    lat: Array
    height_km: Array


@dataclass(frozen=True)
class LaserAtmosphere:
    """The air at n ranges: pressure (hPa), temperature (K), humidity (%), wavelength (um)."""

    pressure_hpa: Array
    temperature_k: Array
    humidity_pct: Array
    wavelength_um: Array


@dataclass(frozen=True)
class LaserRange:
    """The model of n two-way ranges (one-way range units, km).

    Attributes
    ----------
    range_km
        The modelled range: c x two-way time of flight / 2 with every term (n,).
    H
        d range / d x, the GCRF state at the transmit epoch (n, 6): km/km, km/(km/s).
    H_bias
        d range / d bias (n,): ones.
    tau_up, tau_down
        The geometric light times of the two legs (n,), s.
    elevation
        The satellite's elevation at the station (n,), rad (geometric).
    troposphere_km, shapiro_km
        The one-way delays added (n,), km.
    """

    range_km: Array
    H: Array
    H_bias: Array
    tau_up: Array
    tau_down: Array
    elevation: Array
    troposphere_km: Array
    shapiro_km: Array


def geometry(stations: list[LaserStation], index: ArrayLike, t: ArrayLike,
             eop: eop_.EarthOrientation | None = None, tides: bool = True) -> LaserGeometry:
    """Return the `LaserGeometry` of ranges from `stations[index[i]]` at transmit epochs `t`.

    With `tides` the stations are where the solid Earth tides have moved them
    (`station_tides`: up to ~0.3 m).
    """
    tt = np.asarray(t, dtype=float)
    idx = np.asarray(index, dtype=np.intp)
    site_itrs = np.zeros((len(tt), 3))
    for k, st in enumerate(stations):
        mine = idx == k
        if mine.any():
            site_itrs[mine] = st.itrs(tt[mine])
    site = itrs_to_gcrs(np.concatenate([site_itrs, np.zeros_like(site_itrs)], -1), tt, eop)
    omega = ERA_RATE * cip_gcrs(tt, eop)
    lat, _, height = geodetic_of(site_itrs)
    if tides and tt.size:
        site[:, :3] += solid_tide_displacement(site[:, :3], lat, tt)
    return LaserGeometry(tt, site, np.cross(omega, site[:, 3:]), gcrs_to_itrs_matrix(tt, eop),
                         site_itrs, lat, height)


def atmosphere(pressure_hpa: ArrayLike, temperature_k: ArrayLike, humidity_pct: ArrayLike,
               wavelength_um: ArrayLike) -> LaserAtmosphere:
    """Return the `LaserAtmosphere` of per-range values (broadcast to one shape)."""
    p, t, h, w = np.broadcast_arrays(*(np.asarray(v, dtype=float) for v in (
        pressure_hpa, temperature_k, humidity_pct, wavelength_um)))
    return LaserAtmosphere(p, t, h, w)


def _norm(v: Array) -> Array:
    out: Array = np.linalg.norm(v, axis=-1)
    return out


def _dot(a: Array, b: Array) -> Array:
    out: Array = np.einsum("ij,ij->i", a, b)
    return out


def two_way_range(g: LaserGeometry, air: LaserAtmosphere | None, x: ArrayLike,
                  com_km: ArrayLike = LAGEOS_COM_KM, bias_km: ArrayLike = 0.0,
                  shapiro: bool = True) -> LaserRange:
    """Return the model of n two-way ranges (module docstring) at GCRF states `x` (n, 6).

    `x` is the satellite's centre of mass at each range's transmit epoch (km, km/s);
    `air` None leaves the troposphere out; `com_km` and `bias_km` (scalars or (n,)) are
    subtracted and added; `shapiro` False leaves the relativistic delay out.
    """
    xs = np.asarray(x, dtype=float).reshape(-1, 6)
    r, v = xs[:, :3], xs[:, 3:]
    a = -MU_EARTH * r / _norm(r)[:, None] ** 3
    s0, vs, acc = g.site[:, :3], g.site[:, 3:], g.site_acceleration
    tau_up = _norm(r - s0) / C_KM_S
    for _ in range(ITERATIONS):
        rb = r + v * tau_up[:, None] + 0.5 * a * tau_up[:, None] ** 2
        tau_up = _norm(rb - s0) / C_KM_S
    rb = r + v * tau_up[:, None] + 0.5 * a * tau_up[:, None] ** 2
    vb = v + a * tau_up[:, None]
    tau_dn = tau_up.copy()
    for _ in range(ITERATIONS):
        dt = (tau_up + tau_dn)[:, None]
        s_rx = s0 + vs * dt + 0.5 * acc * dt**2
        tau_dn = _norm(rb - s_rx) / C_KM_S
    dt = (tau_up + tau_dn)[:, None]
    s_rx = s0 + vs * dt + 0.5 * acc * dt**2
    v_rx = vs + acc * dt
    H = _jacobian(rb - s0, rb - s_rx, vb, v_rx, tau_up)
    el = _elevation(g, rb - s0)
    trop = np.zeros(len(xs)) if air is None else troposphere.slant_delay_km(
        el, air.pressure_hpa, air.temperature_k, air.humidity_pct, air.wavelength_um,
        g.lat, g.height_km)
    shap = np.zeros(len(xs))
    if shapiro:
        rb_n = _norm(rb)
        for leg_site in (s0, s_rx):
            rs, rho = _norm(leg_site), _norm(rb - leg_site)
            shap += 0.5 * SHAPIRO_KM * np.log((rs + rb_n + rho) / (rs + rb_n - rho))
    rng = 0.5 * C_KM_S * (tau_up + tau_dn) + trop + shap - np.asarray(com_km, dtype=float) \
        + np.asarray(bias_km, dtype=float)
    return LaserRange(np.broadcast_to(rng, tau_up.shape).copy(), H, np.ones(len(xs)),
                      tau_up, tau_dn, el, trop, shap)


def _jacobian(d_up: Array, d_dn: Array, vb: Array, v_rx: Array, tau_up: Array) -> Array:
    """Return d range / d (r, v) (n, 6) of the geometric two-way range.

    ``(c - u1.vb) dtau_up = u1.(dr + tau_up dv)`` and
    ``(c + u2.v_rx) dtau_dn = u2.(dr + tau_up dv) + u2.(vb - v_rx) dtau_up``, with u1, u2
    the unit vectors of the two legs; range = c (tau_up + tau_dn) / 2.
    """
    u1 = d_up / _norm(d_up)[:, None]
    u2 = d_dn / _norm(d_dn)[:, None]
    g_up = u1 / (C_KM_S - _dot(u1, vb))[:, None]  # dtau_up / dr
    k_dn = 1.0 / (C_KM_S + _dot(u2, v_rx))
    g_dn = k_dn[:, None] * (u2 + _dot(u2, vb - v_rx)[:, None] * g_up)  # dtau_dn / dr
    d_r = 0.5 * C_KM_S * (g_up + g_dn)
    return np.concatenate([d_r, d_r * tau_up[:, None]], -1)


def _elevation(g: LaserGeometry, d_gcrs: Array) -> Array:
    """Return the elevation (rad) of GCRF directions `d_gcrs` (n, 3) at the stations."""
    d = np.einsum("nij,nj->ni", g.gcrs_to_itrs, d_gcrs)
    up = np.stack([np.cos(g.lat) * np.cos(_lon(g)), np.cos(g.lat) * np.sin(_lon(g)),
                   np.sin(g.lat)], -1)
    out: Array = np.arcsin(np.clip(_dot(d, up) / _norm(d), -1.0, 1.0))
    return out


def _lon(g: LaserGeometry) -> Array:
    out: Array = np.arctan2(g.site_itrs[:, 1], g.site_itrs[:, 0])
    return out

"""The real Earth: time scales, Earth orientation, frames, refraction, Sun, stations.

UTC/TAI/TT/UT1 (`timescales`, pyerfa), IERS Earth-orientation parameters (`eop`), the GCRF,
ITRF, TEME and topocentric frames (`frames`, IAU 2006/2000A through pyerfa), tropospheric
refraction, the Sun's position and the Earth's shadow, the Sun and the Moon from JPL's DE421
and the Earth's rotation over a span for compiled code (`ephemeris`, `rotation_grid`), light
time, ground stations and their sensors and when they see an object. Imports only `base`.
"""

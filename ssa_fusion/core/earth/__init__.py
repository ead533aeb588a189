"""The real Earth: time scales, Earth orientation, frames, refraction, Sun, stations.

UTC/TAI/TT/UT1 (`timescales`, pyerfa), IERS Earth-orientation parameters (`eop`), the GCRF,
ITRF, TEME and topocentric frames (`frames`, IAU 2006/2000A through pyerfa), tropospheric
refraction, the Sun's position and the Earth's shadow, light time, ground stations and their
sensors and when they see an object. Imports only `base`.
"""

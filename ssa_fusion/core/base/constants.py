"""Physical constants used by the core (km, s, rad)."""

MU_EARTH = 398600.4418
"""Earth gravitational parameter, km^3/s^2 (WGS-84 / EGM-96)."""

R_EARTH = 6378.137
"""Earth equatorial radius, km (WGS-84)."""

J2 = 1.08262668e-3
"""Earth second zonal harmonic (EGM-96), dimensionless."""
J3 = -2.5324105e-6
"""Earth third zonal harmonic (EGM2008, unnormalised: -sqrt(7) C30), dimensionless."""
J4 = -1.6198976e-6
"""Earth fourth zonal harmonic (EGM2008, unnormalised: -3 C40), dimensionless."""

OMEGA_EARTH = 7.292115146706979e-5
"""Earth rotation rate, rad/s (IERS)."""

WGS84_F = 1.0 / 298.257223563
"""WGS-84 flattening."""

MU_EARTH_MOON = 0.012150585609624
"""Earth-Moon CR3BP mass ratio m2 / (m1 + m2), dimensionless."""

G0 = 9.80665
"""Standard gravity, m/s^2 (used by the pendulum)."""

C_KM_S = 299792.458
"""Speed of light in vacuum, km/s (exact, SI)."""

ARCSEC = 3.141592653589793 / (180.0 * 3600.0)
"""One arc second, rad."""

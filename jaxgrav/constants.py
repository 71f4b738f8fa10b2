"""Physical constants and unit factors used throughout jaxgrav.

All values are SI unless the name says otherwise. The reference ellipsoid is WGS84
(NIMA TR8350.2, 3rd ed.); the normal-gravity constants are the defining ones of the
WGS84 ellipsoid, as used by boule's ``WGS84``.
"""

import math

# --- WGS84 defining and derived parameters -----------------------------------------
WGS84_A = 6378137.0
"""Semi-major axis (m)."""
WGS84_F = 1.0 / 298.257223563
"""Flattening (dimensionless)."""
WGS84_GM = 3.986004418e14
"""Geocentric gravitational constant including the atmosphere (m³/s²)."""
WGS84_OMEGA = 7.292115e-5
"""Angular velocity of the Earth (rad/s)."""
WGS84_B = WGS84_A * (1.0 - WGS84_F)
"""Semi-minor axis (m)."""
WGS84_E2 = WGS84_F * (2.0 - WGS84_F)
"""First eccentricity squared (dimensionless)."""
WGS84_LINEAR_ECCENTRICITY = math.sqrt(WGS84_A**2 - WGS84_B**2)
"""Linear eccentricity E = sqrt(a² − b²) (m)."""
WGS84_MEAN_RADIUS = (2.0 * WGS84_A + WGS84_B) / 3.0
"""Arithmetic mean radius R1 = (2a + b)/3 (m)."""

EARTH_RATE = WGS84_OMEGA
"""Earth rotation rate Ω (rad/s); alias of :data:`WGS84_OMEGA`."""
G_NEWTON = 6.6743e-11
"""Newtonian constant of gravitation, CODATA 2018 (m³ kg⁻¹ s⁻²)."""

# --- Unit factors: multiply a value in the named unit to get SI ------------------
MGAL = 1.0e-5
"""1 mGal in m/s²."""
MICROGAL = 1.0e-8
"""1 µGal in m/s²."""
ARCSEC = math.pi / (180.0 * 3600.0)
"""1 arcsecond in radians."""
ARCMIN = math.pi / (180.0 * 60.0)
"""1 arcminute in radians."""
KNOT = 1852.0 / 3600.0
"""1 knot in m/s."""
NANOTESLA = 1.0e-9
"""1 nT in tesla."""
DEG = math.pi / 180.0
"""1 degree in radians."""

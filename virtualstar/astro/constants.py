"""Physical and conventional constants, each with its source."""

import math

import erfa

#: Speed of light in m/s (exact, SI definition; same value as erfa.CMPS).
C_M_S = erfa.CMPS
#: Seconds per day.
DAY_S = erfa.DAYSEC
#: Unix epoch 1970-01-01T00:00:00 UTC as a Julian date.
UNIX_EPOCH_JD = 2440587.5
#: Julian date of J2000.0 (erfa.DJ00).
J2000_JD = erfa.DJ00
#: Mean angular velocity of the Earth in rad/s, IERS Conventions (2010) table 1.1.
EARTH_ROTATION_RAD_S = 7.292115e-5
#: Milliarcseconds per radian.
MAS_PER_RAD = 180.0 / math.pi * 3_600_000.0
#: Arcseconds per radian.
ARCSEC_PER_RAD = 180.0 / math.pi * 3600.0
#: The sky's apparent turn (the sidereal rate) in arcseconds per second: 15.04″/s.
SIDEREAL_RATE_ARCSEC_S = EARTH_ROTATION_RAD_S * ARCSEC_PER_RAD
#: Hipparcos catalogue epoch (Julian year, TT), ESA SP-1200 vol. 1 §1.2.
HIPPARCOS_EPOCH_JYEAR = 1991.25
#: WGS84 reference ellipsoid identifier for erfa.gd2gc.
WGS84 = 1

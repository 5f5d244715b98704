"""Astronomy: from a target, a site and a time to where the mount must point.

Public API (radians and rad/s inside, degrees at user interfaces):

    site = load_site()                                   # Site (TOML, $VIRTUALSTAR_SITE)
    times = UtcTimes.from_unix_us(t_us)                  # mount time → UTC two-part JD
    obs = IcrsStar.from_catalog(star).observe(times, site)
    obs.az_rad, obs.el_rad, obs.az_rate_rad_s, obs.el_rate_rad_s
"""

from .earth_orientation import EarthOrientation
from .exceptions import (
    AstroError,
    CoordinateParseError,
    EarthOrientationWarning,
    SatelliteError,
    SiteError,
    TimeParseError,
    UnknownTarget,
    UnreachablePath,
)
from .observed import Observation, enu_to_azel, observe_enu
from .satellites import Satellite, SatelliteState
from .site import Site, load_site, parse_site_option
from .stars import IcrsStar
from .timescales import UtcTimes

__all__ = [
    "AstroError",
    "CoordinateParseError",
    "EarthOrientation",
    "EarthOrientationWarning",
    "IcrsStar",
    "Observation",
    "Satellite",
    "SatelliteError",
    "SatelliteState",
    "Site",
    "SiteError",
    "TimeParseError",
    "UnknownTarget",
    "UnreachablePath",
    "UtcTimes",
    "enu_to_azel",
    "load_site",
    "observe_enu",
    "parse_site_option",
]

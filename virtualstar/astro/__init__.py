"""Astronomy: from a target, a site and a time to where the mount must point.

Public API (radians and rad/s inside, degrees at user interfaces):

    site = load_site()                                   # Site (TOML, $VIRTUALSTAR_SITE)
    target = resolve_target("Vega")                      # or IcrsStar(ra_deg, dec_deg),
    #   IcrsStar.from_catalog(star), SolarSystemBody("moon"), FixedAltAz(az_deg, el_deg),
    #   Satellite.from_record(tle_record) / Satellite.from_tle(l1, l2, name)
    obs = observe_mount_times(target, t_us, site)        # t_us: int64 µs since 1970 UTC
    obs.az_rad, obs.el_rad, obs.az_rate_rad_s, obs.el_rate_rad_s
    mount_az = unwrap_azimuth(obs.az_rad, limits=MountLimits(), current_az_rad=...)
    find_events(target, site, start, 86400.0); satellite_passes(sat, site, start, end)
    plan_slew(...); plan_keyhole(...)
"""

from .altaz import Horizon, KeyholePlan, MountLimits, elevation_ok, plan_keyhole, unwrap_azimuth
from .avoidance import (
    AvoidanceZones,
    ZoneHit,
    avoidance_from_options,
    check_places,
    load_horizon_file,
    slew_route,
    zone_mask,
)
from .bodies import BODY_SEGMENTS, SolarSystemBody
from .earth_orientation import EarthOrientation
from .events import Event, Pass, find_events, satellite_passes
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
from .slew import SlewPlan, TrapezoidProfile, plan_slew, plan_slew_to_target, trapezoid
from .stars import IcrsStar
from .targets import (
    FixedAltAz,
    Target,
    observe_mount_times,
    parse_altaz,
    parse_radec,
    resolve_target,
)
from .timescales import UtcTimes, iso_utc

__all__ = [
    "AstroError",
    "AvoidanceZones",
    "BODY_SEGMENTS",
    "CoordinateParseError",
    "EarthOrientation",
    "EarthOrientationWarning",
    "Event",
    "FixedAltAz",
    "Horizon",
    "IcrsStar",
    "KeyholePlan",
    "MountLimits",
    "Observation",
    "Pass",
    "Satellite",
    "SatelliteError",
    "SatelliteState",
    "Site",
    "SiteError",
    "SlewPlan",
    "SolarSystemBody",
    "Target",
    "TimeParseError",
    "TrapezoidProfile",
    "UnknownTarget",
    "UnreachablePath",
    "UtcTimes",
    "iso_utc",
    "ZoneHit",
    "avoidance_from_options",
    "check_places",
    "elevation_ok",
    "enu_to_azel",
    "find_events",
    "load_horizon_file",
    "load_site",
    "observe_enu",
    "observe_mount_times",
    "parse_altaz",
    "parse_radec",
    "parse_site_option",
    "plan_keyhole",
    "plan_slew",
    "plan_slew_to_target",
    "resolve_target",
    "satellite_passes",
    "slew_route",
    "trapezoid",
    "unwrap_azimuth",
    "zone_mask",
]

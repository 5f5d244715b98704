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

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
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

# Each public name's module. The names are imported when first used (PEP 562), so that a
# process that needs only part of the astronomy pays only for that part: the Alpaca and INDI
# façades' equatorial conversions need ERFA alone, not scipy's splines nor numba's SGP4
# kernels (~0.8 s of CPU at each start).
_NAMES_IN: dict[str, tuple[str, ...]] = {
    "altaz": (
        "Horizon", "KeyholePlan", "MountLimits", "elevation_ok", "plan_keyhole", "unwrap_azimuth"
    ),
    "avoidance": (
        "AvoidanceZones", "ZoneHit", "avoidance_from_options", "check_places",
        "load_horizon_file", "slew_route", "zone_mask"
    ),
    "bodies": ("BODY_SEGMENTS", "SolarSystemBody"),
    "earth_orientation": ("EarthOrientation",),
    "events": ("Event", "Pass", "find_events", "satellite_passes"),
    "exceptions": (
        "AstroError", "CoordinateParseError", "EarthOrientationWarning", "SatelliteError",
        "SiteError", "TimeParseError", "UnknownTarget", "UnreachablePath"
    ),
    "observed": ("Observation", "enu_to_azel", "observe_enu"),
    "satellites": ("Satellite", "SatelliteState"),
    "site": ("Site", "load_site", "parse_site_option"),
    "slew": ("SlewPlan", "TrapezoidProfile", "plan_slew", "plan_slew_to_target", "trapezoid"),
    "stars": ("IcrsStar",),
    "targets": (
        "FixedAltAz", "Target", "observe_mount_times", "parse_altaz", "parse_radec",
        "resolve_target"
    ),
    "timescales": ("UtcTimes", "iso_utc"),
}
_MODULE_OF = {name: module for module, names in _NAMES_IN.items() for name in names}


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


def __getattr__(name: str) -> Any:
    module = _MODULE_OF.get(name)
    if module is None:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    value = getattr(importlib.import_module(f".{module}", __name__), name)
    globals()[name] = value  # later lookups skip this function
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(__all__))

"""Sun and Moon zones and the horizon profile, checked against astropy's Sun and Moon.

The Sun's and Moon's places come from astropy (get_body → AltAz with the site's
weather), an implementation independent of virtualstar.astro (which uses skyfield's
ephemeris through ERFA-style observed places).
"""

from __future__ import annotations

import math

import astropy.units as u
import numpy as np
import pytest
from astropy.coordinates import AltAz, EarthLocation, get_body
from astropy.time import Time
from astropy.utils import iers

from virtualstar.astro import (
    AvoidanceZones,
    Horizon,
    MountLimits,
    SiteError,
    UtcTimes,
    check_places,
    load_horizon_file,
    load_site,
    plan_slew,
    slew_route,
)

iers.conf.auto_download = False

NOON = "2024-06-21T11:00:00Z"  # Poznań, the Sun high in the south
SITE = load_site()


def astropy_body(name: str, t_us: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Return astropy's observed az, el (rad) of the Sun or Moon at mount times."""
    t = Time(np.asarray(t_us) / 1e6, format="unix", scale="utc")
    loc = EarthLocation.from_geodetic(SITE.lon_deg * u.deg, SITE.lat_deg * u.deg,
                                      SITE.height_m * u.m)
    frame = AltAz(obstime=t, location=loc, pressure=SITE.pressure_hpa * u.hPa,
                  temperature=SITE.temperature_c * u.deg_C, relative_humidity=SITE.humidity,
                  obswl=SITE.wavelength_um * u.micron)
    aa = get_body(name, t, loc).transform_to(frame)
    return aa.az.rad, aa.alt.rad


def offset(az: float, el: float, distance_deg: float, bearing_deg: float) -> tuple[float, float]:
    """Return the direction `distance_deg` from (az, el) towards `bearing_deg` (rad)."""
    import erfa

    # work in a frame where az/el are longitude/latitude: erfa's spherical offset
    d, b = math.radians(distance_deg), math.radians(bearing_deg)
    lat = math.asin(math.sin(el) * math.cos(d) + math.cos(el) * math.sin(d) * math.cos(b))
    lon = az + math.atan2(math.sin(b) * math.sin(d) * math.cos(el),
                          math.cos(d) - math.sin(el) * math.sin(lat))
    assert abs(math.degrees(float(erfa.seps(az, el, lon, lat))) - distance_deg) < 1e-9
    return lon, lat


def noon_us() -> int:
    return int(UtcTimes.from_iso([NOON]).to_unix_us()[0])


def test_a_direction_20_deg_from_the_sun_is_inside_the_30_deg_zone_and_the_distance_is_right():
    t = noon_us()
    saz, sel = (float(x[0]) for x in astropy_body("sun", np.array([t])))
    near = offset(saz, sel, 20.0, 90.0)
    far = offset(saz, sel, 31.0, 90.0)
    zones = AvoidanceZones()
    hit = check_places(np.array([far[0], near[0]]), np.array([far[1], near[1]]),
                       np.array([t, t]), zones, SITE)
    assert hit is not None and hit.zone == "sun" and hit.index == 1
    assert hit.separation_deg == pytest.approx(20.0, abs=0.01)  # skyfield vs astropy
    assert "20.00° from the Sun" in hit.describe("Vega")
    assert check_places(np.array([far[0]]), np.array([far[1]]), np.array([t]), zones,
                        SITE) is None


def test_a_moon_zone_applies_only_when_configured():
    t = int(UtcTimes.from_iso(["2024-03-16T18:00:00Z"]).to_unix_us()[0])  # first quarter, high
    maz, mel = (float(x[0]) for x in astropy_body("moon", np.array([t])))
    assert math.degrees(mel) > 30.0
    near = offset(maz, mel, 5.0, 0.0)
    args = (np.array([near[0]]), np.array([near[1]]), np.array([t]))
    assert check_places(*args, AvoidanceZones(sun_radius_deg=0.0), SITE, horizon=False) is None
    hit = check_places(*args, AvoidanceZones(moon_radius_deg=10.0), SITE, horizon=False)
    assert hit is not None and hit.zone == "moon"
    assert hit.separation_deg == pytest.approx(5.0, abs=0.05)


def min_sun_separation_deg(points: list[tuple[float, float]], t_us: int,
                           limits: MountLimits) -> float:
    """The closest the mount's own path (both axes' trapezoids) comes to astropy's Sun."""
    import erfa

    worst = 180.0
    t0 = t_us
    for (a0, e0), (a1, e1) in zip(points[:-1], points[1:], strict=True):
        plan = plan_slew(a0, e0, a1, e1, limits)
        t_s, az, el = plan.sample(0.25)
        t = t0 + np.round(t_s * 1e6).astype(np.int64)
        saz, sel = astropy_body("sun", t)
        worst = min(worst, float(np.degrees(erfa.seps(az, el, saz, sel)).min()))
        t0 += int(plan.duration_s * 1e6)
    return worst


def test_a_slew_across_the_sun_takes_a_detour_that_keeps_out_of_the_zone():
    t = noon_us()
    limits = MountLimits()
    saz, sel = (float(x[0]) for x in astropy_body("sun", np.array([t])))
    # from 50° east of the Sun to 50° west of it, at the Sun's elevation: straight through
    start = (saz - math.radians(50 / math.cos(sel)), sel)
    end = (saz + math.radians(50 / math.cos(sel)), sel)
    assert min_sun_separation_deg([start, end], t, limits) < 30.0
    legs, hit = slew_route(*start, *end, t, limits, AvoidanceZones(), SITE)
    assert hit is None and len(legs) > 1 and legs[-1] == end
    assert min_sun_separation_deg([start, *legs], t, limits) >= 30.0


def test_a_slew_with_no_way_around_is_refused_with_the_first_place_it_would_enter():
    t = noon_us()
    saz, sel = (float(x[0]) for x in astropy_body("sun", np.array([t])))
    start = (saz - math.radians(35 / math.cos(sel)), sel)
    end = offset(saz, sel, 10.0, 0.0)  # the target itself is inside the zone
    legs, hit = slew_route(*start, *end, t, MountLimits(), AvoidanceZones(), SITE)
    assert legs == [] and hit is not None and hit.zone == "sun"


def test_the_horizon_profile_is_read_and_interpolated_through_north(tmp_path):
    path = tmp_path / "horizon.txt"
    path.write_text("# trees\n350 20\n10 10  # north\n\n180, 5\n")
    zones = AvoidanceZones(horizon=load_horizon_file(path), el_min_deg=7.0)
    az = np.radians([0.0, 10.0, 180.0, 95.0])
    assert zones.min_el_deg(az) == pytest.approx([15.0, 10.0, 7.0, 7.5])
    t = np.full(4, noon_us())
    hit = check_places(az, np.radians([14.0, 11.0, 60.0, 60.0]), t, zones,
                       SITE.without_refraction())
    assert hit.zone == "horizon" and hit.index == 0 and hit.limit_deg == pytest.approx(15.0)


@pytest.mark.parametrize(("text", "words"), [
    ("90\n", "line 1"),
    ("90 ten\n", "expected two numbers"),
    ("400 10\n", "azimuth 400"),
    ("90 95\n", "elevation 95"),
    ("# nothing\n", "no points"),
    ("0 5\n360 6\n", "appears twice"),
])
def test_a_bad_horizon_file_names_the_line_and_what_is_expected(tmp_path, text, words):
    path = tmp_path / "h.txt"
    path.write_text(text)
    with pytest.raises(SiteError, match=words):
        load_horizon_file(path)


def test_zone_radii_outside_0_to_90_are_refused():
    with pytest.raises(ValueError, match="sun_radius_deg"):
        AvoidanceZones(sun_radius_deg=-1)
    with pytest.raises(ValueError, match="moon_radius_deg"):
        AvoidanceZones(moon_radius_deg=120)
    assert Horizon((0.0,), (5.0,)).min_el_rad(np.array([1.0])) == pytest.approx(math.radians(5))


def test_a_mount_inside_the_zone_may_leave_it_but_not_by_crossing_the_sun():
    t = noon_us()
    saz, sel = (float(x[0]) for x in astropy_body("sun", np.array([t])))
    def same_el(sep_deg: float, side: float) -> tuple[float, float]:
        # a place at the Sun's elevation sep_deg from it: moving in azimuth between two of
        # them goes straight through the Sun
        d_az = 2 * math.asin(math.sin(math.radians(sep_deg) / 2) / math.cos(sel))
        return saz + side * d_az, sel

    start = same_el(25.0, -1)  # inside, on one side
    across = same_el(40.0, +1)  # outside, on the other side
    away = same_el(45.0, -1)  # outside, further on the first side
    limits, zones = MountLimits(), AvoidanceZones()
    assert min_sun_separation_deg([start, across], t, limits) < 5.0  # straight = through it
    legs, hit = slew_route(*start, *across, t, limits, zones, SITE)
    assert hit is not None or min_sun_separation_deg([start, *legs], t, limits) >= 24.9
    legs, hit = slew_route(*start, *away, t, limits, zones, SITE)
    assert hit is None and legs == [away]  # leaving straight away from it is fine


def test_the_stow_may_lie_inside_the_zone_but_the_way_there_goes_no_deeper():
    t = noon_us()
    saz, sel = (float(x[0]) for x in astropy_body("sun", np.array([t])))
    stow = offset(saz, sel, 20.0, 0.0)  # the park position, 20° from the Sun
    start = offset(saz, sel, 60.0, 0.0)
    limits, zones = MountLimits(), AvoidanceZones()
    legs, hit = slew_route(*start, *stow, t, limits, zones, SITE)
    assert hit is not None  # not exempt: refused
    legs, hit = slew_route(*start, *stow, t, limits, zones, SITE, target_exempt=True)
    assert hit is None
    assert min_sun_separation_deg([start, *legs], t, limits) >= 19.9

"""Pointing runs pick no star behind the server's horizon profile or near the Sun."""

from __future__ import annotations

import astropy.units as u
import numpy as np
from astropy.coordinates import AltAz, EarthLocation, SkyCoord
from astropy.time import Time
from astropy.utils import iers

from virtualstar.astro import load_site
from virtualstar.cli.pointing_run import plan_for_server

iers.conf.auto_download = False


def test_the_planned_stars_all_stand_above_the_servers_horizon_profile():
    site = load_site()
    wall = {"az_deg": [0.0, 80.0, 90.0, 270.0, 280.0], "el_deg": [10.0, 10.0, 45.0, 45.0, 10.0]}
    status = {"site": {"lat_deg": site.lat_deg, "lon_deg": site.lon_deg,
                       "height_m": site.height_m, "pressure_hpa": site.pressure_hpa,
                       "temperature_c": site.temperature_c, "humidity": site.humidity},
              "mount_time_utc": "2024-05-18T21:30:00Z",
              "safety": {"sun_radius_deg": 30.0, "moon_radius_deg": None, "el_min_deg": 5.0,
                         "horizon": wall}}
    stars = plan_for_server(status, 30, at_utc=None, min_el_deg=15.0)
    assert len(stars) == 30
    # astropy's places of the planned stars, against the wall interpolated here
    loc = EarthLocation.from_geodetic(site.lon_deg * u.deg, site.lat_deg * u.deg,
                                      site.height_m * u.m)
    frame = AltAz(obstime=Time("2024-05-18T21:30:00", scale="utc"), location=loc,
                  pressure=site.pressure_hpa * u.hPa, temperature=site.temperature_c * u.deg_C,
                  relative_humidity=site.humidity, obswl=site.wavelength_um * u.micron)
    aa = SkyCoord([s.ra_deg for s in stars] * u.deg, [s.dec_deg for s in stars] * u.deg
                  ).transform_to(frame)
    floor = np.interp(aa.az.deg, wall["az_deg"], wall["el_deg"], period=360.0)
    assert (aa.alt.deg >= floor).all()
    assert ((aa.az.deg > 90) & (aa.az.deg < 270)).any()  # the south is used, above the wall

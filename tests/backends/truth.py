"""Independent truth for the backend tests and benchmark: astropy and skyfield, shared IERS table."""

from __future__ import annotations

from datetime import UTC, datetime

import numpy as np
from astropy.utils import iers

# offline: astropy-iers-data's table, its predictions beyond it (the same as the VSS's)
iers.conf.auto_download = False
iers.conf.auto_max_age = None


def _site(doc):
    from virtualstar.astro import Site

    return Site(**doc["site"])


def _eop():
    from virtualstar.astro import EarthOrientation

    return EarthOrientation.from_astropy_iers_data()


def star_apparent(name: str, t_s: np.ndarray, doc) -> tuple[np.ndarray, np.ndarray]:
    """astropy's topocentric apparent RA/Dec of date (TETE at the site), degrees."""
    import astropy.units as u
    from astropy.coordinates import TETE, Distance, EarthLocation, SkyCoord
    from astropy.time import Time
    from astropy.utils import iers

    from catalogs import bright_stars

    iers.conf.auto_download = False
    iers.conf.auto_max_age = None
    s = bright_stars().lookup(name)
    site = doc["site"]
    star = SkyCoord(ra=s.ra_deg * u.deg, dec=s.dec_deg * u.deg,
                    pm_ra_cosdec=s.pm_ra_cosdec_mas_yr * u.mas / u.yr,
                    pm_dec=s.pm_dec_mas_yr * u.mas / u.yr,
                    distance=Distance(parallax=s.parallax_mas * u.mas),
                    radial_velocity=(s.rv_km_s or 0.0) * u.km / u.s,
                    obstime=Time(s.epoch_jyear, format="jyear", scale="tcb"), frame="icrs")
    t = Time(t_s, format="unix", scale="utc")
    loc = EarthLocation.from_geodetic(site["lon_deg"] * u.deg, site["lat_deg"] * u.deg,
                                      site["height_m"] * u.m)
    te = star.apply_space_motion(new_obstime=t).transform_to(TETE(obstime=t, location=loc))
    return te.ra.deg, te.dec.deg


def satellite_apparent(tle, t_s: np.ndarray, doc) -> tuple[np.ndarray, np.ndarray]:
    """skyfield's topocentric apparent RA/Dec of date of the TLE, degrees (shared IERS table)."""
    from skyfield.api import EarthSatellite, wgs84

    from virtualstar.astro.bodies import skyfield_context

    sf = skyfield_context(_eop())
    sat = EarthSatellite(tle[1], tle[2], tle[0], sf.ts)
    earth = sf.ephemeris["earth"]
    site = doc["site"]
    here = earth + wgs84.latlon(site["lat_deg"], site["lon_deg"], site["height_m"])
    ts = sf.ts.from_datetimes([datetime.fromtimestamp(float(x), tz=UTC) for x in t_s])
    ra, dec, _ = here.at(ts).observe(earth + sat).apparent().radec(epoch="date")
    return ra.hours * 15.0, dec.degrees


def sky_errors_arcsec(samples, truth) -> np.ndarray:
    """Great-circle distance (arcsec) of each reported place from the truth at its time."""
    s = np.asarray(samples, float)
    ra, dec = truth
    d_ra = ((s[:, 1] * 15.0 - ra + 180.0) % 360.0 - 180.0) * np.cos(np.radians(dec))
    return np.hypot(d_ra, s[:, 2] - dec) * 3600.0


def hour_angles_deg(samples, doc) -> np.ndarray:
    """Local apparent hour angle (astropy's sidereal time) of reported places, degrees."""
    import astropy.units as u
    from astropy.time import Time

    s = np.asarray(samples, float)
    last = Time(s[:, 0], format="unix", scale="utc").sidereal_time(
        "apparent", longitude=doc["site"]["lon_deg"] * u.deg).deg
    return (last - s[:, 1] * 15.0 + 180.0) % 360.0 - 180.0


def observed_azel_deg(samples, doc) -> tuple[np.ndarray, np.ndarray]:
    """astropy's observed az/el of reported places of date at their times."""
    import astropy.units as u
    from astropy.coordinates import TETE, AltAz, EarthLocation, SkyCoord
    from astropy.time import Time

    s = np.asarray(samples, float)
    site = doc["site"]
    loc = EarthLocation.from_geodetic(site["lon_deg"] * u.deg, site["lat_deg"] * u.deg,
                                      site["height_m"] * u.m)
    t = Time(s[:, 0], format="unix", scale="utc")
    c = SkyCoord(s[:, 1] * 15.0 * u.deg, s[:, 2] * u.deg, frame=TETE(obstime=t, location=loc))
    aa = c.transform_to(AltAz(obstime=t, location=loc))
    return aa.az.deg, aa.alt.deg




def sun_separation_deg(samples, doc) -> np.ndarray:
    """astropy's angle (deg) between reported places of date and the Sun, each at its time."""
    import astropy.units as u
    from astropy.coordinates import TETE, EarthLocation, SkyCoord, get_body
    from astropy.time import Time

    s = np.asarray(samples, float)
    site = doc["site"]
    loc = EarthLocation.from_geodetic(site["lon_deg"] * u.deg, site["lat_deg"] * u.deg,
                                      site["height_m"] * u.m)
    t = Time(s[:, 0], format="unix", scale="utc")
    frame = TETE(obstime=t, location=loc)
    places = SkyCoord(s[:, 1] * 15.0 * u.deg, s[:, 2] * u.deg, frame=frame)
    sun = get_body("sun", t, location=loc).transform_to(frame)
    return places.separation(sun).deg

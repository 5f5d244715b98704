"""Independent truth for the VSS and planning tests: observed places from astropy, sky distances."""

from __future__ import annotations

import numpy as np
from astropy.utils import iers

iers.conf.auto_download = False


def observed_frame(t_us: np.ndarray, site):
    """astropy's observed (refracted) AltAz frame of the site at mount times (UTC µs)."""
    import astropy.units as u
    from astropy.coordinates import AltAz, EarthLocation
    from astropy.time import Time

    t = Time(np.asarray(t_us) / 1e6, format="unix", scale="utc")
    loc = EarthLocation.from_geodetic(site.lon_deg * u.deg, site.lat_deg * u.deg, site.height_m * u.m)
    return AltAz(obstime=t, location=loc, pressure=site.pressure_hpa * u.hPa,
                 temperature=site.temperature_c * u.deg_C, relative_humidity=site.humidity,
                 obswl=site.wavelength_um * u.micron)


#: Many instants: astropy on a grid this far apart, a cubic spline of its unit vectors between
#: (a star turns ≤ 15″/s: the spline's own error is ~1e-8″; measured ≤ 3.3 µas from astropy
#: at each of 3 000 instants, astropy's own rounding of a Unix time in seconds to 0.24 µs).
#: astropy costs ~0.35 ms an instant: a 10 Hz encoder stream of minutes, a second or more.
STAR_GRID_US = 10_000_000


def star_truth(name: str, t_us: np.ndarray, site) -> tuple[np.ndarray, np.ndarray]:
    """Return astropy's observed az, el (deg) of a catalog star at mount times (UTC µs).

    Fewer instants than grid nodes are computed each; more, on the STAR_GRID_US grid."""
    from scipy.interpolate import CubicSpline

    t_us = np.atleast_1d(np.asarray(t_us, np.int64))
    lo, hi = int(t_us.min()), int(t_us.max())
    grid = np.arange(lo - 2 * STAR_GRID_US, hi + 3 * STAR_GRID_US, STAR_GRID_US, dtype=np.int64)
    if len(grid) >= len(t_us):
        return _star_truth_at(name, t_us, site)
    az, el = np.radians(_star_truth_at(name, grid, site))
    up = np.stack([np.cos(el) * np.sin(az), np.cos(el) * np.cos(az), np.sin(el)], -1)
    v = CubicSpline((grid - lo) * 1e-6, up, axis=0)((t_us - lo) * 1e-6)
    return (np.degrees(np.arctan2(v[:, 0], v[:, 1])) % 360.0,
            np.degrees(np.arctan2(v[:, 2], np.hypot(v[:, 0], v[:, 1]))))


def _star_truth_at(name: str, t_us: np.ndarray, site) -> tuple[np.ndarray, np.ndarray]:
    """astropy's observed az, el (deg) of a catalog star at each of the mount times."""
    import astropy.units as u
    from astropy.coordinates import Distance, SkyCoord
    from astropy.time import Time

    from catalogs import bright_stars

    s = bright_stars().lookup(name)
    star = SkyCoord(ra=s.ra_deg * u.deg, dec=s.dec_deg * u.deg,
                    pm_ra_cosdec=s.pm_ra_cosdec_mas_yr * u.mas / u.yr,
                    pm_dec=s.pm_dec_mas_yr * u.mas / u.yr,
                    distance=Distance(parallax=s.parallax_mas * u.mas),
                    radial_velocity=(s.rv_km_s or 0.0) * u.km / u.s,
                    obstime=Time(s.epoch_jyear, format="jyear", scale="tcb"), frame="icrs")
    frame = observed_frame(t_us, site)
    aa = star.apply_space_motion(new_obstime=frame.obstime).transform_to(frame)
    return aa.az.deg, aa.alt.deg


def radec_truth(ra_deg: float, dec_deg: float, t_us, site, step_us: int = 10_000):
    """Return astropy's observed az, el (deg) of an ICRS RA/Dec at mount times (UTC µs).

    Computed on a 10-ms grid and interpolated linearly: a star moves at most 15″/s, so
    the interpolation error stays below a microarcsecond, and 10 kHz samples cost little.
    """
    import astropy.units as u
    from astropy.coordinates import SkyCoord

    t_us = np.atleast_1d(np.asarray(t_us, np.int64))
    grid = np.arange(t_us.min() - step_us, t_us.max() + 2 * step_us, step_us)
    aa = SkyCoord(ra=ra_deg * u.deg, dec=dec_deg * u.deg, frame="icrs").transform_to(
        observed_frame(grid, site))
    az = np.degrees(np.unwrap(np.radians(aa.az.deg)))
    return np.interp(t_us, grid, az) % 360.0, np.interp(t_us, grid, aa.alt.deg)


def vega_truth(t_us: np.ndarray, site) -> tuple[np.ndarray, np.ndarray]:
    """Return astropy's observed az, el (deg) of Vega at mount times (UTC µs)."""
    return star_truth("Vega", t_us, site)


def skyfield_iss():
    """The bundled ISS elements as a skyfield satellite, and the skyfield context (offline)."""
    from skyfield.api import EarthSatellite

    from catalogs import load_tle_file, sample_tle_path, select_satellite
    from virtualstar.astro import EarthOrientation
    from virtualstar.astro.bodies import skyfield_context

    sf = skyfield_context(EarthOrientation.from_astropy_iers_data())
    rec = select_satellite(load_tle_file(sample_tle_path("stations")), "ISS")
    return EarthSatellite(rec.line1, rec.line2, rec.name, sf.ts), sf


def iss_truth(t_us: np.ndarray, site) -> tuple[np.ndarray, np.ndarray]:
    """Return skyfield's observed az, el (deg) of the ISS at mount times (UTC µs)."""
    sat, _ = skyfield_iss()
    return satellite_truth(sat, t_us, site)


def satellite_truth(sat, t_us: np.ndarray, site) -> tuple[np.ndarray, np.ndarray]:
    """Return skyfield's observed az, el (deg) of a satellite at mount times (UTC µs).

    `sat`: a skyfield EarthSatellite, (line1, line2) of its elements, or an sgp4 Satrec. The apparent
    direction (light time, aberration), as a telescope sees it, lifted by ERFA's
    refraction constants for the site's air (skyfield's own formula ignores humidity
    and wavelength: arcseconds at 20°); a site without air gets none.
    """
    from datetime import UTC, datetime

    import erfa
    from skyfield.api import EarthSatellite, wgs84

    _, sf = skyfield_iss()
    if isinstance(sat, tuple):
        sat = EarthSatellite(sat[0], sat[1], "truth", sf.ts)
    elif not isinstance(sat, EarthSatellite):
        sat = EarthSatellite.from_satrec(sat, sf.ts)
    earth = sf.ephemeris["earth"]
    observer = earth + wgs84.latlon(site.lat_deg, site.lon_deg, site.height_m)
    ts = sf.ts.from_datetimes([datetime.fromtimestamp(t / 1e6, tz=UTC) for t in t_us])
    alt, az, _ = observer.at(ts).observe(earth + sat).apparent().altaz()
    refa, refb = erfa.refco(site.pressure_hpa, site.temperature_c, site.humidity,
                            site.wavelength_um)
    tan_z = np.tan(np.pi / 2 - alt.radians)
    return az.degrees, alt.degrees + np.degrees(refa * tan_z + refb * tan_z ** 3)


def sky_sep_arcsec(az1, el1, az2, el2) -> np.ndarray:
    import erfa

    return np.degrees(erfa.seps(np.radians(az1), np.radians(el1), np.radians(az2),
                                np.radians(el2))) * 3600.0


def vega_rate_arcsec_s(t_us: int, site) -> float:
    """Return Vega's on-sky rate (arcsec/s) at mount time `t_us`, from astropy."""
    az, el = vega_truth(np.array([t_us, t_us + 1_000_000]), site)
    return float(sky_sep_arcsec(az[0], el[0], az[1], el[1]))

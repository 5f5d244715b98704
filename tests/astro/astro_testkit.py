"""Helpers shared by the astronomy tests (named tolerances, separations)."""

import erfa
import numpy as np

ONE_MAS_RAD = np.deg2rad(1 / 3_600_000)
ONE_ARCSEC_RAD = np.deg2rad(1 / 3600)


def sep_rad(az1, el1, az2, el2):
    """Angular separation between two az/el directions, radians."""
    return erfa.seps(az1, el1, az2, el2)


def atco13_azel(star, times, site, eop, pressure: float):
    """Exact per-point ERFA: space motion to each date with pmsafe (as astropy does), then
    atco13 (ICRS to observed in one call); (az, el) radians."""
    ra, dec = np.radians(star.ra_deg), np.radians(star.dec_deg)
    pmr = np.radians(star.pm_ra_cosdec_mas_yr / 3.6e6) / np.cos(dec)
    pmd = np.radians(star.pm_dec_mas_yr / 3.6e6)
    ep1 = erfa.epj2jd(star.epoch_jyear)
    tt1, tt2 = times.tt()
    ra0, dec0, _, _, px0, _ = erfa.pmsafe(ra, dec, pmr, pmd, star.parallax_mas / 1e3,
                                          star.rv_km_s, ep1[0], ep1[1], tt1, tt2)
    dut1, xp, yp = eop.interpolate(times.jd1, times.jd2)
    aob, zob, *_ = erfa.atco13(ra0, dec0, 0.0, 0.0, px0, 0.0, times.jd1, times.jd2, dut1,
                               site.lon_rad, site.lat_rad, site.height_m, xp, yp, pressure,
                               site.temperature_c, site.humidity, site.wavelength_um)
    return aob, np.pi / 2 - zob

"""Benchmark: one night of sidereal trajectory points (a star), ours vs astropy vs erfa.atco13.

    .venv/bin/python benchmarks/bench_astro_sidereal.py [--points 1000000]

Prints points per second for: ours (VirtualStar IcrsStar.observe, refraction on
and off), astropy's ICRS → AltAz with ErfaAstromInterpolator (300 s), and
plain per-point erfa.atco13 (run on fewer points, rate scaled), plus the
largest difference of ours from atco13 on the common points.
"""

from __future__ import annotations

import argparse
import timeit
import warnings

import erfa
import numpy as np

from virtualstar.astro import EarthOrientation, IcrsStar, Site, UtcTimes

VEGA = IcrsStar(279.23410832, 38.78299311, 201.02, 287.46, 128.93, -13.5, 1991.25, "Vega")
SITE = Site(lat_deg=52.3967, lon_deg=16.8786, height_m=85.0, pressure_hpa=1005.0,
            temperature_c=10.0, humidity=0.6)


def best_of(fn, repeat: int) -> float:
    """Return the best time of one call (seconds) over `repeat` calls."""
    return min(timeit.repeat(fn, repeat=repeat, number=1))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--points", type=int, default=1_000_000)
    parser.add_argument("--atco13-points", type=int, default=2_000)
    parser.add_argument("--repeat", type=int, default=3)
    args = parser.parse_args()
    n = args.points
    eop = EarthOrientation.from_astropy_iers_data()
    times = UtcTimes.from_jd(np.full(n, 2460384.5), 0.8 + np.linspace(0.0, 10.0 / 24, n))
    VEGA.observe(times[:1000], SITE, eop)  # warm caches (refraction table)

    ours = best_of(lambda: VEGA.observe(times, SITE, eop), args.repeat)
    ours_dry = best_of(lambda: VEGA.observe(times, SITE.without_refraction(), eop), args.repeat)

    import astropy.units as u
    from astropy.coordinates import AltAz, Distance, EarthLocation, SkyCoord
    from astropy.coordinates.erfa_astrom import ErfaAstromInterpolator, erfa_astrom
    from astropy.time import Time
    from astropy.utils import iers

    iers.conf.auto_download = False
    t_ap = Time(times.jd1, times.jd2, format="jd", scale="utc")
    loc = EarthLocation.from_geodetic(SITE.lon_deg, SITE.lat_deg, SITE.height_m)
    coo = SkyCoord(ra=VEGA.ra_deg * u.deg, dec=VEGA.dec_deg * u.deg,
                   distance=Distance(parallax=VEGA.parallax_mas * u.mas))
    frame = AltAz(obstime=t_ap, location=loc, pressure=SITE.pressure_hpa * u.hPa,
                  temperature=SITE.temperature_c * u.deg_C, relative_humidity=SITE.humidity,
                  obswl=SITE.wavelength_um * u.um)
    t_ap.delta_ut1_utc  # noqa: B018 - astropy's IERS look-up, outside the timing as for ours

    def astropy_run():
        with erfa_astrom.set(ErfaAstromInterpolator(300 * u.s)):
            coo.transform_to(frame)

    astropy_s = best_of(astropy_run, 1)

    m = args.atco13_points
    pick = np.linspace(0, n - 1, m).astype(int)
    sub = times[pick]
    dut1, xp, yp = eop.interpolate(sub.jd1, sub.jd2)
    ra, dec = np.radians(VEGA.ra_deg), np.radians(VEGA.dec_deg)

    def atco13_run():
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", erfa.ErfaWarning)
            return erfa.atco13(ra, dec, 0.0, 0.0, VEGA.parallax_mas / 1e3, 0.0, sub.jd1, sub.jd2,
                               dut1, SITE.lon_rad, SITE.lat_rad, SITE.height_m, xp, yp,
                               SITE.pressure_hpa, SITE.temperature_c, SITE.humidity,
                               SITE.wavelength_um)

    atco13_s = best_of(atco13_run, 1)
    aob, zob, *_ = atco13_run()
    star_no_pm = IcrsStar(VEGA.ra_deg, VEGA.dec_deg, parallax_mas=VEGA.parallax_mas,
                          epoch_jyear=2000.0)
    full = star_no_pm.observe(times, SITE, eop)
    err_mas = np.degrees(erfa.seps(aob, np.pi / 2 - zob, full.az_rad[pick],
                                   full.el_rad[pick])) * 3.6e6
    high = zob < np.radians(87.0)  # ERFA's refraction model is frozen below ~2.9 deg

    rate = {"ours (refraction on)": n / ours, "ours (refraction off)": n / ours_dry,
            "astropy AltAz + ErfaAstromInterpolator(300 s)": n / astropy_s,
            f"erfa.atco13 per point ({m} points, scaled)": m / atco13_s}
    print(f"{n} sidereal points over 10 h (Vega, one site), best of {args.repeat}")
    for name, pts in rate.items():
        print(f"  {name:48s} {pts / 1e6:8.3f} M points/s")
    ours_rate, _, astropy_rate, atco13_rate = rate.values()
    print(f"  ours vs astropy with interpolator: {ours_rate / astropy_rate:.1f}x; "
          f"vs atco13: {ours_rate / atco13_rate:.0f}x")
    print(f"  max |ours - atco13| on {high.sum()} common points above 3 deg: "
          f"{err_mas[high].max():.2e} mas (all {m} points: {err_mas.max():.2e} mas)")


if __name__ == "__main__":
    main()

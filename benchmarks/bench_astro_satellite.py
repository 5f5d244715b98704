"""Benchmark: one satellite pass, ours vs skyfield vs astropy, with bare sgp4_array as the floor.

    .venv/bin/python benchmarks/bench_astro_satellite.py [--rate-hz 100]

The ISS pass of 2024-05-18 19:51–19:58 UTC over Poznan (culmination 80°),
sampled at --rate-hz. All four run on the same UTC times; refraction off
(neither skyfield nor astropy's TEME pipeline refract). Also prints the
largest separation of ours from skyfield (the accuracy reference).
"""

from __future__ import annotations

import argparse
import timeit
import warnings

import erfa
import numpy as np

from virtualstar.astro import EarthOrientation, Satellite, Site, UtcTimes

LINE1 = "1 25544U 98067A   24138.99590321  .00027700  00000+0  46629-3 0  9991"
LINE2 = "2 25544  51.6390 105.0245 0003368 179.7401 290.4240 15.51492720453865"
SITE = Site(lat_deg=52.3967, lon_deg=16.8786, height_m=85.0, pressure_hpa=0.0)


def best_of(fn, repeat: int) -> float:
    """Return the best time of one call (seconds) over `repeat` calls."""
    return min(timeit.repeat(fn, repeat=repeat, number=1))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rate-hz", type=float, default=100.0)
    parser.add_argument("--repeat", type=int, default=5)
    args = parser.parse_args()
    sat = Satellite.from_tle(LINE1, LINE2, "ISS (ZARYA)")
    eop = EarthOrientation.from_astropy_iers_data()
    start = UtcTimes.from_iso(["2024-05-18T19:51:30"])
    times = start.shifted(np.arange(0.0, 420.0, 1.0 / args.rate_hz))
    n = len(times)
    sat.observe(times[:10], SITE, eop)  # compile the numba kernel (cached on disk)

    bare = best_of(lambda: sat.satrec.sgp4_array(times.jd1, times.jd2), args.repeat)
    ours = best_of(lambda: sat.observe(times, SITE, eop), args.repeat)

    from skyfield.api import EarthSatellite, wgs84

    from virtualstar.astro.bodies import skyfield_context

    ts = skyfield_context(eop).ts  # skyfield on the same IERS table as ours
    es = EarthSatellite.from_satrec(sat.satrec, ts)
    topos = wgs84.latlon(SITE.lat_deg, SITE.lon_deg, SITE.height_m)
    tt1, tt2 = times.tt()

    def skyfield_run():
        t = ts.tt_jd(tt1, tt2)
        return (es - topos).at(t).altaz()

    skyfield_s = best_of(skyfield_run, 1)

    import astropy.units as u
    from astropy.coordinates import (
        ITRS,
        TEME,
        AltAz,
        CartesianDifferential,
        CartesianRepresentation,
        EarthLocation,
    )
    from astropy.time import Time
    from astropy.utils import iers

    iers.conf.auto_download = False
    t_ap = Time(times.jd1, times.jd2, format="jd", scale="utc")
    t_ap.delta_ut1_utc  # noqa: B018 - IERS look-up outside the timing, as for ours
    loc = EarthLocation.from_geodetic(SITE.lon_deg, SITE.lat_deg, SITE.height_m)

    def astropy_run():
        _, r, v = sat.satrec.sgp4_array(times.jd1, times.jd2)
        teme = TEME(CartesianRepresentation(r.T * u.km).with_differentials(
            CartesianDifferential(v.T * u.km / u.s)), obstime=t_ap)
        itrs = teme.transform_to(ITRS(obstime=t_ap))
        return itrs.transform_to(AltAz(obstime=t_ap, location=loc))

    astropy_s = best_of(astropy_run, 1)

    # Accuracy reference: skyfield's full apparent place (light time, aberration).
    from skyfield.api import Loader
    from skyfield_data import get_skyfield_data_path

    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", message="The file finals2000A.all has expired")
        de421 = Loader(get_skyfield_data_path(), verbose=False)("de421.bsp")
    pick = slice(None, None, max(n // 2000, 1))
    t = ts.tt_jd(np.ascontiguousarray(tt1[pick]), np.ascontiguousarray(tt2[pick]))
    alt, az, _ = (de421["earth"] + topos).at(t).observe(de421["earth"] + es).apparent().altaz()
    obs = sat.observe(times[pick], SITE, eop)
    err_mas = np.degrees(erfa.seps(az.radians, alt.radians, obs.az_rad, obs.el_rad)) * 3.6e6

    print(f"ISS pass, {n} points ({args.rate_hz:g} Hz over 7 min), best of {args.repeat} "
          "(skyfield/astropy: 1 run)")
    for name, sec in [("bare sgp4_array (floor)", bare), ("ours (observed az/el + rates)", ours),
                      ("skyfield EarthSatellite (geometric altaz)", skyfield_s),
                      ("astropy TEME -> ITRS -> AltAz", astropy_s)]:
        print(f"  {name:44s} {n / sec / 1e6:8.3f} M points/s   {sec / bare:6.2f}x floor time")
    print(f"  ours is {skyfield_s / ours:.0f}x skyfield and {astropy_s / ours:.0f}x astropy")
    print(f"  max separation ours vs skyfield apparent: {err_mas.max():.3f} mas")


if __name__ == "__main__":
    main()

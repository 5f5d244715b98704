"""The in-process lockstep VSS's own CPU (issue 26): what a track's refreshes and the camera
simulator's truth cost, ours beside the way it was done before, in the same run.

1. **A star track's refreshes.** An hour of Vega sampled as the server samples it: the
   feeder's 5-s chunks of its 20 Hz grid, every correction's replacement (here every chunk
   again from a random instant) and the closed loop's single instants (three a chunk). Ours:
   the absolute node grid with cached nodes and splines (`virtualstar/astro/node_grid.py`).
   Reference: the same calls computing every chunk's nodes afresh (the cache off), which is
   what anchoring the grid at each chunk's first time did. Both against per-point
   `erfa.atco13` at every instant (max error).
2. **Moving a satellite's elements** (`guide_camera.shifted_elements`, 2 s along and 40″
   across at the ISS's culmination, as the closed-loop runs and the bundled camera file
   ask): ours measures each round's truth at the one instant; reference: the truth taken
   from a 409-point grid chunk computed for each round (monkeypatched back), same rounds.
3. **The camera's satellite truth** for ten minutes of an ISS pass: ours on a 0.2-s grid,
   reference the 0.1-s grid, both against skyfield at 400 random instants (max error).
4. **A status's error windows** (1, 10 and 60 s: 711 bins, every `status` asks for them)
   over an hour's history with a target, its rates and a clock offset every 10 s: ours
   summed compiled over a view of the bins (`tracking_errors._reduce_bins`); reference the
   same bins summed one by one in Python (tests/vss/error_windows.py), which is how
   `stats` summed them before; the figures compared field by field.

CPU is `time.process_time()` of this process, so a loaded host slows the wall, not these.

    python benchmarks/bench_vss_cpu.py
"""

from __future__ import annotations

import math
import sys
import time
import warnings
from pathlib import Path

import erfa
import numpy as np

from catalogs import load_tle_file, sample_tle_path, select_satellite
from guide_camera import CameraSite, SatelliteTruth, shifted_elements
from guide_camera.truth import _skyfield
from virtualstar.astro import EarthOrientation, UtcTimes, load_site, node_grid
from virtualstar.astro.stars import IcrsStar

MAS = 180.0 * 3600e3 / math.pi
VEGA = IcrsStar(279.23410832, 38.78299311, 201.02, 287.46, 128.93, -13.5, 1991.25, "Vega")
TRACK_START = "2024-05-18T21:00:00Z"
CULMINATION = "2024-05-18T19:55:00Z"


def _us(iso: str) -> int:
    return int(UtcTimes.from_iso([iso]).to_unix_us()[0])


def _requests(start_us: int, hours: float, rng) -> list[np.ndarray]:
    out = []
    for k in range(int(hours * 3600 / 5)):
        first = start_us + k * 5_000_000
        out.append(first + np.arange(100, dtype=np.int64) * 50_000)  # the feeder's chunk
        again = first + int(rng.integers(0, 5_000_000))  # a correction's replacement
        out.append(np.arange(again, first + 5_000_000, 50_000, dtype=np.int64))
        out += [np.array([first + int(rng.integers(0, 5_000_000))]) for _ in range(3)]
    return out


def track_refreshes(site, eop) -> None:
    rng = np.random.default_rng(26)
    requests = _requests(_us(TRACK_START), 1.0, rng)
    results = {}
    for name, cached in (("ours (absolute grid, cached nodes)", True),
                         ("reference (every chunk's nodes afresh)", False)):
        node_grid.NODE_CACHE.clear()
        real = node_grid.NODE_CACHE
        if not cached:  # a cache that forgets at once: every call computes its nodes
            node_grid.NODE_CACHE = node_grid.NodeCache(max_keys=0, max_splines=0)
        try:
            c0 = time.process_time()
            obs = [VEGA.observe(UtcTimes.from_unix_us(t), site, eop) for t in requests]
            cpu = time.process_time() - c0
        finally:
            node_grid.NODE_CACHE = real
        results[name] = (cpu, obs)
    t = np.concatenate(requests)
    times = UtcTimes.from_unix_us(t)
    ref_az, ref_el = _atco13(VEGA, times, site, eop)
    print(f"1. an hour of Vega in the server's requests ({len(requests)} calls, {len(t)} "
          "instants):")
    for name, (cpu, obs) in results.items():
        az = np.concatenate([o.az_rad for o in obs])
        el = np.concatenate([o.el_rad for o in obs])
        err = erfa.seps(ref_az, ref_el, az, el).max() * MAS
        print(f"   {name:<40} {cpu:6.2f} s CPU ({cpu / len(requests) * 1e3:.2f} ms a call); "
              f"max error vs per-point atco13 {err:.1e} mas")


def _atco13(star, times, site, eop):
    ra, dec = np.radians(star.ra_deg), np.radians(star.dec_deg)
    ep1 = erfa.epj2jd(star.epoch_jyear)
    tt1, tt2 = times.tt()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", erfa.ErfaWarning)
        ra0, dec0, _, _, px0, _ = erfa.pmsafe(
            ra, dec, np.radians(star.pm_ra_cosdec_mas_yr / 3.6e6) / np.cos(dec),
            np.radians(star.pm_dec_mas_yr / 3.6e6), star.parallax_mas / 1e3, star.rv_km_s,
            ep1[0], ep1[1], tt1, tt2)
    dut1, xp, yp = eop.interpolate(times.jd1, times.jd2)
    aob, zob, *_ = erfa.atco13(ra0, dec0, 0.0, 0.0, px0, 0.0, times.jd1, times.jd2, dut1,
                               site.lon_rad, site.lat_rad, site.height_m, xp, yp,
                               site.pressure_hpa, site.temperature_c, site.humidity,
                               site.wavelength_um)
    return aob, np.pi / 2 - zob


def moved_elements(iss, site: CameraSite) -> None:
    at = _us(CULMINATION)
    runs = 3
    print(f"2. shifted_elements (ISS, 2 s along, 40″ across at culmination), {runs} calls each:")
    exact = SatelliteTruth.exact
    for name, gridded in (("ours (each round's truth at its instant)", False),
                          ("reference (a grid chunk for each round)", True)):
        if gridded:
            SatelliteTruth.exact = SatelliteTruth.place
        try:
            c0 = time.process_time()
            for _ in range(runs):
                out = shifted_elements(iss.line1, iss.line2, along_s=2.0, across_arcsec=40.0,
                                       at_us=at, site=site)
            cpu = (time.process_time() - c0) / runs
        finally:
            SatelliteTruth.exact = exact
        print(f"   {name:<40} {cpu:6.3f} s CPU a call (inclination {math.degrees(out.inclo):.7f}°)")


def camera_truth(iss, site: CameraSite) -> None:
    at = _us(CULMINATION)
    rng = np.random.default_rng(1)
    t = at + np.sort(rng.integers(-300_000_000, 300_000_000, 400))
    ref_az, ref_el = SatelliteTruth(iss.line1, iss.line2, site).exact(t)
    print("3. the camera's ISS truth over ten minutes of its pass (horizon to 80°):")
    for name, step in (("ours (0.2-s grid)", 200_000), ("reference (0.1-s grid)", 100_000)):
        truth = SatelliteTruth(iss.line1, iss.line2, site)
        truth.step_us = step
        c0 = time.process_time()
        az, el = truth.place(t)
        cpu = time.process_time() - c0
        err = erfa.seps(ref_az, ref_el, az, el).max() * MAS
        print(f"   {name:<40} {cpu:6.2f} s CPU; max error vs skyfield at 400 instants "
              f"{err:.3f} mas")


def status_windows() -> None:
    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests" / "vss"))
    from error_windows import stats_by_plain_python

    from virtualstar.server.tracking_errors import TrackingErrorHistory

    rng = np.random.default_rng(26)
    t0, h = _us(TRACK_START), TrackingErrorHistory()
    for k in range(3600 * 5):  # an hour of 50 Hz packets of 10 samples (500 Hz)
        t = t0 + k * 200_000 + np.arange(10, dtype=np.int64) * 2_000
        e = rng.normal(0.0, 0.01, 10)
        h.add(t, e, e, np.full(10, 0.8), np.abs(e) * 2, np.abs(e))
        if k % 50 == 0:
            h.note_rates(t[:1], np.array([15.0]))
            h.note_clock_offset(int(t[0]), int(rng.integers(-40, 40)))
    runs = 300
    print(f"4. a status's error windows (1, 10, 60 s) over an hour's history, {runs} statuses:")
    same = True
    for name, figures in (("ours (compiled over a view of the bins)",
                           lambda w: h.window(w).as_dict()),
                          ("reference (the bins summed in Python)",
                           lambda w: stats_by_plain_python(h, h.last_t_us - w * 1_000_000, None))):
        cpu = time.process_time()
        for _ in range(runs):
            out = [figures(w) for w in (1, 10, 60)]
        cpu = time.process_time() - cpu
        same = same and all(h.window(w).as_dict()[k] == v for w, o in zip((1, 10, 60), out, strict=True)
                            for k, v in o.items())
        print(f"   {name:<40} {cpu / runs * 1e3:6.3f} ms a status")
    print(f"   figures identical: {same}")


def main() -> None:
    site = load_site()
    eop = EarthOrientation.from_astropy_iers_data()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # skyfield-data's "expired" IERS file: the past holds
        _skyfield()
    VEGA.observe(UtcTimes.from_unix_us(np.array([_us(TRACK_START)])), site, eop)  # imports
    track_refreshes(site, eop)
    iss = select_satellite(load_tle_file(sample_tle_path("stations")), "ISS")
    camera_site = CameraSite.from_object(site)
    moved_elements(iss, camera_site)
    camera_truth(iss, camera_site)
    status_windows()


if __name__ == "__main__":
    main()

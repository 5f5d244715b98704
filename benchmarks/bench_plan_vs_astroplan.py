"""Benchmark: planning one 10-hour night, ours (`plan_program`) vs astroplan's PriorityScheduler.

    .venv/bin/python benchmarks/bench_plan_vs_astroplan.py [--targets 40] [--repeat 5]

astroplan is the reference (`.venv/bin/pip install -e '.[bench]'`); without it only our
figures are printed.

The night. The bundled satellite elements (catalogs/data/stations.tle) have their epoch on
2024-05-17/18 (day 138), and sgp4 is only trustworthy within days of it, so the night must
be that one. At the default site (Poznań, 52.4° N) the Sun is below -12° for only 4.5 h
then, and a winter night there would be six months from the epoch. The benchmark is
therefore planned at SAAO Sutherland (32.4° S, 20.8° E, 1798 m), where the Sun is below
-12° from 16:43 to 04:24 UTC: the window 2024-05-17 17:40 to 2024-05-18 03:40 UTC is 10 h
of nautical darkness throughout (checked, the maximum Sun elevation is printed), near the
elements' epoch. The Moon (73 % lit) is up until about 00:30 UTC.

The program (written as TOML into a temporary folder, the TLE file copied beside it):

* --targets sidereal targets (default 40): the brightest bundled stars (V, then HIP) that
  spend at least 90 min of the window above 35° and 35° from the Moon (checked on a 10-min
  grid; the margins keep the ones that are only just up out). Target i (in that order) has
  priority 1 + i % 5 and a duration of 10, 20, 30, 15 or 25 min (by i // 5), one block
  each; every target needs elevation >= 30°, the Sun below -12° and the Moon >= 30° away.
  They ask for more time than the night has, so the order and packing matter.
* satellites, priority 5, elevation >= 20°: CSS (TIANHE) and FREGAT DEB, two passes each,
  ISS DEB [SPX-28 IPA FSE] and ISS (ZARYA), one each: six passes in the window.

What is compared. astroplan cannot track satellites, so it gets the same sidereal
blocks (astroplan priority = 6 - ours: lower is more important there; ties keep the
same order) with AltitudeConstraint(30°), AtNightConstraint(-12°),
MoonSeparationConstraint(30°) and the window, a Transitioner at our mount's 6°/s, a
60 s time resolution (our grid step), and one more global constraint (our code, not
astroplan's) that keeps it out of the satellite passes our plan holds, one minute
either side. Both then schedule the sidereal blocks around the same six passes, so the
sidereal priority-weighted hours (Σ priority × hours) compare like for like; the
totals add the satellite passes (astroplan: the same passes it was told to keep free).
Our plan allows more between blocks than astroplan's: the slew with the acceleration
limit (3°/s²) and the cable wrap, plus 15 s of setup, where astroplan allows the
separation at 6°/s, rounded up to a whole minute.

Timing: ours is plan_program() from the program to the plan (resolving the stars,
reading the TLEs, the satellite passes at one-second steps, the scheduling): its first
call in the process (which also loads numba's compiled SGP4 helpers, ~0.3 s once per
process) and the median of --repeat calls after it, each with our caches emptied first
(ERFA's per-grid context, the parsed elements), so each computes the whole plan. astroplan's is the time from the targets' coordinates to its schedule
(blocks, constraints, scheduler), once (--astroplan-repeat), after astropy's IERS table
is loaded. Both use bundled Earth orientation data: astropy's IERS auto-download is
off, the built-in solar-system ephemeris is used, and any attempt to open a network
connection is refused and counted (printed).

Finally both schedules are checked with astropy (AltAz with refraction, every 30 s of
every sidereal block): the lowest elevation, the highest Sun elevation and the smallest
Moon separation over the blocks are printed for each, with the least time between a
sidereal block and a satellite pass.
"""

from __future__ import annotations

import argparse
import shutil
import socket
import statistics
import tempfile
import time
import warnings
from pathlib import Path

import numpy as np

from catalogs import bright_stars
from virtualstar.astro import EarthOrientation, IcrsStar, Site, UtcTimes, observe_mount_times
from virtualstar.planning import PlanRequest, load_program, plan_program
from virtualstar.planning.sky import NightGrid

SITE = Site(lat_deg=-32.3794, lon_deg=20.8107, height_m=1798.0, pressure_hpa=830.0,
            temperature_c=10.0, humidity=0.3, name="SAAO Sutherland")
START, END = "2024-05-17T17:40:00Z", "2024-05-18T03:40:00Z"
TLE_FILE = Path(__file__).resolve().parents[1] / "catalogs" / "data" / "stations.tle"
SATELLITES = [("CSS (TIANHE)", 2), ("FREGAT DEB", 2), ("ISS DEB [SPX-28 IPA FSE]", 1),
              ("ISS (ZARYA)", 1)]
SAT_PRIORITY, SAT_MIN_EL = 5, 20.0
MIN_EL, SUN_MAX_EL, MOON_MIN_SEP = 30.0, -12.0, 30.0
DURATIONS_MIN = (10, 20, 30, 15, 25)
SLEW_DEG_S = 6.0  # the emulator mount's rate limit (scheduler.EMULATOR_LIMITS)

_network_attempts: list[str] = []


def _refuse_network() -> None:
    """Refuse (and count) every attempt to open a connection: the run must be offline."""
    def connect(self, address, *args, **kwargs):
        _network_attempts.append(str(address))
        raise OSError(f"benchmark is offline: refused connection to {address}")

    socket.socket.connect = connect  # type: ignore[method-assign]
    socket.socket.connect_ex = connect  # type: ignore[method-assign]


def _offline_astropy() -> None:
    from astropy.coordinates import solar_system_ephemeris
    from astropy.utils import iers
    from astropy.utils.data import conf as data_conf

    iers.conf.auto_download = False
    iers.conf.auto_max_age = None
    data_conf.allow_internet = False
    solar_system_ephemeris.set("builtin")


def pick_stars(n: int, eop: EarthOrientation) -> list:
    """The n brightest catalog stars well up and away from the Moon for >= 90 min."""
    t0, t1 = (int(x) for x in UtcTimes.from_iso([START, END]).to_unix_us())
    grid = NightGrid.build(t0, t1, SITE, eop, 600.0)
    moon = np.radians([grid.moon_az_deg, grid.moon_el_deg])
    chosen = []
    for star in sorted(bright_stars(), key=lambda s: (s.vmag, s.hip)):
        obs = observe_mount_times(IcrsStar.from_catalog(star), grid.t_us, SITE, eop)
        sep = np.degrees(np.arccos(np.clip(
            np.sin(obs.el_rad) * np.sin(moon[1])
            + np.cos(obs.el_rad) * np.cos(moon[1]) * np.cos(obs.az_rad - moon[0]), -1, 1)))
        good = (np.degrees(obs.el_rad) >= MIN_EL + 5) & (sep >= MOON_MIN_SEP + 5)
        if good.sum() * 10 >= 90:
            chosen.append(star)
        if len(chosen) == n:
            break
    return chosen


def target_table(stars: list) -> list[dict]:
    out = []
    for i, s in enumerate(stars):
        out.append({"name": s.name or s.bayer or f"HIP {s.hip}", "star": s,
                    "priority": 1 + i % 5, "duration_s": 60 * DURATIONS_MIN[(i // 5) % 5]})
    return out


def write_program(folder: Path, targets: list[dict]) -> Path:
    shutil.copy(TLE_FILE, folder / "stations.tle")
    lines = ['[program]', 'name = "bench: 10 h at Sutherland"', '', '[defaults]',
             f'min_el_deg = {MIN_EL}', f'sun_max_el_deg = {SUN_MAX_EL}',
             f'moon_min_sep_deg = {MOON_MIN_SEP}', '']
    for t in targets:
        lines += ['[[target]]', f'name = "{t["name"]}"', f'star = "HIP {t["star"].hip}"',
                  f'priority = {t["priority"]}', f'duration_s = {t["duration_s"]}', '']
    for sat, repeats in SATELLITES:
        lines += ['[[target]]', 'tle_file = "stations.tle"', f'sat = "{sat}"',
                  f'priority = {SAT_PRIORITY}', f'min_el_deg = {SAT_MIN_EL}',
                  f'repeats = {repeats}', '']
    path = folder / "program.toml"
    path.write_text("\n".join(lines), encoding="utf-8")
    return path


def run_ours(program_path: Path, eop: EarthOrientation, repeat: int):
    program = load_program(program_path)
    t0, t1 = (int(x) for x in UtcTimes.from_iso([START, END]).to_unix_us())
    request = PlanRequest(program, t0, t1, SITE)
    c0 = time.perf_counter()
    plan = plan_program(request, eop)
    cold = time.perf_counter() - c0
    warm = []
    for _ in range(repeat):
        _forget_caches()  # every timed call computes everything from the program
        c0 = time.perf_counter()
        again = plan_program(request, eop)
        warm.append(time.perf_counter() - c0)
        if again.as_dict() != plan.as_dict():
            raise SystemExit("our planner gave two different plans for the same request")
    return plan, cold, statistics.median(warm)


def _forget_caches() -> None:
    """Empty what a plan leaves behind for the next: ERFA's per-grid context and the
    parsed satellite elements (what stays is process start-up: imports, numba's compiled
    functions, the IERS table, as astroplan keeps astropy's)."""
    from virtualstar.astro import stars
    from virtualstar.planning import sky

    stars._ASTROM_CACHE.clear()
    sky._satellite.cache_clear()
    sky._tle_records.cache_clear()


def import_astroplan() -> list | None:
    """Import astroplan (which checks its IERS table on import): None if it is not
    installed, else the warnings about Earth orientation data it gave."""
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        try:
            import astroplan  # noqa: F401
        except ImportError:
            return None
    return [w for w in caught if "IERS" in str(w.message) or "Earth" in str(w.message)]


def run_astroplan(targets: list[dict], busy: list[tuple[int, int]]):
    """Schedule the sidereal targets with astroplan around the busy (µs) windows."""
    import astroplan
    import astropy.units as u
    from astroplan import (
        AltitudeConstraint,
        AtNightConstraint,
        FixedTarget,
        MoonSeparationConstraint,
        Observer,
        ObservingBlock,
        PriorityScheduler,
        Schedule,
        TimeConstraint,
        Transitioner,
    )
    from astropy.time import Time

    class KeepFree(astroplan.Constraint):
        """False within the given windows (the satellite passes), `pad` either side."""

        def __init__(self, windows_us, pad_s):
            self.windows = [(a - pad_s * 1e6, b + pad_s * 1e6) for a, b in windows_us]

        def compute_constraint(self, times, observer, targets):
            t = (times.utc.jd - 2440587.5) * 86400e6  # µs since 1970 (fine at 60 s steps)
            ok = np.ones(np.shape(t), bool)
            for a, b in self.windows:
                ok &= ~((t + 60e6 > a) & (t < b))  # the grid slot [t, t + 60 s) touches it
            return ok

    observer = Observer(location=_location(), pressure=SITE.pressure_hpa * u.hPa,
                        temperature=SITE.temperature_c * u.deg_C,
                        relative_humidity=SITE.humidity, name=SITE.name)
    start, end = Time(START, scale="utc"), Time(END, scale="utc")
    coords = _sky_coords([t["star"] for t in targets], start + (end - start) / 2)
    start.delta_ut1_utc  # noqa: B018 - astropy's IERS look-up, outside the timing as for ours

    c0 = time.perf_counter()
    blocks = [ObservingBlock(FixedTarget(coord, name=t["name"]), t["duration_s"] * u.s,
                             6 - t["priority"]) for t, coord in zip(targets, coords, strict=True)]
    constraints = [AltitudeConstraint(min=MIN_EL * u.deg),
                   AtNightConstraint(max_solar_altitude=SUN_MAX_EL * u.deg),
                   MoonSeparationConstraint(min=MOON_MIN_SEP * u.deg),
                   TimeConstraint(start, end), KeepFree(busy, 60.0)]
    scheduler = PriorityScheduler(constraints=constraints, observer=observer,
                                  transitioner=Transitioner(slew_rate=SLEW_DEG_S * u.deg / u.s),
                                  time_resolution=60 * u.s)
    schedule = Schedule(start, end)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        scheduler(blocks, schedule)
    elapsed = time.perf_counter() - c0
    out = [(b.target.name, int(round(b.start_time.unix * 1e6)),
            int(round(b.end_time.unix * 1e6))) for b in schedule.observing_blocks]
    return out, elapsed


def _location():
    import astropy.units as u
    from astropy.coordinates import EarthLocation

    return EarthLocation.from_geodetic(SITE.lon_deg * u.deg, SITE.lat_deg * u.deg,
                                       SITE.height_m * u.m)


def _sky_coords(stars: list, when):
    """ICRS places of catalog stars at `when` (their proper motion applied)."""
    import astropy.units as u
    from astropy.coordinates import Distance, SkyCoord
    from astropy.time import Time

    plx = np.array([max(s.parallax_mas, 0.1) for s in stars])
    coo = SkyCoord(ra=[s.ra_deg for s in stars] * u.deg, dec=[s.dec_deg for s in stars] * u.deg,
                   pm_ra_cosdec=[s.pm_ra_cosdec_mas_yr for s in stars] * u.mas / u.yr,
                   pm_dec=[s.pm_dec_mas_yr for s in stars] * u.mas / u.yr,
                   distance=Distance(parallax=plx * u.mas),
                   radial_velocity=[s.rv_km_s or 0.0 for s in stars] * u.km / u.s,
                   obstime=Time(stars[0].epoch_jyear, format="jyear", scale="tt"))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return coo.apply_space_motion(new_obstime=when)


def check_blocks(blocks: list[tuple[str, int, int]], stars_by_name: dict) -> dict[str, float]:
    """Lowest elevation, highest Sun elevation, least Moon separation (deg) over the blocks,
    every 30 s, with astropy (AltAz with the site's refraction)."""
    import astropy.units as u
    from astropy.coordinates import AltAz, get_body, get_sun
    from astropy.time import Time

    if not blocks:
        return {"min_el": float("nan"), "max_sun_el": float("nan"), "min_moon_sep": float("nan")}
    names, times = [], []
    for name, a, b in blocks:
        t = np.arange(a, b + 1, 30_000_000, dtype=np.int64)
        names += [name] * len(t)
        times.append(t)
    t_us = np.concatenate(times)
    when = Time(t_us / 1e6, format="unix", scale="utc")
    frame = AltAz(obstime=when, location=_location(), pressure=SITE.pressure_hpa * u.hPa,
                  temperature=SITE.temperature_c * u.deg_C, relative_humidity=SITE.humidity,
                  obswl=SITE.wavelength_um * u.um)
    order = sorted(stars_by_name)
    coords = _sky_coords([stars_by_name[n] for n in order], when[len(when) // 2])
    idx = np.array([order.index(n) for n in names])
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        star = coords[idx].transform_to(frame)
        sun = get_sun(when).transform_to(frame)
        moon = get_body("moon", when, _location()).transform_to(frame)
    return {"min_el": float(star.alt.deg.min()), "max_sun_el": float(sun.alt.deg.max()),
            "min_moon_sep": float(star.separation(moon).deg.min())}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--targets", type=int, default=40)
    parser.add_argument("--repeat", type=int, default=5, help="our planner's timed runs")
    parser.add_argument("--astroplan-repeat", type=int, default=1)
    args = parser.parse_args()
    _refuse_network()
    _offline_astropy()

    eop = EarthOrientation.from_astropy_iers_data()
    t0, t1 = (int(x) for x in UtcTimes.from_iso([START, END]).to_unix_us())
    sun_max = float(NightGrid.build(t0, t1, SITE, eop).sun_el_deg.max())
    targets = target_table(pick_stars(args.targets, eop))
    stars_by_name = {t["name"]: t["star"] for t in targets}
    prio = {t["name"]: t["priority"] for t in targets}
    asked_h = sum(t["duration_s"] for t in targets) / 3600
    print(f"{SITE.name} ({SITE.lat_deg:+.2f}°, {SITE.lon_deg:+.2f}°), {START} .. {END} "
          f"(10 h; Sun at most {sun_max:.1f}°)")
    print(f"{len(targets)} stars (priorities 1-5, 10-30 min, {asked_h:.1f} h asked; el >= "
          f"{MIN_EL:g}°, Sun <= {SUN_MAX_EL:g}°, Moon >= {MOON_MIN_SEP:g}°) + "
          f"{sum(r for _, r in SATELLITES)} satellite passes asked "
          f"({', '.join(s for s, _ in SATELLITES)})")

    with tempfile.TemporaryDirectory() as tmp:
        plan, cold_s, ours_s = run_ours(write_program(Path(tmp), targets), eop, args.repeat)
    sat_blocks = [b for b in plan.blocks if b.kind == "satellite"]
    sid_blocks = [b for b in plan.blocks if b.kind != "satellite"]
    sat_wh = sum(b.priority * b.duration_s / 3600 for b in sat_blocks)
    ours_sid_wh = sum(b.priority * b.duration_s / 3600 for b in sid_blocks)
    print(f"satellite passes in our plan: {len(sat_blocks)} "
          f"({', '.join(f'{b.target} {_hm(b.start_us)}-{_hm(b.end_us)}' for b in sat_blocks)})")

    rows = [("ours (plan_program)", ours_s, len(sid_blocks), len(plan.blocks), ours_sid_wh,
             plan.weighted_hours)]
    ap = None
    stale = import_astroplan()
    if stale is not None:
        busy = [(b.start_us, b.end_us) for b in sat_blocks]
        runs = [run_astroplan(targets, busy) for _ in range(max(1, args.astroplan_repeat))]
        ap_blocks = runs[0][0]
        ap_s = statistics.median(r[1] for r in runs)
        ap_sid_wh = sum(prio[n] * (b - a) / 3.6e9 for n, a, b in ap_blocks)
        ap = (ap_blocks, ap_s, ap_sid_wh)
        rows.append((f"astroplan {_astroplan_version()} PriorityScheduler", ap_s, len(ap_blocks),
                     len(ap_blocks) + len(sat_blocks), ap_sid_wh, ap_sid_wh + sat_wh))
        if stale:
            print(f"astroplan warned about Earth orientation data: {stale[0].message}")
    else:
        print("astroplan is not installed: only our figures are printed. Install it with\n"
              "    .venv/bin/pip install -e '.[bench]'")

    print()
    print(f"{'planner':40s} {'time (s)':>9s} {'blocks':>12s} {'weighted hours':>22s}")
    print(f"{'':40s} {'':>9s} {'sidereal/all':>12s} {'sidereal':>10s} {'total':>11s}")
    for name, secs, n_sid, n_all, sid_wh, all_wh in rows:
        print(f"{name:40s} {secs:9.3f} {n_sid:>5d} / {n_all:<4d} {sid_wh:10.3f} {all_wh:11.3f}")
    print(f"ours: first call {cold_s:.3f} s, median of {args.repeat} after it "
          f"{ours_s:.3f} s (in the table); totals include the satellite passes (weighted "
          f"{sat_wh:.3f} h" + (", the same passes kept free for astroplan)" if ap else ")"))

    if ap is not None:
        ap_blocks, ap_s, ap_sid_wh = ap
        speed, speed_cold = ap_s / ours_s, ap_s / cold_s
        ratio = ours_sid_wh / ap_sid_wh if ap_sid_wh else float("inf")
        ratio_all = plan.weighted_hours / (ap_sid_wh + sat_wh)
        print(f"astroplan time / our time: {speed:.2f}x ({speed_cold:.2f}x against our first "
              f"call)")
        print(f"our weighted hours / astroplan's: sidereal {ratio:.3f}, total {ratio_all:.3f}")
        ours_chk = check_blocks([(b.target, b.start_us, b.end_us) for b in sid_blocks],
                                stars_by_name)
        ap_chk = check_blocks(ap_blocks, stars_by_name)
        print(f"astropy check of the sidereal blocks every 30 s (need el >= {MIN_EL:g}, "
              f"Sun <= {SUN_MAX_EL:g}, Moon >= {MOON_MIN_SEP:g}):")
        for name, chk in (("ours", ours_chk), ("astroplan", ap_chk)):
            print(f"  {name:10s} lowest el {chk['min_el']:7.3f}°  highest Sun "
                  f"{chk['max_sun_el']:7.3f}°  least Moon separation {chk['min_moon_sep']:7.3f}°")
        busy = [(b.start_us, b.end_us) for b in sat_blocks]
        for name, blocks in (("ours", [(b.target, b.start_us, b.end_us) for b in sid_blocks]),
                             ("astroplan", ap_blocks)):
            gap = _least_gap_s(blocks, busy)
            print(f"  {name:10s} least time between a sidereal block and a satellite pass "
                  f"{gap:.0f} s" + (" (OVERLAP)" if gap < 0 else ""))
        ours_names = {b.target for b in sid_blocks}
        ap_names = {n for n, _, _ in ap_blocks}
        print(f"  targets only ours scheduled: {sorted(ours_names - ap_names) or 'none'}; "
              f"only astroplan: {sorted(ap_names - ours_names) or 'none'}")
        print("goals (issue):")
        print(f"  weighted hours >= astroplan's (sidereal, like for like): "
              f"{'MET' if ours_sid_wh >= ap_sid_wh else 'NOT MET'} "
              f"({ours_sid_wh:.3f} vs {ap_sid_wh:.3f})")
        print(f"  >= 20x faster than astroplan: {'MET' if speed >= 20 else 'NOT MET'} "
              f"({speed:.2f}x)")
    print(f"network connections attempted: {len(_network_attempts)}"
          + (f" ({', '.join(_network_attempts[:3])})" if _network_attempts else ""))


def _least_gap_s(blocks: list[tuple[str, int, int]], busy: list[tuple[int, int]]) -> float:
    """Least time (s) between the blocks and the busy windows; negative when they overlap."""
    gaps = [max(a - e, s - b) / 1e6 for _, a, b in blocks for s, e in busy]
    return min(gaps, default=float("inf"))


def _astroplan_version() -> str:
    import astroplan

    return astroplan.__version__


def _hm(t_us: int) -> str:
    return UtcTimes.from_unix_us(int(t_us)).iso(0)[0][11:16]


if __name__ == "__main__":
    main()

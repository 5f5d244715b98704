"""`vs passes`: list the passes of a satellite over the site between two UTC times."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Annotated

import typer

from virtualstar.cli.where import (
    HumidityOpt,
    JsonOpt,
    NoRefractionOpt,
    PressureOpt,
    SatOpt,
    SiteFileOpt,
    SiteOpt,
    TemperatureOpt,
    build_site,
    fail,
    load_satellite,
    parse_times,
    run_collecting_warnings,
)
from virtualstar.display import safe_text


def passes(
    tle: Annotated[Path, typer.Option("--tle", help="TLE (2/3-line) or OMM JSON file.")],
    start: Annotated[str, typer.Option("--from", help="Start of the search, UTC ISO 8601.")],
    end: Annotated[str, typer.Option("--to", help="End of the search, UTC ISO 8601.")],
    sat: SatOpt = None,
    min_el: Annotated[float, typer.Option(
        "--min-el", help="Lowest culmination counted as a pass, and the rise/set "
                         "elevation, degrees.")] = 0.0,
    site: SiteOpt = None,
    site_file: SiteFileOpt = None,
    pressure_hpa: PressureOpt = None,
    temperature_c: TemperatureOpt = None,
    humidity: HumidityOpt = None,
    no_refraction: NoRefractionOpt = False,
    horizon: Annotated[Path | None, typer.Option(
        "--horizon", help="Horizon profile ('AZ_DEG EL_DEG' lines, docs/vss.md 'Safety'): each "
        "pass also gets the times it is above it. Default: the site file's, if any.")] = None,
    as_json: JsonOpt = False,
) -> None:
    """List satellite passes: rise, culmination (time, elevation) and set; the closest the pass
    comes to the Sun; with a horizon profile, when it is above that profile."""
    from virtualstar.astro import (
        AstroError,
        EarthOrientation,
        avoidance_from_options,
        satellite_passes,
    )

    the_site = build_site(site_file, site, pressure_hpa, temperature_c, humidity, no_refraction)
    t0, t1 = parse_times([start]), parse_times([end])
    if not -90.0 < min_el < 90.0:
        raise fail(f"--min-el {min_el}: expected degrees between -90 and 90")
    span_s = float(t1.seconds_since(t0.jd1[0], t0.jd2[0])[0])
    if span_s <= 0:
        raise fail(f"--to {end} is not after --from {start}")
    if span_s > 31 * 86400:
        raise fail(f"--from/--to span {span_s / 86400:.1f} days; at most 31 days per search")
    try:
        zones = avoidance_from_options(site_file=site_file, horizon_file=horizon)
    except AstroError as exc:
        raise fail(str(exc)) from None

    def work():
        eop = EarthOrientation.from_astropy_iers_data()
        satellite = load_satellite(tle, sat)
        found = satellite_passes(satellite, the_site, t0, t1, min_el_deg=min_el, eop=eop)
        return satellite, [{**_pass_fields(p),
                            **_pass_sky(satellite, p, the_site, zones, eop, t0, t1)}
                           for p in found]

    satellite, rows = run_collecting_warnings(work)
    if as_json:
        typer.echo(json.dumps(rows, indent=1))
        return
    typer.echo(f"{safe_text(satellite.name)}: {len(rows)} passes above {min_el:g} deg from {the_site.name}")
    typer.echo(f"{'rise UTC':24} {'az':>6}   {'culmination UTC':24} {'el':>5} {'az':>6}   "
               f"{'set UTC':24} {'az':>6}  {'sun_sep_min':>11}  {'visible':7}"
               + (f"  {'above the horizon profile (UTC)':45}" if zones.horizon else ""))
    for r in rows:
        line = (f"{r['rise_utc'] or '(before start)':24} {_num(r['rise_az_deg'])}   "
                f"{r['culmination_utc']:24} {r['culmination_el_deg']:5.1f} "
                f"{r['culmination_az_deg']:6.1f}   {r['set_utc'] or '(after end)':24} "
                f"{_num(r['set_az_deg'])}  {_num(r['sun_min_separation_deg'], 11)}  "
                f"{_visibility(r):7}")
        if zones.horizon:
            line += (f"  {r['above_horizon_from_utc'] or '-'} .. "
                     f"{r['above_horizon_to_utc'] or '-'}")
        typer.echo(line)


def _num(value: float | None, width: int = 6) -> str:
    return f"{value:{width}.1f}" if value is not None else f"{'-':>{width}}"


def _visibility(r: dict) -> str:
    if r["visible"]:
        return "yes"
    return "sunlit" if r["sunlit"] else "shadow"


def _pass_sky(satellite, p, site, zones, eop, t0, t1) -> dict:
    """The pass sampled every second: its closest approach to the Sun, its time above the profile.

    A pass already up at the search's start (no rise) or still up at its end (no set) is
    sampled from that start or to that end: the part inside the window counts whole.
    """
    import erfa
    import numpy as np

    from virtualstar.astro.avoidance import body_places
    from virtualstar.astro.bodies import DARK_SUN_EL_DEG, satellite_sunlit

    lo = p.rise.utc if p.rise is not None else t0
    hi = p.set.utc if p.set is not None else t1
    span = float(hi.seconds_since(lo.jd1[0], lo.jd2[0])[0])
    times = lo.shifted(np.arange(0.0, span + 1.0, 1.0))
    obs = satellite.observe(times, site, eop)
    sun_az, sun_el = body_places(times, site, eop, ("sun",))["sun"]
    sep = np.degrees(erfa.seps(obs.az_rad, obs.el_rad, sun_az, sun_el))
    out = {"sun_min_separation_deg": round(float(sep.min()), 3)}
    # sunlit (out of the Earth's shadow, skyfield) while the observer is in darkness
    # (the Sun more than 6° below the horizon): a pass the eye can see, as Heavens-Above says
    sunlit = satellite_sunlit(satellite.satrec, times, eop)
    dark = np.degrees(sun_el) < DARK_SUN_EL_DEG
    k = int(np.argmax(obs.el_rad))
    out.update({"sunlit": bool(sunlit.any()), "observer_in_darkness": bool(dark[k]),
                "visible": bool((sunlit & dark).any())})
    if zones.horizon is not None:
        above = np.degrees(obs.el_rad) >= zones.min_el_deg(obs.az_rad)
        idx = np.flatnonzero(above)
        iso = times.iso()
        out["above_horizon_from_utc"] = iso[idx[0]] if idx.size else None
        out["above_horizon_to_utc"] = iso[idx[-1]] if idx.size else None
    return out


def _pass_fields(p) -> dict:
    return {
        "rise_utc": p.rise.utc.iso()[0] if p.rise else None,
        "rise_az_deg": round(p.rise.az_deg, 3) if p.rise else None,
        "culmination_utc": p.culmination.utc.iso()[0],
        "culmination_el_deg": round(p.culmination.el_deg, 3),
        "culmination_az_deg": round(p.culmination.az_deg, 3),
        "set_utc": p.set.utc.iso()[0] if p.set else None,
        "set_az_deg": round(p.set.az_deg, 3) if p.set else None,
    }


__all__ = ["passes"]

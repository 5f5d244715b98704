"""`vs where`: where a star, planet, RA/Dec or satellite is, for one or more UTC times."""

from __future__ import annotations

import dataclasses
import json
import math
import warnings
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any

import typer

from virtualstar.display import safe_text

if TYPE_CHECKING:
    from virtualstar.astro import Satellite, Site, UtcTimes

# The astronomy (numpy, ERFA, SGP4, numba, scipy) is imported inside the functions that
# compute: --help stays fast (tests/test_import_rules.py).

SATELLITE_LOOKBACK_S = 1800.0  # a satellite up now rose within the last half hour

SiteOpt = Annotated[str | None, typer.Option(
    "--site", help="Site as LAT,LON,HEIGHT_M (degrees, degrees east, metres); "
                   "default: the site TOML ($VIRTUALSTAR_SITE or the packaged default).")]
SiteFileOpt = Annotated[Path | None, typer.Option(
    "--site-file", envvar="VIRTUALSTAR_SITE", help="Site TOML file with a \\[site] table.")]
PressureOpt = Annotated[float | None, typer.Option(
    "--pressure-hpa", help="Air pressure for refraction, hPa (0 switches refraction off).")]
TemperatureOpt = Annotated[float | None, typer.Option(
    "--temperature-c", help="Air temperature for refraction, degrees Celsius.")]
HumidityOpt = Annotated[float | None, typer.Option(
    "--humidity", help="Relative humidity for refraction, 0..1.")]
NoRefractionOpt = Annotated[bool, typer.Option(
    "--no-refraction", help="Give geometric (unrefracted) elevations.")]
TleOpt = Annotated[Path | None, typer.Option(
    "--tle", help="TLE (2/3-line) or OMM JSON file with satellite elements.")]
SatOpt = Annotated[str | None, typer.Option(
    "--sat", help="Satellite name or NORAD number in the --tle file (default: the first).")]
JsonOpt = Annotated[bool, typer.Option("--json", help="Print JSON instead of a table.")]


def fail(message: str, code: int = 2) -> typer.Exit:
    """Print an error to stderr and return the Exit to raise."""
    typer.echo(f"error: {message}", err=True)
    return typer.Exit(code)


class UsageError(Exception):
    """A bad argument found while warnings are being collected (reported after them)."""


def run_collecting_warnings(work):
    """Run work(); show its warnings on stderr, then its error (if any) and exit 2."""
    from virtualstar.astro import AstroError

    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        try:
            return work()
        except (UsageError, AstroError) as exc:
            error = str(exc)
        finally:
            echo_warnings(caught)
    raise fail(error)


def build_site(site_file, site, pressure_hpa, temperature_c, humidity, no_refraction) -> Site:
    """Return the site from the shared options, or raise typer.Exit with a clear error."""
    from virtualstar.astro import AstroError
    from virtualstar.astro.site import site_from_options

    try:
        return site_from_options(site_file=site_file, site_text=site, pressure_hpa=pressure_hpa,
                                 temperature_c=temperature_c, humidity=humidity,
                                 no_refraction=no_refraction)
    except AstroError as exc:
        raise fail(str(exc)) from None


def load_satellite(tle: Path, sat: str | None) -> Satellite:
    """Return the satellite chosen from a TLE/OMM file, or raise UsageError."""
    from catalogs import CatalogError, load_tle_file, select_satellite
    from virtualstar.astro import AstroError, Satellite

    try:
        records = load_tle_file(tle)
        if not records:
            raise UsageError(f"{tle}: no element sets found")
        record = select_satellite(records, sat) if sat else records[0]
        return Satellite.from_record(record)
    except (CatalogError, AstroError, KeyError, ValueError) as exc:
        raise UsageError(str(exc).strip('"')) from None


def parse_times(at: list[str] | None) -> UtcTimes:
    """Return the --at times (default: now), or raise typer.Exit."""
    from virtualstar.astro import AstroError, UtcTimes

    try:
        return UtcTimes.from_iso(at) if at else UtcTimes.now()
    except AstroError as exc:
        raise fail(str(exc)) from None


def echo_warnings(caught: list[warnings.WarningMessage]) -> None:
    """Show each distinct warning once on stderr, without Python's file/line noise."""
    seen = set()
    for w in caught:
        text = str(w.message)
        if text not in seen:
            seen.add(text)
            typer.echo(f"warning: {text}", err=True)


@dataclass(frozen=True)
class _Row:
    utc: str
    az_deg: float
    el_deg: float
    ra_deg: float
    dec_deg: float
    az_rate_deg_s: float
    el_rate_deg_s: float
    range_km: float | None = None  # satellites only
    sun_separation_deg: float | None = None  # from the Sun's observed place at the same time


def where(
    target: Annotated[str | None, typer.Argument(
        help="Star name ('Vega', 'HIP 91262', 'alf Lyr'), planet ('mars', 'moon', 'sun') or "
             "ICRS RA/Dec ('05h34m31.94s +22d00m52.2s', '83.633 22.0145'). "
             "With --tle: a satellite name (same as --sat) or nothing.")] = None,
    tle: TleOpt = None,
    sat: SatOpt = None,
    at: Annotated[list[str] | None, typer.Option(
        "--at", help="UTC time, ISO 8601 (2024-05-18T21:30:00Z); repeat for more. "
                     "Default: now.")] = None,
    site: SiteOpt = None,
    site_file: SiteFileOpt = None,
    pressure_hpa: PressureOpt = None,
    temperature_c: TemperatureOpt = None,
    humidity: HumidityOpt = None,
    no_refraction: NoRefractionOpt = False,
    as_json: JsonOpt = False,
) -> None:
    """Show where a target is: apparent RA/Dec, observed az/el and rates, rise/culmination/set."""
    the_site = build_site(site_file, site, pressure_hpa, temperature_c, humidity, no_refraction)
    times = parse_times(at)
    obj, rows, events = run_collecting_warnings(
        lambda: _compute(_target(target, tle, sat, times), times, the_site))
    if as_json:
        out = [{**_row_fields(row), **ev, "target": obj.name,
                "refraction": the_site.refraction} for row, ev in zip(rows, events, strict=True)]
        typer.echo(json.dumps(out, indent=1))
        return
    _print_table(obj, the_site, rows, events)


def _target(target: str | None, tle: Path | None, sat: str | None, times: UtcTimes) -> Any:
    from virtualstar.astro import resolve_target

    if tle is not None:
        obj = load_satellite(tle, sat or target)
        _check_tle_epoch(tle, sat or target, times)
        return obj
    if target is None:
        raise UsageError("give a TARGET (star, planet or RA/Dec) or --tle FILE; "
                         "see vs where --help")
    try:
        return resolve_target(target)
    except KeyError as exc:  # UnknownTarget, catalogs.UnknownStar
        raise UsageError(str(exc).strip('"')) from None


def _check_tle_epoch(tle: Path, sat: str | None, times: UtcTimes) -> None:
    import datetime as dt

    from catalogs import check_epoch, load_tle_file, select_satellite

    records = load_tle_file(tle)
    record = select_satellite(records, sat) if sat else records[0]
    when = dt.datetime.fromtimestamp(int(times.to_unix_us()[0]) / 1e6, dt.UTC)
    check_epoch(record, when)


def _compute(obj: Any, times: UtcTimes, site: Site) -> tuple[Any, list[_Row], list[dict]]:
    import erfa
    import numpy as np

    from virtualstar.astro import EarthOrientation, Satellite, find_events
    from virtualstar.astro.avoidance import body_places
    from virtualstar.astro.observed import topocentric_apparent_radec

    eop = EarthOrientation.from_astropy_iers_data()
    obs = obj.observe(times, site, eop)
    geometric = obj.observe(times, site.without_refraction(), eop)
    ra, dec = topocentric_apparent_radec(geometric.az_rad, geometric.el_rad, times, site, eop)
    iso = times.iso()
    rows = [_Row(iso[i], math.degrees(obs.az_rad[i]), math.degrees(obs.el_rad[i]),
                 math.degrees(ra[i]), math.degrees(dec[i]), math.degrees(obs.az_rate_rad_s[i]),
                 math.degrees(obs.el_rate_rad_s[i])) for i in range(len(times))]
    if isinstance(obj, Satellite):
        range_km = obj.topocentric(times, site, eop).range_m / 1e3
        rows = [dataclasses.replace(r, range_km=float(d)) for r, d in zip(rows, range_km,
                                                                           strict=True)]
    sun_az, sun_el = body_places(times, site, eop, ("sun",))["sun"]
    sep = np.degrees(erfa.seps(obs.az_rad, obs.el_rad, sun_az, sun_el))
    rows = [dataclasses.replace(r, sun_separation_deg=round(float(d), 4))
            for r, d in zip(rows, sep, strict=True)]
    events = []
    back_s = SATELLITE_LOOKBACK_S if isinstance(obj, Satellite) else 86400.0
    for i in range(len(times)):
        found = find_events(obj, site, times[i].shifted(-back_s), back_s + 86400.0, eop=eop)
        events.append(_event_fields(found, times[i], float(obs.el_rad[i]) > 0.0))
    return obj, rows, events


def _row_fields(row: _Row) -> dict:
    fields = dataclasses.asdict(row)
    if fields["range_km"] is None:
        del fields["range_km"]
    return fields


def _event_fields(found, now: UtcTimes, up_now: bool) -> dict:
    """Rise, culmination and set of the visibility now (up) or the next one (down).

    Up now: the rise is the one before now (None if it was up all the time searched),
    then the next culmination and set. Down now: the next rise, culmination and set.
    `visibility` says which, or `circumpolar` / `never rises` over the next 24 h.
    """
    def t(ev) -> float:
        return float(ev.utc.seconds_since(now.jd1[0], now.jd2[0])[0])

    past = [ev for ev in found if t(ev) <= 0]
    future = [ev for ev in found if t(ev) > 0]
    fields: dict[str, Any] = {"rise_utc": None, "culmination_utc": None,
                              "culmination_el_deg": None, "set_utc": None}
    if up_now:
        rises = [i for i, ev in enumerate(past) if ev.kind == "rise"]
        if rises:
            fields["rise_utc"] = past[rises[-1]].utc.iso()[0]
        # this visibility's culmination may be behind us already
        chosen = [ev for ev in past[rises[-1] + 1:] if ev.kind == "culmination"] \
            if rises else []
        chosen = chosen[-1:] + future
    else:
        first_rise = next((i for i, ev in enumerate(future) if ev.kind == "rise"), None)
        chosen = future[first_rise:] if first_rise is not None else []
    for ev in chosen:
        key = f"{ev.kind}_utc"
        if fields[key] is None and not (ev.kind == "rise" and up_now):
            fields[key] = ev.utc.iso()[0]
            if ev.kind == "culmination":
                fields["culmination_el_deg"] = round(ev.el_deg, 4)
        if ev.kind == "set":
            break
    will_set = any(ev.kind == "set" for ev in future)
    will_rise = any(ev.kind == "rise" for ev in future)
    if up_now:
        fields["visibility"] = "up now" if will_set else "circumpolar"
    else:
        fields["visibility"] = "down" if will_rise else "never rises"
    return fields


def _hms(deg: float, hours: bool) -> str:
    value = deg / 15.0 if hours else abs(deg)
    d = int(value)
    m = int((value - d) * 60)
    s = ((value - d) * 60 - m) * 60
    if hours:
        return f"{d:02d}h{m:02d}m{s:05.2f}s"
    return f"{'-' if deg < 0 else '+'}{d:02d}d{m:02d}m{s:04.1f}s"


def _print_table(obj: Any, site: Site, rows: list[_Row], events: list[dict]) -> None:
    refr = (f"refraction on ({site.pressure_hpa:g} hPa, {site.temperature_c:g} C, "
            f"humidity {site.humidity:g})" if site.refraction else "refraction off")
    typer.echo(f"{safe_text(obj.name)} from {safe_text(site.name)} (lat {site.lat_deg:.4f}, lon {site.lon_deg:.4f}, "
               f"{site.height_m:g} m), {refr}")
    typer.echo(f"{'UTC':24} {'az_deg':>10} {'el_deg':>9} {'az_rate_deg_s':>14} "
               f"{'el_rate_deg_s':>14}  {'RA (apparent)':>13} {'Dec':>12} {'sun_sep_deg':>11}")
    for row, ev in zip(rows, events, strict=True):
        typer.echo(f"{row.utc:24} {row.az_deg:10.5f} {row.el_deg:9.5f} "
                   f"{row.az_rate_deg_s:14.7f} {row.el_rate_deg_s:14.7f}  "
                   f"{_hms(row.ra_deg, True):>13} {_hms(row.dec_deg, False):>12} "
                   f"{row.sun_separation_deg:11.2f}")
        culm = (f"{ev['culmination_utc']} (el {ev['culmination_el_deg']:.2f})"
                if ev["culmination_utc"] else "-")
        if ev["visibility"] in ("circumpolar", "never rises"):
            typer.echo(f"{'':24} {ev['visibility']} (next 24 h); culmination {culm}")
        else:
            typer.echo(f"{'':24} {ev['visibility']}: rise {ev['rise_utc'] or '(before the search)'}"
                       f", culmination {culm}, set {ev['set_utc'] or '-'}")


__all__ = ["where"]

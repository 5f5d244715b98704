"""`vs slew`: point the mount at RA/Dec, Az/El or a catalog star (sky targets are then tracked)."""

from __future__ import annotations

from typing import Annotated, Any

import typer
from rich.console import Console
from rich.table import Table

from virtualstar.cli.status import JsonOpt, ServerOpt, _f, ask, fail, print_json, shown

__all__ = ["AllowSunOpt", "RadecOpt", "StarOpt", "op_table", "slew", "target_params"]

RadecOpt = Annotated[str | None, typer.Option(
    "--radec", help='ICRS "RA DEC": "05h34m31.94s +22d00m52.2s", "05:34:31.94 +22:00:52.2" '
                    '(RA in hours) or "83.633 22.0145" (degrees).')]
AltazOpt = Annotated[str | None, typer.Option(
    "--altaz", help='Observed "AZ EL" in degrees (azimuth north through east), e.g. "180 45".')]
AllowSunOpt = Annotated[bool, typer.Option(
    "--allow-sun", help="Engineering override: ignore the Sun and Moon exclusion zones for this "
                        "operation (operators only; the server logs it and tells every client).")]
StarOpt = Annotated[str | None, typer.Option(
    "--star", help='Bright-star name, HIP number or Bayer designation ("Vega", "HIP 91262", '
                   '"alf Lyr"), or a planet.')]


def target_params(radec: str | None, altaz: str | None, star: str | None, *,
                  as_json: bool = False) -> dict[str, Any]:
    """Return the API target parameters of exactly one option, or exit (2) with an error.

    --radec and --altaz are checked here, so a malformed one is a bad argument (2), not a
    refusal by the server (1).
    """
    given = {k: v for k, v in (("radec", radec), ("altaz", altaz), ("star", star)) if v}
    if len(given) != 1:
        raise fail("give exactly one of --radec \"RA DEC\", --altaz \"AZ EL\" or --star NAME",
                   as_json=as_json)
    if radec:
        check_radec(radec, as_json=as_json)
    if altaz:
        check_altaz(altaz, as_json=as_json)
    return given


def check_radec(text: str, *, as_json: bool = False) -> None:
    from virtualstar.astro import AstroError, parse_radec

    try:
        parse_radec(text)
    except AstroError as exc:
        raise fail(f"--radec: {exc}", as_json=as_json) from None


def check_altaz(text: str, *, as_json: bool = False) -> None:
    from virtualstar.astro import AstroError, parse_altaz

    try:
        parse_altaz(text)
    except AstroError as exc:
        raise fail(f"--altaz {exc}", as_json=as_json) from None


def op_table(op: dict[str, Any], title: str) -> Table:
    """Return a rich table of an operation result."""
    info = op.get("info", {})
    t = Table(title=title, show_header=False, title_justify="left")
    t.add_column("what", style="bold")
    t.add_column("value")
    t.add_row("operation", f"#{op['id']} {op['kind']} {shown(op['target'])}: {op['phase']}")
    rows = [("slew time", "slew_time_s", ".1f", " s"),
            ("landing error RMS", "landing_rms_arcsec", ".3f", "″"),
            ("landing error peak", "landing_peak_arcsec", ".3f", "″"),
            ("pass start (UTC)", "pass_start_utc", "", ""),
            ("pass end (UTC)", "pass_end_utc", "", ""),
            ("culmination", "culmination_el_deg", ".1f", "°"),
            ("keyhole deviation (planned)", "keyhole_max_error_arcsec", ".1f", "″"),
            ("error on target RMS", "tracking_rms_arcsec", ".3f", "″"),
            ("error on target peak", "tracking_peak_arcsec", ".3f", "″"),
            ("following error RMS / peak", "following_rms_arcsec", "", ""),
            ("on the sky, with the clock", "on_sky_rms_arcsec", "", ""),
            ("planned deviation", "planned_deviation_peak_arcsec", "", ""),
            ("outcome", "outcome", "", ""),
            ("ended", "ended", "", "")]
    for label, key, fmt, unit in rows:
        if key in info:
            t.add_row(label, _f(info[key], fmt, unit) if fmt else _op_value(key, info))
    return t


def _op_value(key: str, info: dict[str, Any]) -> str:
    """The rows that combine several fields of a track's figures (docs/vss-api.md)."""
    if key == "following_rms_arcsec":  # what the encoders missed of the demand sent
        return (f"{_f(info[key], '.3f', '″')} / {_f(info.get('following_peak_arcsec'), '.3f')}″ "
                "(encoders vs demand)")
    if key == "on_sky_rms_arcsec":
        return f"RMS {_f(info[key], '.3f', '″')}, peak {_f(info.get('on_sky_peak_arcsec'), '.3f')}″"
    if key == "planned_deviation_peak_arcsec":
        why = ", ".join(info.get("planned_deviation") or []) or "none planned"
        return (f"peak {_f(info[key], '.1f', '″')}, {_f(info.get('planned_deviation_s'), '.1f')} s"
                f" beyond {_f(info.get('off_target_threshold_arcsec'), 'g')}″ ({why})")
    if key == "outcome":
        if info[key] == "degraded":
            return (f"[red]degraded[/]: {_f(info.get('off_target_s'), '.1f')} s off target "
                    f"(beyond {_f(info.get('off_target_threshold_arcsec'), 'g')}″), peak "
                    f"{_f(info.get('tracking_peak_arcsec'), '.1f')}″")
        return f"{info[key]}: on target (off it {_f(info.get('off_target_s'), '.1f')} s)"
    return str(info[key])


def slew(radec: RadecOpt = None, altaz: AltazOpt = None, star: StarOpt = None,
         allow_sun: AllowSunOpt = False, server: ServerOpt = None, as_json: JsonOpt = False) -> None:
    """Slew to a target and wait until it lands; a sky target is then tracked until `vs stop`.

    Targets within the Sun's exclusion zone (30°) or below the horizon are refused; a slew
    whose path would cross the zone goes round it.
    """
    params: dict[str, Any] = target_params(radec, altaz, star, as_json=as_json)
    if allow_sun:
        params["allow_sun"] = True
    op = ask(server, "slew", params, progress=True, quiet=as_json)
    if as_json:
        print_json(op)
    else:
        Console().print(op_table(op, "slew"))

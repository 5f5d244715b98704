"""`vs plan`: plan an observing program over a night (satellite passes first, then by priority)."""

from __future__ import annotations

import json
import re
from pathlib import Path
from typing import Annotated

import typer

from virtualstar.cli.status import fail as status_fail
from virtualstar.cli.status import shown
from virtualstar.display import safe_text

__all__ = ["plan"]


def plan(
    program: Annotated[Path, typer.Argument(
        help="Program file (TOML): its [[target]] tables and their constraints; a commented "
             "example is catalogs/data/program-example.toml.", show_default=False)],
    night: Annotated[str | None, typer.Option(
        "--night", help="The night that begins on this date (site's local evening), e.g. "
                        "2024-05-18: from sunset to sunrise as almanacs give them (the Sun's upper limb "
                        "on a sea-level horizon with standard refraction: its centre 50' below).")] = None,
    start: Annotated[str | None, typer.Option(
        "--from", help="Start of the planning window, UTC ISO 8601 (instead of --night).")] = None,
    end: Annotated[str | None, typer.Option(
        "--to", help="End of the planning window, UTC ISO 8601.")] = None,
    out: Annotated[Path | None, typer.Option(
        "-o", "--out", help="Write the plan here (JSON, for vs run).")] = None,
    png: Annotated[Path | None, typer.Option(
        "--png", help="Write a picture: elevation against time, blocks marked, twilight "
                      "shaded.")] = None,
    site_file: Annotated[Path | None, typer.Option(
        "--site-file", envvar="VIRTUALSTAR_SITE", help="Site TOML file with a \\[site] table "
        "(and optionally \\[safety]: Sun zone, horizon profile).")] = None,
    horizon: Annotated[Path | None, typer.Option(
        "--horizon", help="Horizon profile ('AZ_DEG EL_DEG' lines); default: the site file's "
                          "or the flat limit.")] = None,
    mount_geometry: Annotated[str, typer.Option(
        "--mount-geometry", help="The mount's geometry: altaz, fork or german (`vs status "
        "--json` → backend.capabilities.geometry). On a German mount every satellite pass is "
        "cut to its longest stretch on one side of the meridian (no flip mid-track).")] = "altaz",
    as_json: Annotated[bool, typer.Option("--json", help="Print the plan as JSON.")] = False,
) -> None:
    """Plan a night: satellite passes become fixed blocks, sidereal targets fill the gaps by
    priority, slews included; every target left out is listed with the reason."""
    from virtualstar.astro import AstroError, EarthOrientation, UtcTimes, avoidance_from_options
    from virtualstar.astro.site import site_from_options
    from virtualstar.planning import PlanningError, PlanRequest, load_program, plan_program
    from virtualstar.planning.sky import night_window

    def fail(message: str):  # with --json, the error goes to stdout as JSON too
        return status_fail(message, as_json=as_json)

    if mount_geometry not in ("altaz", "fork", "german"):
        raise fail(f"--mount-geometry {mount_geometry!r}: expected altaz, fork or german")
    if (night is None) == (start is None and end is None) or ((start is None) != (end is None)):
        raise fail("give either --night DATE or both --from and --to")
    try:
        site = site_from_options(site_file=site_file)
        zones = avoidance_from_options(site_file=site_file, horizon_file=horizon)
        eop = EarthOrientation.from_astropy_iers_data()
        prog = load_program(program)
        if night is not None:
            a, b = night_window(night, site, eop)
        else:
            try:
                a, b = (int(x) for x in UtcTimes.from_iso([start, end]).to_unix_us())
            except (AstroError, ValueError) as exc:
                raise fail(f"--from {start!r} / --to {end!r}: expected UTC ISO 8601 times, "
                           f"e.g. 2024-05-18T20:00:00Z ({exc})") from None
            if b <= a:
                raise fail(f"--to {end} is not after --from {start}")
            if b - a > 36 * 3600e6:
                raise fail("--from/--to span more than 36 hours: plan one night at a time")
        result = plan_program(PlanRequest(prog, a, b, site, zones,
                                          mount_geometry=mount_geometry), eop)
        if png is not None:
            from virtualstar.planning.plot import plot_plan

            plot_plan(result, prog, site, png, eop)
    except typer.Exit:
        raise
    except (PlanningError, AstroError, ValueError) as exc:
        raise fail(str(exc)) from None
    except OSError as exc:
        raise fail(f"cannot write {exc.filename}: {exc.strerror or exc}") from None
    doc = result.as_dict()
    doc["program_file"] = str(program.resolve())
    if out is not None:
        try:
            out.write_text(json.dumps(doc, indent=1) + "\n", encoding="utf-8")
        except OSError as exc:
            raise fail(f"cannot write {out}: {exc.strerror or exc}") from None
    if as_json:
        typer.echo(json.dumps(doc, indent=1))
        return
    _print(doc, result)


def _print(doc: dict, result) -> None:
    from rich.console import Console
    from rich.table import Table

    t = Table(title=f"{shown(doc['program'])}: {doc['start_utc']} .. {doc['end_utc']} — "
                    f"{doc['priority_weighted_hours']:.2f} priority-weighted hours "
                    f"(planned in {getattr(result, 'timing_s', 0.0):.1f} s)",
              title_justify="left")
    for col in ("start UTC", "end UTC", "target", "#", "prio", "az", "el", "slew"):
        t.add_column(col, justify="left" if col in ("target", "start UTC", "end UTC")
                     else "right")
    for b in doc["blocks"]:
        t.add_row(b["start_utc"][11:19], b["end_utc"][11:19], shown(b["target"]), str(b["repeat"]),
                  f"{b['priority']:g}", f"{b['start_az_deg']:.1f}°", f"{b['start_el_deg']:.1f}°",
                  f"{b['slew_s']:.0f} s")
    console = Console()
    console.print(t)
    left_out = doc["left_out"]
    lines = (left_out_summary(left_out) if console.is_terminal and len(left_out) > LIST_LEFT_OUT
             else [f"left out: {x['target']}: {x['reason']}" for x in left_out])
    for line in lines:
        console.print(safe_text(line), markup=False, highlight=False)


#: At a terminal, more left-out targets than this are summarised by reason (all of them
#: when the output goes to a file or a pipe, and in --json).
LIST_LEFT_OUT = 20
_NAMES_PER_REASON = 4


def left_out_summary(left_out: list[dict]) -> list[str]:
    """Return a few lines for many left-out targets: how many for each kind of reason, and
    the first few names of each (the reason without its target-specific details)."""
    groups: dict[str, list[str]] = {}
    for x in left_out:
        key = re.split(r" \(|: ", x["reason"])[0]
        key = re.sub(r"\d{4}-\d\d-\d\dT[\d:.]+Z", "…", key)
        groups.setdefault(key, []).append(x["target"])
    out = [f"left out: {len(left_out)} targets (each with its reason: vs plan --json, or "
           "vs plan ... | cat):"]
    for key, names in sorted(groups.items(), key=lambda kv: -len(kv[1])):
        shown = ", ".join(names[:_NAMES_PER_REASON])
        more = f" and {len(names) - _NAMES_PER_REASON} more" if len(names) > _NAMES_PER_REASON \
            else ""
        out.append(f"  {len(names):>6} {key}: {shown}{more}")
    return out

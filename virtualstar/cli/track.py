"""`vs track`: track a star or RA/Dec sidereally, or a satellite through its next pass."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer
from rich.console import Console

from virtualstar.cli.slew import AllowSunOpt, RadecOpt, StarOpt, check_radec, op_table
from virtualstar.cli.status import JsonOpt, ServerOpt, ask, fail, print_json

__all__ = ["track"]


def track(
    tle: Annotated[Path | None, typer.Option(
        "--tle", help="TLE file (2- or 3-line sets); tracks the next pass of the satellite.")] = None,
    sat: Annotated[str | None, typer.Option(
        "--sat", help="Satellite name in the --tle file (default: the first).")] = None,
    radec: RadecOpt = None,
    star: StarOpt = None,
    duration: Annotated[float | None, typer.Option(
        "--duration", help="Track this many seconds (mount time), then stop; default: until "
                           "`vs stop` (stars) or the end of the pass (satellites).")] = None,
    wait: Annotated[bool, typer.Option(
        "--wait", help="Wait until the track ends and print its tracking-error summary.")] = False,
    allow_sun: AllowSunOpt = False,
    closed_loop: Annotated[bool, typer.Option(
        "--closed-loop", help="Guide the track with the server's guide camera: along/across "
        "offsets for a satellite, RA/Dec for a star (needs vs server --camera or "
        "--camera-sim).")] = False,
    server: ServerOpt = None,
    as_json: JsonOpt = False,
) -> None:
    """Track a target; returns once tracking has begun (satellite: once the pass is planned)."""
    given = [n for n, v in (("--tle", tle), ("--radec", radec), ("--star", star)) if v]
    if len(given) != 1:
        raise fail("give exactly one of --tle FILE [--sat NAME], --radec \"RA DEC\" or --star NAME",
                   as_json=as_json)
    if sat and not tle:
        raise fail("--sat selects a satellite in a --tle file; give --tle FILE too",
                   as_json=as_json)
    if duration is not None and not duration > 0:
        raise fail(f"--duration {duration}: expected a positive number of seconds",
                   as_json=as_json)
    params: dict = {"wait": wait}
    if allow_sun:
        params["allow_sun"] = True
    if closed_loop:
        params["closed_loop"] = True
    if duration is not None:
        params["duration_s"] = duration
    if tle is not None:
        from virtualstar.files import FileRefused, read_text_file

        try:  # the server takes at most 256 KiB of TLE text
            params["tle"] = read_text_file(tle, max_bytes=256 * 1024, what="TLE file")
        except FileRefused as exc:
            raise fail(f"cannot read {exc}", as_json=as_json) from None
        if sat:
            params["sat"] = sat
    elif radec:
        check_radec(radec, as_json=as_json)
        params["radec"] = radec
    else:
        params["star"] = star
    if wait and not as_json:
        op = _track_showing_the_wait(server, params)
    else:
        op = ask(server, "track", params, progress=True, quiet=as_json)
    if as_json:
        print_json(op)
    else:
        Console().print(op_table(op, "track"))


def _track_showing_the_wait(server: str | None, params: dict) -> dict:
    """Send `track` and show the wait (a live countdown at a terminal, lines when piped)."""
    import sys

    from virtualstar.cli.status import api_password
    from virtualstar.cli.wait_display import WaitDisplay
    from virtualstar.vss_client import default_server_url

    console = Console(stderr=True)
    url = server or default_server_url()
    with WaitDisplay(url, password=api_password(), terminal=console.is_terminal,
                     out=sys.stderr, console=console) as display:
        return ask(server, "track", params, on_event=display.on_event)

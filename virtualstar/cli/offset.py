"""`vs offset`: move the running track by an offset, PWI4-style, within 20 ms."""

from __future__ import annotations

import math
from typing import Annotated, Any

import typer
from rich.console import Console
from rich.table import Table

from virtualstar.cli.status import JsonOpt, ServerOpt, ask, fail, print_json

__all__ = ["offset"]

AXES = ("ra", "dec", "az", "el", "path", "transverse", "all")
OPS = ("add", "set", "rate", "reset")


def offset(
    axis: Annotated[str, typer.Argument(
        help="ra, dec (arcsec on the sky east/north), az, el (arcsec of the axes), path "
        "(along the track: seconds with --seconds, else arcsec), transverse (arcsec across "
        "it, + to the left of travel); all (with --op reset).")],
    value: Annotated[float | None, typer.Argument(
        help="Arcsec (rate: arcsec/s); with --seconds, seconds of time (path only).")] = None,
    op: Annotated[str, typer.Option(
        "--op", help="add (default): the offset grows by VALUE; set: becomes VALUE; rate: "
        "drifts VALUE per second from now; reset: back to 0, no drift.")] = "add",
    seconds: Annotated[bool, typer.Option(
        "--seconds", "-s", help="VALUE is seconds of time along the track (path).")] = False,
    server: ServerOpt = None,
    as_json: JsonOpt = False,
) -> None:
    """Offset the running track (PWI4-style) on ra, dec, az, el, path or transverse: add,
    set, rate or reset; applied gradually from 20 ms after the server accepts it."""
    if axis not in AXES:
        raise fail(f"axis {axis!r}: expected one of {', '.join(AXES)}", as_json=as_json)
    if op not in OPS:
        raise fail(f"--op {op!r}: expected one of {', '.join(OPS)}", as_json=as_json)
    if op == "reset":
        if value is not None:
            raise fail("--op reset takes no VALUE", as_json=as_json)
    elif value is None or not math.isfinite(value):
        raise fail(f"--op {op} needs a finite VALUE", as_json=as_json)
    if seconds and axis != "path":
        raise fail("--seconds is for the path axis (time along the track)", as_json=as_json)
    if axis == "all" and op != "reset":
        raise fail("axis 'all' goes with --op reset", as_json=as_json)
    params: dict[str, Any] = {"axis": axis, "op": op}
    if value is not None:
        params["seconds" if seconds else "arcsec"] = value
    doc = ask(server, "offset", params, quiet=as_json)
    if as_json:
        print_json(doc)
        return
    Console().print(offset_table(doc))


# `vs offset dec -5`: a negative VALUE is an argument, not an unknown option
offset.context_settings = {"ignore_unknown_options": True}  # type: ignore[attr-defined]


def offset_table(doc: dict[str, Any]) -> Table:
    """A table of an offset answer: when it starts and ends, and each axis's totals."""
    t = Table(title=f"offset (operation #{doc['id']}, {doc['mode']})", title_justify="left")
    for col in ("axis", "total", "rate /s", "goal", "moving"):
        t.add_column(col)
    for axis, a in doc["offsets"]["axes"].items():
        unit = "s" if axis == "path" else "arcsec"
        sym = " s" if unit == "s" else "″"
        t.add_row(axis, f"{a[f'total_{unit}']:+.3f}{sym}", f"{a[f'rate_{unit}_per_s']:+.3f}{sym}",
                  f"{a[f'goal_{unit}']:+.3f}{sym}", "yes" if a["moving"] else "no")
    t.caption = (f"from {doc['from_utc']} ({doc['lead_ms']:.0f} ms after acceptance, "
                 f"{doc['sent']}), reached {doc['reached_utc']}")
    return t

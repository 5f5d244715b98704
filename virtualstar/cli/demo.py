"""`vs demo`: slew, sidereal tracking and an ISS pass on the embedded emulator, in simulated time."""

from __future__ import annotations

import asyncio
import json
from pathlib import Path
from typing import Annotated

import typer
from rich.console import Console
from rich.table import Table

from virtualstar.cli.status import JsonOpt, _f, fail

__all__ = ["demo"]


def demo(
    speed: Annotated[float, typer.Option(
        "--speed", help="Simulated time at X times real time.", min=1.0, max=100.0)] = 20.0,
    out: Annotated[Path, typer.Option(
        "--out", help="Folder for the tracking-error plot (PNG).")] = Path("demo-output"),
    sidereal: Annotated[float, typer.Option(
        "--sidereal", help="Seconds (mount time) of sidereal tracking.", min=1.0)] = 30.0,
    as_json: JsonOpt = False,
) -> None:
    """Run the demo in one process (about a minute) and print slew times and tracking errors."""
    from virtualstar.demo import DemoConfig, run_demo

    console = Console(stderr=True)
    say = (lambda text: None) if as_json else (lambda text: console.print(f"[dim]{text}"))
    try:
        result = asyncio.run(run_demo(DemoConfig(speed=speed, out_dir=out, sidereal_s=sidereal),
                                      say))
    except OSError as exc:
        raise fail(f"cannot write the plot into {out}: {exc.strerror or exc}", 1) from None
    except RuntimeError as exc:
        raise fail(str(exc), 1) from None
    if as_json:
        typer.echo(json.dumps(result.as_dict(), allow_nan=False, default=str, indent=2))
        return
    t = Table(title=f"VirtualStar demo ({result.wall_s:.0f} s wall time, x{speed:g})",
              title_justify="left")
    for col in ("phase", "duration", "slew time", "error RMS", "error peak"):
        t.add_column(col, justify="left" if col == "phase" else "right")
    for p in result.phases:
        t.add_row(p.name, f"{(p.to_us - p.from_us) / 1e6:.1f} s", _f(p.slew_time_s, ".1f", " s"),
                  _f(p.rms_arcsec, ".3f", "″"), _f(p.peak_arcsec, ".3f", "″"))
    Console().print(t)
    info = result.pass_info
    Console().print(f"{info.get('satellite')}: culmination {info.get('culmination_deg', 0):.1f}°, "
                    f"max azimuth rate {_f(info.get('max_az_rate_deg_s'), '.2f', '°/s')}, keyhole "
                    f"{'used' if info.get('keyhole') else 'not needed'}")
    Console().print(f"plot: {result.plot}")

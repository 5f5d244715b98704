"""`vs demo`: slew, sidereal tracking and an ISS pass on the embedded emulator, in simulated time."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Annotated

import typer
from rich.console import Console
from rich.table import Table

from virtualstar.cli.status import JsonOpt, _f, fail

__all__ = ["demo"]


def demo(
    speed: Annotated[str, typer.Option(
        "--speed", help="'max': lockstep simulated time as fast as the CPU allows (the same "
        "figures on every run); X: lockstep at up to X times real time.")] = "max",
    out: Annotated[Path, typer.Option(
        "--out", help="Folder for the tracking-error plot (PNG).")] = Path("demo-output"),
    sidereal: Annotated[float, typer.Option(
        "--sidereal", help="Seconds (mount time) of sidereal tracking.", min=1.0)] = 30.0,
    as_json: JsonOpt = False,
) -> None:
    """Run the demo in one process (well under a minute) and print slew times and errors.

    Per phase: the error on target (the boresight against the target's true place), the
    deviation planned apart (a keyhole), the encoders' following error and the on-sky error.

    The embedded emulator and the server share one clock (lockstep simulated time): the
    figures are the same on every run and host; only the wall time differs.
    """
    from virtualstar.cli.server import parse_speed
    from virtualstar.demo import DemoConfig, run_demo

    pace = parse_speed(speed)
    console = Console(stderr=True)
    say = (lambda text: None) if as_json else (lambda text: console.print(f"[dim]{text}"))
    try:
        result = run_demo(DemoConfig(speed=pace, out_dir=out, sidereal_s=sidereal), say)
    except OSError as exc:
        raise fail(f"cannot write the plot into {out}: {exc.strerror or exc}", 1) from None
    except RuntimeError as exc:
        raise fail(str(exc), 1) from None
    if as_json:
        typer.echo(json.dumps(result.as_dict(), allow_nan=False, default=str, indent=2))
        return
    pace_text = "as fast as the CPU allows" if pace is None else f"up to x{pace:g}"
    t = Table(title=f"VirtualStar demo ({result.wall_s:.0f} s wall time, lockstep {pace_text}); "
                    "errors in arcsec, RMS/peak", title_justify="left")
    t.add_column("phase", overflow="fold", min_width=16)
    for col in ("slew", "on target", "planned", "following", "on sky"):
        t.add_column(col, justify="right", no_wrap=True)
    for p in result.phases:
        t.add_row(f"{p.name}, {(p.to_us - p.from_us) / 1e6:.0f} s", _f(p.slew_time_s, ".1f", " s"),
                  f"{_f(p.on_target_rms_arcsec, '.3f')}/{_f(p.on_target_peak_arcsec, '.3f')}",
                  _f(p.planned_deviation_peak_arcsec, ".3f"),
                  f"{_f(p.rms_arcsec, '.3f')}/{_f(p.peak_arcsec, '.3f')}",
                  f"{_f(p.on_sky_rms_arcsec, '.3f')}/{_f(p.on_sky_peak_arcsec, '.3f')}")
    Console().print(t)
    info = result.pass_info
    Console().print(f"{info.get('satellite')}: culmination {info.get('culmination_deg', 0):.1f}°, "
                    f"max azimuth rate {_f(info.get('max_az_rate_deg_s'), '.2f', '°/s')}, keyhole "
                    f"{'used' if info.get('keyhole') else 'not needed'}")
    clock = max((abs(p.clock_offset_us or 0) for p in result.phases), default=0)
    Console().print("on target: the boresight (encoders through the pointing model) against "
                    "the target's true place; planned: the demand against it (peak; a keyhole), "
                    "apart; following: the encoders against the demand; on sky: on target with "
                    f"the mount clock's offset (≤ {clock} µs) × the target's rate")
    Console().print(f"plot: {result.plot}")

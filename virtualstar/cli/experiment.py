"""`vs experiment`: reproduce the paper's validation runs on the emulator in simulated time."""

from __future__ import annotations

import asyncio
import json
from pathlib import Path
from typing import Annotated

import typer
from rich.progress import BarColumn, Progress, TextColumn

from virtualstar.recorder.exceptions import RecorderError

# The experiment (the emulator, the recorder, matplotlib) is imported when it runs.

app = typer.Typer(help="Reproduce the paper's experiments on the mount emulator.",
                  no_args_is_help=True, add_completion=False)


def _fail(message: str, code: int = 2) -> typer.Exit:
    typer.echo(f"vs experiment: error: {message}", err=True)
    return typer.Exit(code)


def _hms(seconds: float) -> str:
    s = int(seconds)
    return f"{s // 3600:02d}:{s % 3600 // 60:02d}:{s % 60:02d}"


@app.command()
def sine(
    axis: Annotated[str, typer.Option("--axis", help="az or el.")] = "az",
    hours: Annotated[float, typer.Option("--hours", help="Simulated hours to run.")] = 12.0,
    record_hz: Annotated[float, typer.Option("--record-hz", help="Recording rate, Hz (≤ 10000).")] = 1000.0,
    out: Annotated[Path, typer.Option("--out", help="Directory for the store and the plots.")] = Path("sine-experiment"),
    period_s: Annotated[float, typer.Option("--period-s", help="Period of the speed's sinusoid, s.")] = 600.0,
    drift: Annotated[float | None, typer.Option(
        "--drift-rad-min", help="Average axis speed, rad/min (default: the paper's, "
                                "0.0095).")] = None,
    json_out: Annotated[bool, typer.Option("--json", help="Print the result as JSON.")] = False,
    no_progress: Annotated[bool, typer.Option("--no-progress", help="Hide the progress bar.")] = False,
) -> None:
    """Drive one axis along a drifting sinusoid for --hours of simulated time, recording
    position, motor current and tracking error at --record-hz into OUT/store, then write
    OUT/fig6_overview.png and OUT/fig7_first_2s.png.

    The emulator runs in this process as fast as the recorder keeps up; the trajectory
    is pushed through ASTCom (traj.push_rates) directly, not through the VirtualStar Server.
    """
    from virtualstar.recorder.experiment import (
        DRIFT_RAD_PER_MIN,
        SineExperiment,
        run_sine_experiment,
    )

    try:
        exp = SineExperiment(axis=axis, hours=hours, record_hz=record_hz, period_s=period_s,
                             drift_rad_per_min=DRIFT_RAD_PER_MIN if drift is None else drift)
    except ValueError as exc:
        raise _fail(str(exc)) from None
    if out.exists() and (out / "store").exists() and any((out / "store").iterdir()):
        raise _fail(f"{out}/store already holds a recording; choose another --out")
    total = exp.hours * 3600
    with Progress(TextColumn("simulated {task.fields[sim]} / {task.fields[end]}"), BarColumn(),
                  TextColumn("{task.percentage:>3.0f}%  ×{task.fields[speed]:.0f} real time"),
                  disable=no_progress or json_out, transient=False) as progress:
        task = progress.add_task("sine", total=total, sim=_hms(0), end=_hms(total), speed=0.0)

        def on_progress(sim_s: float, total_s: float, speed: float) -> None:
            progress.update(task, completed=min(sim_s, total), sim=_hms(sim_s), speed=speed)

        try:
            result = asyncio.run(run_sine_experiment(exp, out, on_progress=on_progress))
        except (RecorderError, OSError) as exc:
            raise _fail(str(exc), 1) from None
    doc = result.as_dict()
    if json_out:
        typer.echo(json.dumps(doc))
        return
    typer.echo(f"{doc['samples_per_signal']} samples per signal, {doc['lost']} lost; "
               f"{result.sim_s:.0f} s simulated in {result.wall_s:.1f} s (×{result.speed:.0f})")
    typer.echo(f"store: {result.store}")
    for p in result.plots:
        typer.echo(f"plot:  {p}")

"""`vs run`: run a plan on a VSS (or the embedded emulator), block by block."""

from __future__ import annotations

import json
import sys
from pathlib import Path
from typing import Annotated, Any

import typer

from virtualstar.cli.status import JsonOpt, ServerOpt, ask, print_json
from virtualstar.cli.status import fail as status_fail

__all__ = ["run"]


def run(
    plan: Annotated[Path, typer.Argument(
        help="Plan file written by `vs plan ... -o PLAN.json`.", show_default=False)],
    server: ServerOpt = None,
    emulator: Annotated[bool, typer.Option(
        "--emulator", help="Run on the embedded emulator in lockstep simulated time instead "
                           "of a server (the whole night, as fast as --speed allows).")] = False,
    speed: Annotated[str, typer.Option(
        "--speed", help="With --emulator: 'max' (as fast as the CPU allows) or at most N× "
                        "real time.")] = "max",
    resume: Annotated[Path | None, typer.Option(
        "--resume", help="A previous run's result (-o/--json of vs run): its finished blocks "
                         "count, and the rest of the night is planned again from now.")] = None,
    out: Annotated[Path | None, typer.Option(
        "-o", "--out", help="Write the run's result here (JSON; give it to --resume).")] = None,
    png: Annotated[Path | None, typer.Option(
        "--png", help="Write a picture: planned and observed blocks, re-plans, tracking "
                      "error per block.")] = None,
    record: Annotated[list[str] | None, typer.Option(
        "--record", help="Record this signal for the whole run (repeat for several; "
                         "`astcom list URL` shows the names), e.g. axis.az.error_arcsec.",
        show_default=False)] = None,
    record_rate: Annotated[float, typer.Option(
        "--record-rate", help="Samples per second per recorded signal.")] = 100.0,
    store: Annotated[list[str] | None, typer.Option(
        "--store", help="Where --record writes: parquet:DIR or "
                        "influx:http://127.0.0.1:8086/DB (repeat for several).",
        show_default="parquet:run-recording")] = None,
    mount: Annotated[str | None, typer.Option(
        "--mount", help="With --server and --record: the mount's ASTCom endpoint to record "
                        "from (password: ASTCOM_PASSWORD).", show_default=False)] = None,
    as_json: JsonOpt = False,
) -> None:
    """Run a plan block by block through the VSS API: each block's start and end, slew time and
    tracking error (encoder and on sky, RMS and peak); the rest of the night is planned again
    after a missed, late or faulted block. Ctrl-C (or `vs stop`) ends it; --resume goes on.

    --record NAME records mount signals for the whole run into --store (read with vs data)."""

    def fail(message: str, code: int = 2):  # with --json, the error goes to stdout too
        return status_fail(message, code, as_json=as_json)

    from virtualstar.files import FileRefused, read_text_file

    try:  # a regular file of at most 64 MiB: a FIFO or /dev/zero would never end
        doc = json.loads(read_text_file(plan, max_bytes=64 << 20, what="plan"))
    except FileRefused as exc:
        raise fail(f"cannot read {exc}") from None
    except json.JSONDecodeError as exc:
        raise fail(f"{plan}: not JSON ({exc}); write a plan with vs plan PROGRAM --night DATE "
                   "-o PLAN.json") from None
    from virtualstar.planning import PlanningError
    from virtualstar.planning.program import Program
    from virtualstar.planning.scheduler import Plan

    try:
        if not isinstance(doc, dict):
            raise PlanningError("not a plan (a JSON object written by vs plan) ")
        Program.from_dict(Plan.from_dict(doc).program_spec)
    except PlanningError as exc:
        raise fail(f"{plan}: {exc}") from None
    done = None
    if resume is not None:
        try:
            previous = json.loads(resume.read_text(encoding="utf-8"))
            done = [*previous.get("done_before", []), *previous["records"]]
        except (OSError, ValueError, KeyError, TypeError, AttributeError) as exc:
            raise fail(f"--resume {resume}: not a vs run result ({exc})") from None
    recording = _recording(record, record_rate, store, emulator, server, mount, fail)
    show = _Progress(quiet=as_json)
    if emulator:
        from virtualstar.cli.server import parse_speed
        from virtualstar.planning.emulated import run_plan_on_emulator
        from virtualstar.recorder.exceptions import RecorderError

        pace = parse_speed(speed)
        try:
            result = run_plan_on_emulator(doc, speed=pace, done=done, on_event=show,
                                          record=recording)
        except KeyboardInterrupt:
            raise fail("interrupted: the simulated night ends with the process", 130) from None
        except RecorderError as exc:
            raise fail(f"--record: {exc}") from None
    elif recording is not None:
        result = _on_server_recorded(server, mount, doc, done, show, fail, recording, as_json)
    else:
        result = _on_server(server, doc, done, show, as_json)
    _report(result, out, png, as_json, fail)
    if result.get("state") == "failed":
        raise typer.Exit(1)


def _recording(names, rate_hz: float, stores, emulator: bool, server, mount, fail):
    """The --record options checked before anything runs (None: nothing to record)."""
    if not names:
        if stores or mount:
            raise fail("--store and --mount go with --record NAME (the signals to record)")
        return None
    from virtualstar.planning.recording import DEFAULT_RECORD_STORE, RunRecording
    from virtualstar.recorder.exceptions import RecorderError  # loads pyarrow: only to record

    if not emulator and mount is None:
        raise fail("--record on a server needs --mount URL, the mount's ASTCom endpoint "
                   "(e.g. ws://127.0.0.1:8765); with --emulator the run records in process")
    try:
        return RunRecording(tuple(names), rate_hz, tuple(stores or [DEFAULT_RECORD_STORE]))
    except RecorderError as exc:
        raise fail(str(exc)) from None


def _on_server_recorded(server, mount: str, doc, done, show, fail, recording,
                        as_json: bool) -> dict[str, Any]:
    import os

    from astcom_client import AstcomError
    from virtualstar.planning.recording import ThreadedRecording
    from virtualstar.recorder.exceptions import RecorderError

    rec = ThreadedRecording(recording, mount, password=os.environ.get("ASTCOM_PASSWORD"))
    try:
        rec.start()
    except (RecorderError, AstcomError, OSError) as exc:
        raise fail(f"--record from {mount}: {exc}") from None
    try:
        result = _on_server(server, doc, done, show, as_json)
    finally:
        summary = rec.stop()
    result["recording"] = summary
    return result


def _on_server(server: str | None, doc: dict, done, show, as_json: bool) -> dict[str, Any]:
    try:
        return ask(server, "run_plan", {"plan": doc, "done": done, "wait": True},
                   quiet=as_json, on_event=show)
    except KeyboardInterrupt:
        typer.echo("stopping the program (the mount comes to rest) ...", err=True)
        ask(server, "stop", {}, quiet=as_json)
        return ask(server, "program", {}, quiet=as_json)


class _Progress:
    """Print one line per finished block (and re-plan) as the server reports them."""

    def __init__(self, quiet: bool) -> None:
        self.quiet = quiet
        self.seen = 0
        self.replans = 0

    def __call__(self, kind: str, data: dict[str, Any]) -> None:
        if self.quiet or kind != "program":
            return
        last, blocks = data.get("last"), (data.get("summary") or {}).get("blocks", 0)
        if last is not None and blocks > self.seen:
            self.seen = blocks
            print(_block_line(last), file=sys.stderr, flush=True)
        if data.get("replans", 0) > self.replans:
            self.replans = data["replans"]
            print(f"  re-planned the rest of the night ({self.replans})", file=sys.stderr,
                  flush=True)


def _block_line(r: dict[str, Any]) -> str:
    figs = ("" if r.get("encoder_rms_arcsec") is None else
            f" encoder {r['encoder_rms_arcsec']:.3f}″ RMS / {r['encoder_peak_arcsec']:.3f}″ peak,"
            f" on sky {r['on_sky_rms_arcsec']:.3f}″ / {r['on_sky_peak_arcsec']:.3f}″")
    err = f" ({r['error']['message']})" if r.get("error") else ""
    slew = "" if r.get("slew_s") is None else f" slew {r['slew_s']:.0f} s"
    return (f"{(r.get('start_utc') or r['planned_start_utc'])[11:19]} {r['target']} "
            f"#{r['repeat']}: {r['outcome']}{slew}{figs}{err}")


def _report(result: dict[str, Any], out: Path | None, png: Path | None, as_json: bool,
            fail) -> None:
    if out is not None:
        try:
            out.write_text(json.dumps(result, indent=1) + "\n", encoding="utf-8")
        except OSError as exc:
            raise fail(f"cannot write {out}: {exc.strerror or exc}") from None
    if png is not None:
        from virtualstar.planning.plot import plot_run

        try:
            plot_run(result, png)
        except OSError as exc:
            raise fail(f"cannot write {png}: {exc.strerror or exc}") from None
    if as_json:
        print_json(result)
        return
    from rich import box
    from rich.console import Console
    from rich.table import Table

    s = result.get("summary", {})
    wall = f", {result['wall_s']:.0f} s wall time" if "wall_s" in result else ""
    t = Table(title=f"{result.get('program')}: {result.get('state')} — {s.get('done', 0)} done, "
                    f"{s.get('late', 0)} late, {s.get('missed', 0)} missed, "
                    f"{s.get('faulted', 0)} faulted, {len(result.get('replans', []))} re-plans; "
                    f"{s.get('priority_weighted_hours', 0.0):.2f} priority-weighted h{wall}",
              title_justify="left", box=box.SIMPLE_HEAD)
    for col in ("start", "min", "block", "outcome", "slew", "enc″ RMS/pk", "sky″ RMS/pk"):
        t.add_column(col, justify="left" if col in ("start", "block", "outcome") else "right")

    def pair(r: dict[str, Any], key: str) -> str:
        if r.get(f"{key}_rms_arcsec") is None:
            return "-"
        return f"{r[f'{key}_rms_arcsec']:.3f}/{r[f'{key}_peak_arcsec']:.3f}"

    for r in result.get("records", []):
        minutes = "-" if r.get("observed_s") is None else f"{r['observed_s'] / 60:.1f}"
        t.add_row((r.get("start_utc") or r["planned_start_utc"])[11:19], minutes,
                  f"{r['target']} #{r['repeat']}", r["outcome"],
                  "-" if r.get("slew_s") is None else f"{r['slew_s']:.0f} s",
                  pair(r, "encoder"), pair(r, "on_sky"))
    console = Console()
    console.print(t)
    for rp in result.get("replans", []):
        console.print(f"re-planned at {rp['at_utc'][11:19]}: {rp['reason']} → {rp['blocks']} "
                      "blocks", markup=False)
    if result.get("error"):
        console.print(f"ended: {result['error']['message']}", markup=False)

"""`vs run`: run a plan on a VSS (or the embedded emulator), block by block."""

from __future__ import annotations

import json
import sys
from pathlib import Path
from typing import Annotated, Any

import typer

from virtualstar.cli.status import JsonOpt, ServerOpt, ask, print_json, shown
from virtualstar.cli.status import fail as status_fail
from virtualstar.display import safe_text

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
    inject: Annotated[list[str] | None, typer.Option(
        "--inject", help="With --emulator: write an emulator parameter at a time of the night, "
                         "NAME=VALUE@WHEN (WHEN: ISO-8601 UTC, or +S seconds after the plan's "
                         "start), e.g. axis.az.inject_winding_fault=0.2@+900 (a fault to "
                         "rehearse; docs/mount-emulator.md, \"Fault injection\"); repeat for "
                         "several.", show_default=False)] = None,
    as_json: JsonOpt = False,
) -> None:
    """Run a plan block by block through the VSS API: each block's start, delay and slew, the
    error on target (boresight vs the target's true place) with the planned deviation apart,
    and the outcome (done, degraded, late, missed, faulted); the rest of the night is planned
    again after a missed, late or faulted block. Ctrl-C (or `vs stop`) ends it; --resume goes on.

    Per block: the error on target (RMS, peak, seconds off target), the planned deviation (a
    keyhole), the encoders' following error and the on-sky error. A block off target for over
    1 s is `degraded`; one that begins over 10 s late is `late`.

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
    writes = _writes(inject or [], doc, emulator, fail)
    show = _Progress(quiet=as_json)
    if emulator:
        from virtualstar.cli.server import parse_speed
        from virtualstar.planning.emulated import run_plan_on_emulator
        from virtualstar.recorder.exceptions import RecorderError

        pace = parse_speed(speed)
        try:
            result = run_plan_on_emulator(doc, speed=pace, done=done, on_event=show,
                                          record=recording, writes=writes)
        except KeyboardInterrupt:
            raise fail("interrupted: the simulated night ends with the process", 130) from None
        except RecorderError as exc:
            raise fail(f"--record: {exc}") from None
        except PlanningError as exc:
            raise fail(f"--inject: {exc}") from None
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


def _writes(specs: list[str], doc: dict, emulator: bool, fail) -> list:
    """The --inject options as timed writes (checked before anything runs)."""
    if not specs:
        return []
    if not emulator:
        raise fail("--inject goes with --emulator (a real mount takes no injected faults)")
    from virtualstar.astro import UtcTimes
    from virtualstar.planning.emulated import TimedWrite

    out = []
    for spec in specs:
        what, _, when = spec.rpartition("@")
        name, _, value = what.partition("=")
        try:
            number = float(value)
            if when.startswith("+"):
                t_us = int(doc["start_us"]) + round(float(when[1:]) * 1e6)
            else:
                t_us = int(UtcTimes.from_iso([when]).to_unix_us()[0])
        except (ValueError, KeyError, TypeError):
            raise fail(f"--inject {spec!r}: expected NAME=VALUE@WHEN, WHEN an ISO-8601 UTC "
                       "time or +S seconds after the plan's start (e.g. "
                       "axis.az.inject_friction_growth=5@+1200)") from None
        if not name.strip():
            raise fail(f"--inject {spec!r}: no parameter name before '='")
        out.append(TimedWrite(t_us, name.strip(), number))
    return out


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
    figs = ""
    if r.get("encoder_rms_arcsec") is not None:
        if r.get("on_target_rms_arcsec") is not None:
            figs += (f" on target {_f(r['on_target_rms_arcsec'], '.3f')}″ RMS / "
                     f"{_f(r.get('on_target_peak_arcsec'), '.3f')}″ peak"
                     + (f", {r['off_target_s']:.1f} s off target" if r.get("off_target_s")
                        else "") + ",")
        figs += (f" following {_f(r['encoder_rms_arcsec'], '.3f')}″ /"
                 f" {_f(r['encoder_peak_arcsec'], '.3f')}″")
        if r.get("planned_deviation"):
            figs += (f"; planned deviation {_f(r.get('planned_deviation_peak_arcsec'), '.1f')}″ "
                     f"({', '.join(r['planned_deviation'])})")
    err = f" ({safe_text(r['error']['message'])})" if r.get("error") else ""
    slew = "" if r.get("slew_s") is None else f" slew {r['slew_s']:.0f} s"
    delay = f" {r['delay_s']:.0f} s late" if (r.get("delay_s") or 0) >= 1.0 else ""
    return (f"{(r.get('start_utc') or r['planned_start_utc'])[11:19]} {safe_text(r['target'])} "
            f"#{r['repeat']}: {r['outcome']}{delay}{slew}{figs}{err}")


def _f(value: Any, fmt: str) -> str:
    return "-" if value is None else f"{value:{fmt}}"


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
    from rich.console import Console
    from rich.table import Table

    s = result.get("summary", {})
    wall = f", {result['wall_s']:.0f} s wall time" if "wall_s" in result else ""
    t = Table(title=f"{shown(result.get('program'))}: {result.get('state')} — {s.get('done', 0)} done, "
                    f"{s.get('degraded', 0)} degraded, {s.get('late', 0)} late, "
                    f"{s.get('missed', 0)} missed, {s.get('faulted', 0)} faulted, "
                    f"{len(result.get('replans', []))} re-plans; "
                    f"{s.get('priority_weighted_hours', 0.0):.2f} priority-weighted h on "
                    f"target{wall}", title_justify="left", box=None, header_style="bold underline",
              padding=(0, 1), pad_edge=False)
    for col in ("start", "block", "outcome", "late", "slew", "on target″", "off", "plan″",
                "following″"):
        t.add_column(col, justify="left" if col in ("start", "block", "outcome") else "right",
                     no_wrap=True)

    def pair(r: dict[str, Any], key: str) -> str:
        if r.get(f"{key}_rms_arcsec") is None:
            return "-"
        return f"{r[f'{key}_rms_arcsec']:.3f}/{r[f'{key}_peak_arcsec']:.3f}"

    def planned(r: dict[str, Any]) -> str:
        peak = r.get("planned_deviation_peak_arcsec")
        why = ", ".join(r.get("planned_deviation") or [])
        return "-" if peak is None else f"{peak:.2f}" + (f" {why}" if why else "")

    for r in result.get("records", []):
        t.add_row((r.get("start_utc") or r["planned_start_utc"])[11:16],
                  f"{shown(r['target'])} #{r['repeat']}", r["outcome"],
                  "-" if r.get("delay_s") is None else f"{r['delay_s']:.0f}",
                  "-" if r.get("slew_s") is None else f"{r['slew_s']:.0f}",
                  pair(r, "on_target"),
                  "-" if r.get("off_target_s") is None else f"{r['off_target_s']:.1f}",
                  planned(r), pair(r, "encoder"))
    console = Console()
    console.print(t)
    console.print("start: UTC; late, slew: s; on target: the boresight against the target's "
                  "true place (RMS/peak), off: seconds beyond the threshold; plan: the planned "
                  "deviation, the demand against that place (peak), apart; following: the "
                  "encoders against the demand; -o/--json: every figure", markup=False)
    for rp in result.get("replans", []):
        console.print(f"re-planned at {rp['at_utc'][11:19]}: {rp['reason']} → {rp['blocks']} "
                      "blocks", markup=False)
    if result.get("error"):
        console.print(f"ended: {safe_text(result['error']['message'])}", markup=False)

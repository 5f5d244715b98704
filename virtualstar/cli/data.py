"""`vs data`: query, plot and export what `vs record` stored."""

from __future__ import annotations

import json
import sys
from pathlib import Path
from typing import Annotated

import typer

from virtualstar.cli.store_warnings import reports_damage
from virtualstar.recorder.exceptions import RecorderError
from virtualstar.recorder.timeparse import parse_time_bound, utc_text

# The stores (numpy, pyarrow) are imported when a command runs: --help stays fast.

app = typer.Typer(help="Query, plot and export recorded signals.", no_args_is_help=True,
                  add_completion=False)

StoreArg = Annotated[str, typer.Argument(
    help="parquet:DIR (or DIR) or influx:http://HOST:8086/DB (credentials: INFLUX_USERNAME/INFLUX_PASSWORD).")]
FromOpt = Annotated[str, typer.Option(
    "--from", help="Window start: start, +S (seconds after the first sample), -S (before the "
                   "last), ISO-8601 UTC, or mount µs.")]
ToOpt = Annotated[str, typer.Option("--to", help="Window end (excluded), same forms; 'end' includes the last sample.")]
NamesOpt = Annotated[list[str] | None, typer.Option(
    "--names", help="Signals to return (comma-separated or repeated); default: all.")]


def _fail(message: str, code: int = 2) -> typer.Exit:
    typer.echo(f"vs data: error: {message}", err=True)
    return typer.Exit(code)


class OutsideStore(RecorderError):
    """The asked window holds no time of the store at all (exit 1, with the store's span)."""


def _error(exc: Exception) -> typer.Exit:
    """Return the Exit for a store or query error: 1 for a window outside the store."""
    return _fail(str(exc), 1 if isinstance(exc, OutsideStore) else 2)


def _open(store: str):
    """Open a store's reader; say on stderr when it recovered a recording whose recorder died."""
    from virtualstar.recorder.stores import open_reader

    reader = open_reader(store)
    recovered = getattr(reader, "recovered", None)
    if recovered is not None:
        typer.echo(f"vs data: warning: {recovered}", err=True)
    return reader


def _names(names: list[str] | None) -> list[str] | None:
    if not names:
        return None
    return [n.strip() for item in names for n in item.split(",") if n.strip()]


def _window(reader, t_from: str, t_to: str) -> tuple[int, int]:
    """Return the [from, to) window asked for; raise OutsideStore when it holds none of the
    store's time, QueryError when it is empty."""
    start, end = reader.time_range()
    a = parse_time_bound(t_from, start, end, option="--from")
    b = parse_time_bound(t_to, start, end, option="--to")
    span = (f"the store spans {utc_text(start)} to {utc_text(end)} ({start}..{end} µs, "
            f"{(end - start) / 1e6:g} s)")
    if a > end or b <= start:
        where = "after the store's last sample" if a > end else "before its first sample"
        raise OutsideStore(f"the window --from {t_from!r} ({utc_text(a)}) --to {t_to!r} "
                           f"({utc_text(b)}) lies {where}; {span}")
    if b <= a:
        raise RecorderError(f"empty window: --to {t_to!r} ({b} µs) is not after --from "
                            f"{t_from!r} ({a} µs); {span}")
    return a, b


def _warn_if_no_samples(n: int, a: int, b: int) -> None:
    if n == 0:
        typer.echo(f"vs data: warning: no samples from {utc_text(a)} to {utc_text(b)} (a gap "
                   "in the recording; `vs data info` lists the gaps)", err=True)


def _plain(v) -> list:
    if v.dtype.kind == "f":
        return [None if x != x else x for x in v.tolist()]  # NaN is not JSON
    return v.tolist()


@app.command()
@reports_damage("vs data")
def query(
    store: StoreArg,
    t_from: FromOpt = "start",
    t_to: ToOpt = "end",
    names: NamesOpt = None,
    decimate: Annotated[int | None, typer.Option(
        "--decimate", help="Return a min/max envelope of about N buckets instead of every sample.")] = None,
    json_out: Annotated[bool, typer.Option("--json", help="Print JSON.")] = False,
    csv_out: Annotated[bool, typer.Option("--csv", help="Print CSV (t_us, then one column per signal).")] = False,
) -> None:
    """Print a time window at full rate, or its min/max envelope with --decimate N.

    JSON at full rate: {"store", "from_t_us", "to_t_us", "names", "t_us": [...],
    "values": {name: [...]}}; with --decimate: {"bucket_us", "t_us", "n", "min": {...},
    "max": {...}}. Without --json/--csv a short summary is printed.
    """
    if json_out and csv_out:
        raise _fail("give --json or --csv, not both")
    if decimate is not None and decimate < 1:
        raise _fail(f"--decimate {decimate}: expected a number of buckets >= 1")
    try:
        reader = _open(store)
        a, b = _window(reader, t_from, t_to)
        wanted = _names(names)
        if decimate is not None:
            env = reader.envelope(a, b, wanted, decimate)
            doc = {"store": store, "from_t_us": a, "to_t_us": b, "names": env.names,
                   "bucket_us": env.bucket_us, "t_us": env.t_us.tolist(), "n": env.n.tolist(),
                   "min": {k: _plain(v) for k, v in env.mins.items()},
                   "max": {k: _plain(v) for k, v in env.maxs.items()}}
            if csv_out:
                cols = ["t_us", "n"] + [f"{k}__{m}" for k in env.names for m in ("min", "max")]
                typer.echo(",".join(cols))
                for i in range(len(env)):
                    row = [env.t_us[i], env.n[i]] + [x for k in env.names
                                                     for x in (env.mins[k][i], env.maxs[k][i])]
                    typer.echo(",".join(repr(x.item()) if hasattr(x, "item") else str(x) for x in row))
                return
            _warn_if_no_samples(int(env.n.sum()), a, b)
            if json_out:
                typer.echo(json.dumps(doc))
                return
            typer.echo(f"{len(env)} buckets of {env.bucket_us / 1e6:g} s from {utc_text(a)} "
                       f"to {utc_text(b)}")
            import numpy as np

            for k in env.names:
                lo = float(np.nanmin(env.mins[k])) if len(env) else float("nan")
                hi = float(np.nanmax(env.maxs[k])) if len(env) else float("nan")
                typer.echo(f"  {k}: min {lo!r}, max {hi!r}")
            return
        block = reader.window(a, b, wanted)
    except (RecorderError, OSError) as exc:
        raise _error(exc) from None
    _warn_if_no_samples(len(block), a, b)
    if csv_out:
        from virtualstar.recorder.export import write_csv

        write_csv([block], block.names, sys.stdout)
        return
    if json_out:
        typer.echo(json.dumps({"store": store, "from_t_us": a, "to_t_us": b, "names": block.names,
                               "t_us": block.t_us.tolist(),
                               "values": {k: _plain(v) for k, v in block.columns.items()}}))
        return
    typer.echo(f"{len(block)} samples from {utc_text(a)} to {utc_text(b)}")
    for k, v in block.columns.items():
        if len(v):
            typer.echo(f"  {k}: min {v.min().item()!r}, max {v.max().item()!r}, "
                       f"mean {float(v.mean())!r}")


@app.command()
@reports_damage("vs data")
def info(store: StoreArg,
         json_out: Annotated[bool, typer.Option("--json", help="Print JSON.")] = False) -> None:
    """Print the signals, time span, sample count and gaps of a store.

    Damaged files are named on stderr and skipped; each is a gap whose reason starts with
    "damaged" (`vs data recover DIR` sets them aside).
    """
    from virtualstar.recorder.parquet_store import ParquetStoreReader

    try:
        reader = _open(store)
        start, end = reader.time_range()
        doc = {"store": store, "signals": [s.__dict__ for s in reader.signals()],
               "first_t_us": start, "last_t_us": end, "first_utc": utc_text(start),
               "last_utc": utc_text(end), "samples": reader.count(),
               "gaps": [g.__dict__ for g in reader.gaps()]}
        if isinstance(reader, ParquetStoreReader):
            doc["bytes"] = sum(f.stat().st_size for f in reader.path.rglob("*") if f.is_file())
            doc["writer_pid"] = reader.writer_pid  # a live recorder writing it now, or None
    except (RecorderError, OSError) as exc:
        raise _error(exc) from None
    if json_out:
        typer.echo(json.dumps(doc))
        return
    typer.echo(f"{store}: {doc['samples']} samples from {doc['first_utc']} to {doc['last_utc']}")
    for s in doc["signals"]:
        typer.echo(f"  {s['name']} [{s['unit']}] {s['dtype']}")
    typer.echo(f"  {len(doc['gaps'])} gap(s), {sum(max(0, g['lost_samples']) for g in doc['gaps'])} "
               "samples known lost")
    for g in doc["gaps"]:
        if g["reason"].startswith("damaged"):
            typer.echo(f"  {g['reason']}")


@app.command()
@reports_damage("vs data")
def plot(
    store: StoreArg,
    out: Annotated[Path, typer.Option("-o", "--out", help="Directory for the PNG files (created).")],
    t_from: FromOpt = "start",
    t_to: ToOpt = "end",
    names: NamesOpt = None,
    window: Annotated[float, typer.Option("--window", help="Seconds at full rate for the second plot.")] = 2.0,
    buckets: Annotated[int, typer.Option("--buckets", help="Envelope buckets of the overview.")] = 2000,
) -> None:
    """Write PNGs like the paper's Fig. 6 (envelope) and Fig. 7 (first seconds at full rate).

    OUT/fig6_overview.png: min/max envelope of the window; OUT/fig7_first_2s.png: its first
    --window seconds, every sample.
    """
    if not window > 0 or buckets < 1:
        raise _fail("--window must be > 0 seconds and --buckets >= 1")
    from virtualstar.recorder.plots import plot_envelope, plot_window  # matplotlib: only here

    try:
        out.mkdir(parents=True, exist_ok=True)
        reader = _open(store)
        a, b = _window(reader, t_from, t_to)
        wanted = _names(names)
        signals = [s for s in reader.signals() if wanted is None or s.name in wanted]
        if wanted and len(signals) != len(wanted):
            have = [s.name for s in reader.signals()]
            raise RecorderError(f"unknown signal(s) in --names; the store holds {', '.join(have)}")
        env = reader.envelope(a, b, [s.name for s in signals], buckets)
        p6 = plot_envelope(env, signals, out / "fig6_overview.png",
                           title=f"{store}: min/max envelope")
        block = reader.window(a, min(b, a + round(window * 1e6)), [s.name for s in signals])
        p7 = plot_window(block, signals, out / f"fig7_first_{window:g}s.png",
                         title=f"{store}: first {window:g} s at full rate")
    except (RecorderError, OSError) as exc:
        raise _error(exc) from None
    typer.echo(f"wrote {p6} and {p7}")


@app.command()
@reports_damage("vs data")
def export(
    store: StoreArg,
    csv_path: Annotated[Path | None, typer.Option("--csv", help="Write a CSV file here.")] = None,
    mat_path: Annotated[Path | None, typer.Option("--mat", help="Write a MATLAB .mat file here.")] = None,
    t_from: FromOpt = "start",
    t_to: ToOpt = "end",
    names: NamesOpt = None,
) -> None:
    """Export a window (default: everything) to CSV and/or MATLAB .mat."""
    if csv_path is None and mat_path is None:
        raise _fail("give --csv FILE and/or --mat FILE")
    from virtualstar.recorder.export import write_csv, write_mat
    from virtualstar.recorder.parquet_store import ParquetStoreReader

    try:
        reader = _open(store)
        a, b = _window(reader, t_from, t_to)
        wanted = _names(names)
        signals = [s for s in reader.signals() if wanted is None or s.name in wanted]
        if wanted and len(signals) != len(wanted):
            raise RecorderError("unknown signal(s) in --names; `vs data info STORE` lists them")
        sel = [s.name for s in signals]
        block = None
        if csv_path is not None:
            if isinstance(reader, ParquetStoreReader) and t_from == "start" and t_to == "end":
                rows = write_csv(reader.iter_blocks(sel), sel, csv_path)
            else:
                block = reader.window(a, b, sel)
                rows = write_csv([block], sel, csv_path)
            typer.echo(f"wrote {rows} rows to {csv_path}")
        if mat_path is not None:
            block = block if block is not None else reader.window(a, b, sel)
            rows = write_mat(block, signals, mat_path)
            typer.echo(f"wrote {rows} rows to {mat_path}")
    except (RecorderError, OSError) as exc:
        raise _error(exc) from None


@app.command()
@reports_damage("vs data")
def recover(
    directory: Annotated[Path, typer.Argument(help="Parquet store directory (parquet:DIR).")],
    json_out: Annotated[bool, typer.Option("--json", help="Print JSON.")] = False,
) -> None:
    """Finish a Parquet store whose recorder died, and set its damaged files aside.

    A recorder that died left its hour in progress as a journal: its samples are kept and
    the crash is recorded as a gap (any `vs data` command and a new `vs record` into the
    store do this by themselves). Then every finished hour file is read whole: a damaged
    file (or journal) keeps every batch or row group that still reads, is moved aside as
    NAME.damaged (never deleted) and its loss is recorded in gaps.csv. A store a live
    recorder is writing is left alone (exit 1). --json: {"store", "recovered", "journals",
    "samples", "last_t_us", "unreadable", "damaged": [{"file", "moved_to", "problem"}]}.
    """
    from virtualstar.recorder.parquet_journal import live_writer_pid
    from virtualstar.recorder.parquet_store import (
        DEFAULT_ROW_GROUP_ROWS,
        DEFAULT_ZSTD_LEVEL,
        OVERVIEW_BUCKET_US,
        recover_store,
    )
    from virtualstar.recorder.repair import repair_finished_hours

    if not directory.is_dir():
        raise _fail(f"{directory} is not a directory; expected a Parquet store (parquet:DIR)")
    pid = live_writer_pid(directory)
    if pid is not None:
        raise _fail(f"a live recorder (PID {pid}) is writing {directory}; nothing to recover", 1)
    try:
        report = recover_store(directory)
        repaired = repair_finished_hours(directory, row_group_rows=DEFAULT_ROW_GROUP_ROWS,
                                         zstd_level=DEFAULT_ZSTD_LEVEL,
                                         overview_bucket_us=OVERVIEW_BUCKET_US)
    except (RecorderError, OSError) as exc:
        raise _fail(str(exc), 1) from None
    moved = (report.damaged if report else []) + repaired.moved
    doc = {"store": str(directory), "recovered": report is not None or bool(moved),
           "journals": [p.name for p in report.journals] if report else [],
           "samples": report.rows if report else 0,
           "last_t_us": report.last_t_us if report else None,
           "unreadable": [p.name for p in report.unreadable] if report else [],
           "damaged": [{"file": p.name.removesuffix(".damaged"), "moved_to": p.name,
                        "problem": problem} for p, problem in moved]}
    if json_out:
        typer.echo(json.dumps(doc))
        return
    lines = [str(report)] if report else []
    lines += [str(repaired)] if repaired.moved else []
    typer.echo("; ".join(lines) if lines else f"{directory}: nothing to recover")


@app.command()
@reports_damage("vs data")
def anomalies(
    store: StoreArg,
    t_from: FromOpt = "start",
    t_to: ToOpt = "end",
    reference: Annotated[list[str] | None, typer.Option(
        "--reference", help="A stretch to learn the mount as usual from, FROM..TO (each in "
                            "the forms of --from, e.g. +600..+1800 or ISO-8601 UTC); repeat "
                            "for several. Default: chosen automatically, the first 15 minutes "
                            "of the mount working (powered, settled, no fault logged). A "
                            "stretch with the mount powered off, one shorter than 5 minutes "
                            "of working time, or one holding one motion phase while the "
                            "window holds others is refused (exit 2).",
        show_default=False)] = None,
    ref_from: Annotated[str | None, typer.Option(
        "--reference-from", help="Start of one reference stretch (as --reference FROM..TO; "
                                 "with --reference-to, default 15 minutes after it).")] = None,
    ref_to: Annotated[str | None, typer.Option(
        "--reference-to", help="End of that reference stretch.")] = None,
    threshold: Annotated[float, typer.Option(
        "--threshold", help="Flag beyond this many robust sigmas of the reference (each "
                            "detector also has an absolute floor).")] = 8.0,
    cogging: Annotated[int | None, typer.Option(
        "--cogging-periods", help="Cogging periods per motor revolution in the current model "
                                  "(the motor's datasheet); default: found from the "
                                  "reference; 0: none.")] = None,
    settle_s: Annotated[float, typer.Option(
        "--settle-s", help="Seconds after each slew (and power-on) left out of the reference "
                           "and the scoring: the loops and the structure settle.")] = 10.0,
    json_out: Annotated[bool, typer.Option(
        "--json", help="Print the report as JSON: anomalies, what each detector checked and "
                       "what it could not, phases, reference.")] = False,
    plot_path: Annotated[Path | None, typer.Option(
        "--plot", help="Write a PNG of every detector's score over time here.")] = None,
) -> None:
    """Flag the stretches where the mount behaves unlike itself on a reference stretch.

    The night is cut into motion phases (powered off, at rest, slewing, settling, tracking;
    from the mount's and the VSS's events in the store, else from the signals) and, per
    axis, speed regimes; each detector models each of them apart: the current minus a
    model of position, velocity and acceleration (friction rising, winding faults), the
    tracking error's octave-band spectrum (a growing resonance), one-sample jumps (encoder
    glitches), the temperature's trend (runaway) and the clock rate seen in the sample
    times (drift). --json prints {"anomalies": [{"start_utc", "end_utc", "start_t_us",
    "end_t_us", "kind", "signals", "score", "axis", "detail"}], "checks": [...],
    "not_run": [{"detector", "axis", "reason"}], "phases", "reference", "window"}; score
    >= 1 is past the flagging limit. Exit 0 whether or not anything is found, 2 for a wrong
    argument, store or a refused reference; docs/anomalies.md says what each kind means.
    """
    from virtualstar.anomalies import DetectorConfig, detect_anomalies
    from virtualstar.anomalies.phases import PhaseConfig

    if not threshold > 0:
        raise _fail(f"--threshold {threshold}: expected a number of sigmas > 0")
    if cogging is not None and not cogging >= 0:
        raise _fail(f"--cogging-periods {cogging}: expected >= 0 (0: no cogging term)")
    if not 0 <= settle_s <= 600:
        raise _fail(f"--settle-s {settle_s}: expected 0..600 seconds")
    try:
        reader = _open(store)
        a, b = _window(reader, t_from, t_to)
        stretches = [_reference_stretch(text, a, b) for text in reference or []]
        if ref_from is not None or ref_to is not None:
            ra = parse_time_bound(ref_from or "start", a, b - 1, option="--reference-from")
            rb = (parse_time_bound(ref_to, a, b - 1, option="--reference-to") if ref_to
                  else ra + 900_000_000)
            if rb <= ra:
                raise RecorderError(f"empty reference: --reference-to ({rb} µs) is not after "
                                    f"--reference-from ({ra} µs)")
            stretches.append((ra, rb))
        report = detect_anomalies(reader, a, b, reference=stretches or None,
                                  config=DetectorConfig(threshold=threshold,
                                                        cogging_periods=cogging,
                                                        phases=PhaseConfig(settle_s=settle_s)))
        if plot_path is not None:
            from virtualstar.anomalies.plot import plot_report

            plot_report(report, plot_path, title=f"{store}: {len(report.anomalies)} anomalies")
    except (RecorderError, OSError) as exc:
        raise _error(exc) from None
    if json_out:
        typer.echo(json.dumps(report.as_dict()))
        return
    ref = report.reference
    typer.echo(f"{len(report.anomalies)} anomalies from {utc_text(a)} to {utc_text(b)} "
               f"({report.segments} segments at {report.rate_hz:g} Hz; {ref.how} reference "
               + ", ".join(f"{utc_text(x)} to {utc_text(y)}" for x, y in ref.stretches)
               + f", {ref.usable_s:.0f} s of the mount working)")
    typer.echo("phases (" + report.phase_source + "): "
               + ", ".join(f"{k} {v:.0f} s" for k, v in report.phase_s.items() if v > 0))
    for x in report.anomalies:
        typer.echo(f"  {utc_text(x.start_us)} .. {utc_text(x.end_us)}  {x.kind:<11} "
                   f"{x.axis or '-':<3} score {x.score:6.2f}  {x.detail}")
    typer.echo("checked:")
    for c in report.checks:
        typer.echo(f"  {c.line()}")


def _reference_stretch(text: str, a: int, b: int) -> tuple[int, int]:
    """One --reference FROM..TO as mount µs (RecorderError naming the option if wrong)."""
    lo, sep, hi = text.partition("..")
    if not sep or not lo.strip() or not hi.strip():
        raise RecorderError(f"--reference {text!r}: expected FROM..TO, each as --from takes "
                            "it (start, end, +S, -S, ISO-8601 UTC or mount µs), e.g. "
                            "+600..+1800")
    ra = parse_time_bound(lo, a, b - 1, option="--reference")
    rb = parse_time_bound(hi, a, b - 1, option="--reference")
    if rb <= ra:
        raise RecorderError(f"empty reference: --reference {text!r} ends ({rb} µs) before it "
                            f"begins ({ra} µs)")
    return ra, rb

"""`vs record`: stream controller signals over ASTCom into a store, with exact mount times."""

from __future__ import annotations

import asyncio
import contextlib
import json
import logging
import signal
from pathlib import Path
from typing import Annotated

import typer

# The recorder (pyarrow) and ASTCom (numpy, websockets) are imported when the command
# runs: --help stays fast (tests/test_import_rules.py).


def _fail(message: str, code: int = 2) -> typer.Exit:
    typer.echo(f"vs record: error: {message}", err=True)
    return typer.Exit(code)


def record(
    url: Annotated[str, typer.Argument(help="ASTCom endpoint, e.g. ws://127.0.0.1:8765 or tcp://mount:8766.")],
    names: Annotated[list[str], typer.Argument(help="Signals to record (see `astcom list URL`).")],
    rate: Annotated[float, typer.Option("--rate", help="Samples per second per signal (≤ the device loop rate).")] = 1000.0,
    duration: Annotated[float | None, typer.Option(
        "--duration", help="Stop after this many (wall-clock) seconds; default: until Ctrl-C.")] = None,
    store: Annotated[list[str] | None, typer.Option(
        "--store", help="parquet:DIR (default ./recording) or influx:http://127.0.0.1:8086/DB; "
                        "repeat to write several stores at once.")] = None,
    password: Annotated[str | None, typer.Option(
        "--password", envvar="ASTCOM_PASSWORD", help="Endpoint password (observer is enough).")] = None,
    spool: Annotated[Path | None, typer.Option(
        "--spool", help="Where InfluxDB batches wait while the database is down "
                        "(default: <tmp>/vs-record-spool/DB).")] = None,
    json_out: Annotated[bool, typer.Option("--json", help="Print the summary as JSON.")] = False,
    vss: Annotated[str | None, typer.Option(
        "--vss-log", help="Also keep this VSS's event log (ws://HOST:PORT) in the store: "
        "operations, phases, commands with client and role.")] = None,
    detect: Annotated[bool, typer.Option(
        "--detect-anomalies", help="Run the `vs data anomalies` detectors live (after a "
        "15-minute reference, a minute behind the stream so that the events giving the "
        "motion phases are in): each anomaly goes to stderr and into the store's event "
        "log.")] = False,
) -> None:
    """Record NAME... from URL at --rate into --store until --duration or Ctrl-C.

    Every sample keeps its mount timestamp (t_us, integer µs). Lost samples (sequence or
    tick gaps) and endpoint restarts are reported on stderr and kept in the store's gap
    table; the recorder reconnects by itself.
    """
    from astcom_client import AstcomError
    from virtualstar.recorder import RecorderError, parse_store_spec
    from virtualstar.recorder.stores import TeeWriter, open_writer
    from virtualstar.recorder.subscriber import Recorder, client_connector

    if not rate > 0:
        raise _fail(f"--rate {rate}: expected a positive number of samples per second")
    if duration is not None and not duration > 0:
        raise _fail(f"--duration {duration}: expected a positive number of seconds")
    try:
        specs = [parse_store_spec(s) for s in (store or ["parquet:recording"])]
        writers = [open_writer(s, spool_dir=spool) for s in specs]
    except RecorderError as exc:
        raise _fail(str(exc)) from None
    writer = writers[0] if len(writers) == 1 else TeeWriter(writers)

    def on_gap(gap) -> None:
        lost = "unknown number of" if gap.lost_samples < 0 else str(gap.lost_samples)
        typer.echo(f"vs record: {gap.reason}: {lost} samples missing between t_us "
                   f"{gap.after_t_us} and {gap.before_t_us}", err=True)

    logging.basicConfig(level=logging.WARNING, format="vs record: %(message)s")
    watch = watch_events = watch_end = None
    live = None
    if detect:
        from virtualstar.anomalies.live import LiveAnomalies

        def on_anomaly(anomaly) -> None:
            recorder.anomaly_found(anomaly)
            typer.echo(f"vs record: anomaly: {anomaly.kind} {anomaly.axis} from "
                       f"{anomaly.as_dict()['start_utc']}: {anomaly.detail}", err=True)

        def on_refused(message: str) -> None:
            typer.echo(f"vs record: anomaly detection cannot start: {message}", err=True)

        live = LiveAnomalies(list(names), rate, on_anomaly, on_refused=on_refused)
        if not live.active:
            raise _fail("--detect-anomalies needs axis.<az|el>.position/current/error_arcsec/"
                        "temperature among the names")
        watch, watch_events, watch_end = live.feed, live.feed_events, live.finish
    sources = []
    if vss is not None:
        if not vss.startswith(("ws://", "wss://")):
            raise _fail(f"--vss-log {vss!r}: expected a VSS URL, ws://HOST:PORT")
        from virtualstar.cli.status import api_password
        from virtualstar.eventlog import VssEventSource

        sources.append(VssEventSource(url=vss, password=api_password()))
    recorder = Recorder(client_connector(url, password=password), list(names), rate, writer,
                        source=url, on_gap=on_gap, watch=watch, event_sources=sources,
                        watch_events=watch_events, watch_end=watch_end)
    try:
        summary = asyncio.run(_run(recorder, duration))
    except (RecorderError, AstcomError, OSError) as exc:
        # 1: the endpoint refused (a wire error); 2: a bad argument (a rate or name the
        # device cannot serve: 422), our mistake, or no connection at all
        code = 1 if (isinstance(exc, AstcomError) and not isinstance(exc, ConnectionError)
                     and getattr(exc, "code", None) not in (404, 422)) else 2
        raise _fail(f"{url}: {exc}", code) from None
    summary.store = ", ".join(str(s) for s in specs)
    if json_out:
        typer.echo(json.dumps(summary.as_dict()))
        return
    typer.echo(f"recorded {summary.samples} samples of {len(names)} signals at "
               f"{summary.rate_hz:g} Hz into {summary.store}; lost {summary.lost} in "
               f"{len(summary.gaps)} gap(s), {summary.reconnects} reconnect(s)")


async def _run(recorder, duration: float | None):
    loop = asyncio.get_running_loop()
    for sig in (signal.SIGINT, signal.SIGTERM):
        with contextlib.suppress(NotImplementedError, RuntimeError):
            loop.add_signal_handler(sig, recorder.stop)
    return await recorder.run(duration)

"""`vs log`: the event log of a recording store, or of a running VirtualStar Server."""

from __future__ import annotations

import asyncio
import json
from typing import Annotated

import typer

from virtualstar.cli.store_warnings import reports_damage

#: astcom_client.events.LEVELS, named here so that --help does not import ASTCom (numpy);
#: tests/events checks that they agree.
LEVEL_NAMES = ("debug", "info", "warning", "error")

__all__ = ["log"]


def _fail(message: str, code: int = 2) -> typer.Exit:
    typer.echo(f"vs log: error: {message}", err=True)
    return typer.Exit(code)


def _split(values: list[str] | None) -> tuple[str, ...]:
    return tuple(v.strip() for item in values or [] for v in item.split(",") if v.strip())


def _store_events(source: str) -> list:
    """Return a store's events; a Parquet store's are read even when it has no sample file."""
    from virtualstar.eventlog import store_events
    from virtualstar.recorder import EmptyStore
    from virtualstar.recorder.event_store import read_events
    from virtualstar.recorder.stores import open_reader
    from virtualstar.recorder.storespec import parse_store_spec

    spec = parse_store_spec(source)
    if spec.kind != "parquet":
        return store_events(open_reader(spec))
    assert spec.path is not None
    if not spec.path.is_dir():
        raise EmptyStore(f"store directory {spec.path} does not exist")
    return read_events(spec.path)


@reports_damage("vs log")
def log(
    source: Annotated[str, typer.Argument(
        help="A store (parquet:DIR or DIR) or a VSS URL (ws://HOST:PORT) to read or follow.")],
    t_from: Annotated[str, typer.Option(
        "--from", help="Start: start, +S, -S, ISO-8601 UTC or mount µs (store: relative to "
                       "its first/last event).")] = "start",
    t_to: Annotated[str, typer.Option("--to", help="End (excluded), same forms.")] = "end",
    level: Annotated[str, typer.Option(
        "--level", help=f"Lowest level shown: {', '.join(LEVEL_NAMES)}.")] = "debug",
    sources: Annotated[list[str] | None, typer.Option(
        "--source", help="Only these sources (emulator, vss, recorder); comma-separated or "
                         "repeated.")] = None,
    kinds: Annotated[list[str] | None, typer.Option(
        "--kind", help="Only these kinds (fault, state, param, command, phase, connection, auth, "
                       "clock_sync, gap, session, anomaly ...).")] = None,
    text: Annotated[str, typer.Option(
        "--grep", help="Only events whose message or fields contain this text "
                       "(case-insensitive).")] = "",
    json_out: Annotated[bool, typer.Option(
        "--json", help="Print JSON: a list, or with --follow one object per line.")] = False,
    follow: Annotated[bool, typer.Option(
        "--follow", "-f", help="Keep printing new events of a VSS until Ctrl-C.")] = False,
    duration: Annotated[float | None, typer.Option(
        "--duration", help="With --follow: stop after this many seconds.")] = None,
) -> None:
    """Print the event log of a store or a VSS (filters: time, level, source, kind, text;
    --follow a VSS live).

    Each event: time, level, source, kind, message, fields. From a store: the events the recorder kept beside the samples (its own, and the
    mount emulator's). From a VSS URL: the server's log (operations and phases, faults,
    safety actions, commands with client and role, connections); --follow keeps polling.
    Table by default; --json gives {"seq", "t_us", "utc", "source", "level", "kind",
    "message", "fields"} per event. When the server's log had to drop events (connection
    churn), how many of each kind is said on stderr.
    """
    from astcom_client.events import LEVELS
    from virtualstar.eventlog import EventFilter, follow_vss, format_event
    from virtualstar.recorder import RecorderError
    from virtualstar.recorder.timeparse import parse_time_bound

    if level not in LEVELS:
        raise _fail(f"--level {level!r}: expected one of {', '.join(LEVELS)}")
    remote = source.startswith(("ws://", "wss://"))
    if follow and not remote:
        raise _fail("--follow needs a VSS URL (ws://HOST:PORT); a store is read once")
    if duration is not None and not duration > 0:
        raise _fail(f"--duration {duration}: expected seconds > 0")
    try:
        if remote:
            lo = parse_time_bound(t_from, 0, 2**62, option="--from") if t_from != "start" else None
            hi = parse_time_bound(t_to, 0, 2**62, option="--to") if t_to != "end" else None
        else:
            events = _store_events(source)
            first = events[0].t_us if events else 0
            last = events[-1].t_us if events else 0
            lo = parse_time_bound(t_from, first, last, option="--from")
            hi = parse_time_bound(t_to, first, last, option="--to")
        flt = EventFilter(lo, hi, level, _split(sources), _split(kinds), text)
    except (RecorderError, OSError, ValueError) as exc:
        raise _fail(str(exc)) from None
    if remote:
        from virtualstar.cli.status import api_password
        from virtualstar.vss_client import ServerUnavailable, VssRequestError

        printed: list = []

        def show(e) -> None:
            if json_out and follow:
                typer.echo(json.dumps(e.as_dict()))
            elif json_out:
                printed.append(e.as_dict())
            else:
                typer.echo(format_event(e))

        def dropped(counts: dict[str, int]) -> None:
            # on stderr: the table and the JSON on stdout stay as documented
            typer.echo("the server's log dropped, to keep operations and faults: " + ", ".join(
                f"{n} {kind} event{'s' if n != 1 else ''}" for kind, n in sorted(
                    counts.items())), err=True)

        try:
            asyncio.run(follow_vss(source, flt, show, password=api_password(),
                                   follow=follow, duration_s=duration, on_dropped=dropped))
        except KeyboardInterrupt:
            pass
        except VssRequestError as exc:
            raise _fail(f"the server refused log: {exc.message} [{exc.code}]", 1) from None
        except ServerUnavailable as exc:
            raise _fail(str(exc)) from None
        if json_out and not follow:
            typer.echo(json.dumps(printed))
        return
    kept = [e for e in events if flt.matches(e)]
    if json_out:
        typer.echo(json.dumps([e.as_dict() for e in kept]))
        return
    for e in kept:
        typer.echo(format_event(e))

"""`vs watch`: live status and tracking error, refreshed until Ctrl-C (or --count updates)."""

from __future__ import annotations

import asyncio
import contextlib
import json
from typing import Annotated

import typer
from rich.console import Console
from rich.live import Live

from virtualstar.cli.status import (
    JsonOpt,
    ServerOpt,
    _f,
    api_password,
    fail,
    render_status,
    shown,
)
from virtualstar.vss_client import ServerUnavailable, VssClient, VssRequestError, default_server_url

__all__ = ["watch"]


def watch(
    interval: Annotated[float, typer.Option(
        "--interval", help="Seconds between updates.", min=0.05)] = 1.0,
    count: Annotated[int, typer.Option(
        "--count", help="Stop after this many updates (0: until Ctrl-C).", min=0)] = 0,
    server: ServerOpt = None,
    as_json: JsonOpt = False,
) -> None:
    """Show status and tracking error live; keeps waiting through server restarts.

    On a terminal the table is redrawn in place; into a pipe or a file (vs watch > log)
    each update is one line, written as it comes.
    """
    url = server or default_server_url()
    try:
        asyncio.run(_watch(url, interval, count, as_json))
    except ServerUnavailable as exc:
        raise fail(str(exc)) from None
    except KeyboardInterrupt:
        pass


async def _watch(url: str, interval: float, count: int, as_json: bool) -> None:
    console = Console()
    client = await VssClient.connect(url, reconnect=True, password=api_password())
    events: list[str] = []

    async def collect() -> None:
        async for kind, data in client.events():
            if kind in ("fault", "mount_disconnected", "mount_connected", "reconnected",
                        "resumed", "slew_done"):
                events.append(f"{kind}: {json.dumps(data, default=str)[:160]}")
                if as_json:
                    typer.echo(json.dumps({"event": kind, "data": data}, default=str))

    pump = asyncio.get_running_loop().create_task(collect())
    shown = 0
    live_table = console.is_terminal and not as_json
    try:
        with (Live(console=console, auto_refresh=False, transient=False) if live_table
              else contextlib.nullcontext()) as live:
            while count == 0 or shown < count:
                try:
                    st = await client.request("status", timeout_s=max(5.0, 3 * interval))
                except (ServerUnavailable, TimeoutError):
                    if live_table:
                        live.update(f"[yellow]waiting for the server at {url}...", refresh=True)
                    elif not as_json:
                        typer.echo(f"waiting for the server at {url}...")
                    await asyncio.sleep(interval)
                    continue
                except VssRequestError as exc:
                    st = {"error": exc.message}
                shown += 1
                if as_json:
                    typer.echo(json.dumps({"status": st}, default=str))
                elif not console.is_terminal:
                    typer.echo(status_line(st))
                    for line in events:
                        typer.echo(f"event {line}")
                    events.clear()
                else:
                    table = render_status(st)
                    for line in events[-5:]:
                        table.add_row("event", line)
                    live.update(table, refresh=True)
                if count == 0 or shown < count:
                    await asyncio.sleep(interval)
    finally:
        pump.cancel()
        await client.close()


def status_line(st: dict) -> str:
    """One line of a status, for logs: time, state, place, errors, operation, clock."""
    if "error" in st:
        return f"error {st['error']}"
    if not st.get("connected"):
        return f"mount not connected ({st.get('mount_error')})"
    enc = st["encoder"]
    err = st.get("tracking_error", {}).get("1s", {})
    op = st.get("operation") or {}
    clock = st.get("time_sync", {}).get("offset_us")
    return (f"{st['mount_time_utc']} {st['mount_state']} az {enc['az_deg']:.5f} el "
            f"{enc['el_deg']:.5f} on target RMS {_f(err.get('on_target_rms_arcsec'), '.3f', '″')}"
            f" following RMS {_f(err.get('rms_arcsec'), '.3f', '″')} on-sky "
            f"{_f(err.get('on_sky_rms_arcsec'), '.3f', '″')} clock {_f(clock, '+d', ' µs')}"
            + (f" op #{op['id']} {op['kind']} {shown(op['target'])}: {op['phase']}" if op
               else ""))

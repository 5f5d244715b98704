"""`vs watch`: live status and tracking error, refreshed until Ctrl-C (or --count updates)."""

from __future__ import annotations

import asyncio
import json
from typing import Annotated

import typer
from rich.console import Console
from rich.live import Live

from virtualstar.cli.status import JsonOpt, ServerOpt, api_password, fail, render_status
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
    """Show status and tracking error live; keeps waiting through server restarts."""
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
    try:
        with Live(console=console, auto_refresh=False, transient=False) as live:
            while count == 0 or shown < count:
                try:
                    st = await client.request("status", timeout_s=max(5.0, 3 * interval))
                except (ServerUnavailable, TimeoutError):
                    if not as_json:
                        live.update(f"[yellow]waiting for the server at {url}...", refresh=True)
                    await asyncio.sleep(interval)
                    continue
                except VssRequestError as exc:
                    st = {"error": exc.message}
                shown += 1
                if as_json:
                    typer.echo(json.dumps({"status": st}, default=str))
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

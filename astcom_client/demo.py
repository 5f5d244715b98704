"""A short tour of ASTCom against the example device: `python -m astcom_client.demo`.

Starts the example device on loopback (WebSocket and TCP), then lists, reads, writes,
invokes and streams with the Client, printing each step as a table. Takes a few seconds.
"""

from __future__ import annotations

import asyncio
import time

import numpy as np
from rich.console import Console
from rich.table import Table

from .client import Client
from .endpoint import Endpoint, EndpointConfig
from .example_device import ExampleDevice
from .exceptions import Forbidden
from .text import value_to_text

console = Console()
PASSWORDS = {"operator": "demo-operator", "observer": "demo-observer"}


async def tour(loop_rate_hz: float = 1000.0, stream_s: float = 1.0) -> dict[str, float]:
    """Run the demonstration; return the stream figures it printed."""
    device = ExampleDevice(loop_rate_hz=loop_rate_hz)
    endpoint = Endpoint(device.collection, EndpointConfig(loop_rate_hz=loop_rate_hz,
                                                          passwords=PASSWORDS, name="example"))
    ws_url = await endpoint.serve("ws://127.0.0.1:0")
    tcp_url = await endpoint.serve("tcp://127.0.0.1:0")
    loop_task = asyncio.create_task(device.run(endpoint))
    console.rule("[bold]ASTCom demonstration")
    console.print(f"example device at {loop_rate_hz:g} Hz on {ws_url} and {tcp_url}")
    try:
        async with await Client.connect(ws_url, password=PASSWORDS["operator"]) as client:
            console.print(f"connected as [bold]{client.role}[/bold] (HMAC challenge-response)")
            await _show_list(client)
            await _show_read_write(client)
            await _show_invoke(client)
            figures = await _show_stream(client, stream_s)
        async with await Client.connect(tcp_url, password=PASSWORDS["observer"]) as observer:
            try:
                await observer.write({"wave.amplitude": 0.0})
            except Forbidden as exc:
                console.print(f"observer over TCP tried to write: [yellow]{exc}[/yellow]")
        stats = endpoint.stats()
        console.print(f"endpoint stats: clients {stats['clients']}, dropped samples "
                      f"{stats['dropped_samples']}, tick {stats['tick']}")
    finally:
        loop_task.cancel()
        await endpoint.close()
    console.rule("[bold green]done")
    return figures


async def _show_list(client: Client) -> None:
    entries = await client.list()
    table = Table("name", "type", "kind", "access", "unit", "doc", title="LIST")
    for e in entries:
        table.add_row(e.name, e.type, e.kind, e.access, e.unit, e.doc)
    console.print(table)


async def _show_read_write(client: Client) -> None:
    names = ["counter", "wave.sine", "wave.amplitude", "gains", "site"]
    before, tick, _ = await client.read_at(names)
    await client.write({"wave.amplitude": 2.5, "gains": [2.0, 0.2, 0.02]})
    after, tick_after, _ = await client.read_at(names)
    table = Table("name", f"tick {tick}", f"after WRITE, tick {tick_after}", title="READ / WRITE")
    for name in names:
        table.add_row(name, value_to_text(before[name]), value_to_text(after[name]))
    console.print(table)


async def _show_invoke(client: Client) -> None:
    table = Table("call", "returns", title="INVOKE")
    table.add_row("math.add(1.5, 2.25)", value_to_text(await client.invoke("math.add", 1.5, 2.25)))
    table.add_row("math.sum([0..99])",
                  value_to_text(await client.invoke("math.sum", np.arange(100.0))))
    table.add_row("counter.reset()", value_to_text(await client.invoke("counter.reset")))
    console.print(table)


async def _show_stream(client: Client, seconds: float) -> dict[str, float]:
    stream = await client.stream(["counter", "wave.sine", "wave.cosine"], rate_hz=500)
    start = time.monotonic()
    last = None
    while time.monotonic() - start < seconds:
        last = await stream.get(timeout_s=5.0)
    await stream.stop()
    assert last is not None
    table = Table("t_us", "tick", *stream.names, title=f"STREAM at {stream.rate_hz:g} Hz (last 5 samples)")
    for t_us, tick, row in list(zip(last.t_us, last.ticks, last.values, strict=True))[-5:]:
        table.add_row(str(t_us), str(tick), *(f"{v:.9g}" for v in row))
    console.print(table)
    console.print(f"{stream.samples} samples in {stream.packets} packets, lost {stream.lost}")
    return {"samples": stream.samples, "lost": stream.lost, "rate_hz": stream.rate_hz}


def main() -> None:
    """Run the demonstration."""
    asyncio.run(tour())


if __name__ == "__main__":
    main()

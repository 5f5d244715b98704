"""A running emulator + VSS on an event loop in a background thread, for CLI tests.

The `vs` commands run `asyncio.run` themselves, so the server side lives on its
own loop in a thread; tests talk to it through the CLI (CliRunner), through
`VssClient`, and to the emulator directly through an ASTCom `Client` (the
independent view of where the encoders are).
"""

from __future__ import annotations

import asyncio
import threading
from typing import Any

from astcom_client import Client
from virtualstar.astro import Site
from virtualstar.launcher import start_emulator
from virtualstar.server import build_server

SPEED = 20.0


class TcpProxy:
    """Forward TCP connections to (host, port); `cut()` breaks every open one, as a network would."""

    def __init__(self, host: str, port: int) -> None:
        self.target = (host, port)
        self.server: asyncio.base_events.Server | None = None
        self.writers: set[asyncio.StreamWriter] = set()
        self.port = 0

    async def start(self) -> int:
        self.server = await asyncio.start_server(self._handle, "127.0.0.1", 0)
        self.port = self.server.sockets[0].getsockname()[1]
        return self.port

    async def _handle(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        try:
            up_reader, up_writer = await asyncio.open_connection(*self.target)
        except OSError:
            writer.close()
            return
        self.writers |= {writer, up_writer}

        async def pump(src: asyncio.StreamReader, dst: asyncio.StreamWriter) -> None:
            try:
                while data := await src.read(65536):
                    dst.write(data)
                    await dst.drain()
            except (ConnectionError, OSError):
                pass
            finally:
                dst.close()

        await asyncio.gather(pump(reader, up_writer), pump(up_reader, writer))
        self.writers -= {writer, up_writer}

    def cut(self) -> None:
        for w in list(self.writers):
            w.transport.abort()
        self.writers.clear()

    async def close(self) -> None:
        self.cut()
        if self.server is not None:
            self.server.close()


class Rig:
    """Emulator (simulated time) + VSS, started on a private event loop."""

    def __init__(self, *, start_us: int, site: Site | None = None, speed: float = SPEED,
                 emulator_options: dict[str, Any] | None = None,
                 **telescope_options: Any) -> None:
        self.start_us = start_us
        self.site = site
        self.speed = speed
        self.options = telescope_options
        self.emulator_options = emulator_options or {}
        self.loop = asyncio.new_event_loop()
        self.thread = threading.Thread(target=self.loop.run_forever, daemon=True)
        self.thread.start()
        self.emulator = None
        self.server = None
        self.proxy: TcpProxy | None = None
        self.url = ""

    def run(self, coro, timeout_s: float = 120.0):
        """Run a coroutine on the rig's loop and return its result."""
        return asyncio.run_coroutine_threadsafe(coro, self.loop).result(timeout_s)

    def start(self, listen: str = "ws://127.0.0.1:0") -> Rig:
        async def go() -> None:
            self.emulator = await start_emulator(speed=self.speed, start_us=self.start_us,
                                                 **self.emulator_options)
            await self.start_server(listen)

        self.run(go())
        return self

    async def start_server(self, listen: str = "ws://127.0.0.1:0") -> str:
        if self.proxy is None:  # the VSS reaches the mount through a proxy that can cut the line
            host, port = self.emulator.url.rsplit("/", 1)[-1].rsplit(":", 1)
            self.proxy = TcpProxy(host, int(port))
            await self.proxy.start()
        self.server = build_server(mount_url=f"ws://127.0.0.1:{self.proxy.port}", site=self.site,
                                   speed=self.speed, **self.options)
        self.url = await self.server.start(listen)
        for _ in range(400):
            if self.server.telescope.link.connected and self.server.telescope.errors.samples:
                break
            await asyncio.sleep(0.01)
        return self.url

    async def mount_read(self, names: list[str]) -> tuple[dict[str, Any], int]:
        """Read emulator variables directly (one tick); return (values, mount time µs)."""
        async with await Client.connect(self.emulator.url) as c:
            values, _tick, t_us = await c.read_at(names)
        return values, int(t_us)

    async def mount_write(self, values: dict[str, Any]) -> None:
        async with await Client.connect(self.emulator.url) as c:
            await c.write(values)

    def close(self) -> None:
        async def stop() -> None:
            if self.server is not None:
                await self.server.close()
            if self.proxy is not None:
                await self.proxy.close()
            if self.emulator is not None:
                await self.emulator.stop()

        try:
            self.run(stop(), 30.0)
        finally:
            self.loop.call_soon_threadsafe(self.loop.stop)
            self.thread.join(10.0)

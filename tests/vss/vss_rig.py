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
        self.server = build_server(mount_url=self.emulator.url, site=self.site, speed=self.speed,
                                   **self.options)
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
            if self.emulator is not None:
                await self.emulator.stop()

        try:
            self.run(stop(), 30.0)
        finally:
            self.loop.call_soon_threadsafe(self.loop.stop)
            self.thread.join(10.0)

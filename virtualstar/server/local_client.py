"""A client of a VSS in the same process: the API without a socket (demo, tests, benchmarks).

`LocalVssClient` has the methods of `virtualstar.vss_client.VssClient` that a
script uses (`request`, `events`, `next_event`, `close`) and answers the same
way, errors included (`VssRequestError` with the API's code), but calls the
server's command table directly. In lockstep simulated time nothing then stands
between the client and the server that the kernel schedules, so a scripted run
gives the same result every time.
"""

from __future__ import annotations

import asyncio
from collections.abc import AsyncIterator
from typing import Any

from virtualstar.vss_client import VssRequestError

from .exceptions import VssError
from .protocol import encode
from .server import VssServer

__all__ = ["LocalVssClient"]


class LocalVssClient:
    """An in-process client of `server`; every event broadcast from now on is queued."""

    def __init__(self, server: VssServer) -> None:
        self.server = server
        self._events = server.subscribe()

    async def request(self, cmd: str, params: dict[str, Any] | None = None,
                      timeout_s: float | None = None) -> Any:
        """Run one command; return its result as JSON would carry it, or raise VssRequestError."""
        try:
            async with asyncio.timeout(timeout_s):
                result = await self.server.call(cmd, params)
        except VssError as exc:
            raise VssRequestError(exc.code, str(exc)) from None
        return _as_json(result)

    async def events(self) -> AsyncIterator[tuple[str, dict[str, Any]]]:
        while True:
            yield await self._events.get()

    async def next_event(self, name: str, timeout_s: float | None = None) -> dict[str, Any]:
        """Return the data of the next event called `name` (others are skipped)."""
        async def find() -> dict[str, Any]:
            async for kind, data in self.events():
                if kind == name:
                    return data
            raise AssertionError("unreachable")

        async with asyncio.timeout(timeout_s):
            return await find()

    async def close(self) -> None:
        self.server.unsubscribe(self._events)

    async def __aenter__(self) -> LocalVssClient:
        return self

    async def __aexit__(self, *exc: object) -> None:
        await self.close()


def _as_json(value: Any) -> Any:
    import json

    return json.loads(encode(value))

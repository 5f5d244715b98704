"""Helpers of the ASTCom tests: run a coroutine, serve the example device."""

from __future__ import annotations

import asyncio
import contextlib
from collections.abc import AsyncIterator, Coroutine
from typing import Any

from astcom_client import Client, Endpoint, EndpointConfig
from astcom_client.example_device import ExampleDevice

PASSWORDS = {"operator": "op-secret", "observer": "obs-secret"}


def run(coro: Coroutine[Any, Any, Any], timeout_s: float = 20.0) -> Any:
    """Run `coro` on a fresh event loop, failing after `timeout_s`."""
    return asyncio.run(asyncio.wait_for(coro, timeout_s))


@contextlib.asynccontextmanager
async def served(url: str | None = None, *, loop_rate_hz: float = 1000.0, realtime: bool = False,
                 n_extra_signals: int = 0, **config: Any
                 ) -> AsyncIterator[tuple[ExampleDevice, Endpoint, str | None]]:
    """Serve an ExampleDevice; with `realtime` its tick loop runs, else tests advance it."""
    device = ExampleDevice(loop_rate_hz=loop_rate_hz, n_extra_signals=n_extra_signals)
    config.setdefault("passwords", PASSWORDS)
    endpoint = Endpoint(device.collection, EndpointConfig(loop_rate_hz=loop_rate_hz, **config))
    bound = await endpoint.serve(url) if url else None
    task = asyncio.create_task(device.run(endpoint)) if realtime else None
    try:
        yield device, endpoint, bound
    finally:
        if task is not None:
            task.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await task
        await endpoint.close()


async def memory_client(endpoint: Endpoint, password: str | None = PASSWORDS["operator"],
                        **kwargs: Any) -> Client:
    """Return a Client joined to `endpoint` in memory (no sockets)."""
    return await Client.open(endpoint.connect_in_memory(), password=password, **kwargs)


async def settle(rounds: int = 5) -> None:
    """Let the endpoint's writer tasks and the client's reader run."""
    for _ in range(rounds):
        await asyncio.sleep(0)


@contextlib.asynccontextmanager
async def memory_session(password: str | None = PASSWORDS["operator"], *,
                         client_options: dict[str, Any] | None = None, **serve_options: Any
                         ) -> AsyncIterator[tuple[ExampleDevice, Endpoint, Client]]:
    """Serve an ExampleDevice and join one in-memory Client to it."""
    async with served(**serve_options) as (device, endpoint, _):
        client = await memory_client(endpoint, password, **(client_options or {}))
        try:
            yield device, endpoint, client
        finally:
            await client.close()


class RawPeer:
    """A client that writes frames by hand, to send what a well-behaved Client never would."""

    def __init__(self, transport: Any) -> None:
        from astcom_client.codec import Codec

        self.transport = transport
        self.codec = Codec()
        self.seq = 0

    async def send(self, obj: Any) -> None:
        await self.transport.send(self.codec.encode(obj))

    async def send_raw(self, data: bytes) -> None:
        await self.transport.send(data)

    async def recv(self, timeout_s: float = 30.0) -> Any:
        """Return the next decoded frame, or None when the endpoint closed.

        `timeout_s` only bounds a failure (every caller expects a frame or the close): at 2 s
        a starved host timed out a refusal the device had sent."""
        data = await asyncio.wait_for(self.transport.recv(), timeout_s)
        return None if data is None else self.codec.decode(data)

    async def request(self, op: str, args: dict[str, Any] | None = None) -> list[Any]:
        """Send [op, seq, args] and return the reply frame (skipping stream packets)."""
        self.seq += 1
        await self.send([op, self.seq, args or {}])
        while True:
            frame = await self.recv()
            if frame is None or frame[0] != "DATA":
                return frame

    async def login(self, password: str = PASSWORDS["operator"]) -> list[Any]:
        """Say HELLO and AUTH; return the AUTH reply."""
        hello = await self.request("HELLO", {"version": "1.0", "client": "raw"})
        return await self.auth(hello[2]["nonce"], password)

    async def auth(self, nonce: bytes, password: str = PASSWORDS["operator"]) -> list[Any]:
        """Send AUTH answering the HELLO reply's `nonce`; return the reply."""
        import os

        from astcom_client.auth import client_mac

        cnonce = os.urandom(16)
        mac = client_mac(password, nonce, cnonce)
        return await self.request("AUTH", {"cnonce": cnonce, "mac": mac})


@contextlib.contextmanager
def device_in_thread(url: str = "ws://127.0.0.1:0", **options: Any) -> Any:
    """Serve a real-time ExampleDevice from a background thread; yield {"url", "device", ...}."""
    import threading

    state: dict[str, Any] = {}
    ready = threading.Event()
    loop = asyncio.new_event_loop()

    async def main() -> None:
        async with served(url, realtime=True, **options) as (device, endpoint, bound):
            state.update(device=device, endpoint=endpoint, url=bound, stop=asyncio.Event(),
                         loop=asyncio.get_running_loop())
            ready.set()
            await state["stop"].wait()

    thread = threading.Thread(target=loop.run_until_complete, args=(main(),), daemon=True)
    thread.start()
    if not ready.wait(10.0):
        raise RuntimeError("the example device did not start")
    try:
        yield state
    finally:
        loop.call_soon_threadsafe(state["stop"].set)
        thread.join(10.0)
        loop.close()

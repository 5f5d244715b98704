"""An asyncio client of the VirtualStar Server API (used by the `vs` CLI).

::

    async with await VssClient.connect("ws://127.0.0.1:8740") as vs:
        status = await vs.request("status")
        await vs.request("slew", {"star": "Vega"})
        async for event in vs.events():        # ("heartbeat", {...}), ("fault", {...}), ...
            ...

A server with passwords says so in its hello; the client then authenticates with
`password` by ASTCom's challenge–response (the password never crosses the wire)
and checks the server's proof. The client watches the server's heartbeat: if
nothing arrives for `silence_s`, the connection is declared dead even when the
socket looks open.
With ``reconnect=True`` it then reconnects with backoff and the event iterator
carries on (a ``reconnected`` event marks the gap); pending requests fail with
`ServerUnavailable`.
"""

from __future__ import annotations

import asyncio
import contextlib
import hmac
import itertools
import json
import os
from collections.abc import AsyncIterator
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:  # websockets is imported when a connection is made (the CLI starts faster)
    from websockets.asyncio.client import ClientConnection

__all__ = ["DEFAULT_SERVER_URL", "PASSWORD_ENV_VAR", "SERVER_ENV_VAR", "ServerUnavailable",
           "VssClient", "VssRequestError", "call_server", "default_server_url"]

SERVER_ENV_VAR = "VS_SERVER"
PASSWORD_ENV_VAR = "VS_PASSWORD"
DEFAULT_SERVER_URL = "ws://127.0.0.1:8740"


def default_server_url() -> str:
    """Return $VS_SERVER or the local default server URL."""
    return os.environ.get(SERVER_ENV_VAR) or DEFAULT_SERVER_URL


class VssRequestError(RuntimeError):
    """The server refused a request: `.code` (e.g. bad_request) and its message."""

    def __init__(self, code: str, message: str) -> None:
        super().__init__(f"{message} [{code}]")
        self.code = code
        self.message = message


class ServerUnavailable(ConnectionError):
    """No connection to the server (refused, lost, or silent beyond the heartbeat)."""


class VssClient:
    """One connection to a VSS (optionally self-reconnecting)."""

    def __init__(self, url: str, *, silence_s: float = 5.0, reconnect: bool = False,
                 password: str | None = None) -> None:
        self.url = url
        self.silence_s = silence_s
        self.reconnect = reconnect
        self._password = password
        self.role: str | None = None
        self._ws: ClientConnection | None = None
        self._ids = itertools.count(1)
        self._pending: dict[int, asyncio.Future] = {}
        self._events: asyncio.Queue[tuple[str, dict[str, Any]]] = asyncio.Queue(1024)
        self._reader: asyncio.Task | None = None
        self._closed = False
        self.hello: dict[str, Any] = {}
        self.reconnects = 0

    @classmethod
    async def connect(cls, url: str, *, timeout_s: float = 5.0, silence_s: float = 5.0,
                      reconnect: bool = False, password: str | None = None) -> VssClient:
        """Connect to `url` (authenticating with `password` if the server asks for one).

        Raises ServerUnavailable (with what to check) if it cannot connect, and
        VssRequestError("unauthorized") for a missing or wrong password.
        """
        client = cls(url, silence_s=silence_s, reconnect=reconnect, password=password)
        await client._open(timeout_s)
        client._reader = asyncio.get_running_loop().create_task(client._run())
        return client

    async def _open(self, timeout_s: float) -> None:
        from websockets.asyncio.client import connect
        from websockets.exceptions import InvalidURI, WebSocketException

        try:
            async with asyncio.timeout(timeout_s):
                ws = await connect(self.url, max_size=1 << 24, ping_interval=None,
                                   open_timeout=timeout_s)
            async with asyncio.timeout(timeout_s):
                first = json.loads(await ws.recv())
        except (OSError, TimeoutError, WebSocketException, InvalidURI, ValueError) as exc:
            raise ServerUnavailable(
                f"cannot reach the VirtualStar Server at {self.url}: {exc or type(exc).__name__}; "
                "is `vs server` running? (--server URL or $VS_SERVER pick another one)") from None
        if first.get("event") != "hello":
            await ws.close()
            raise ServerUnavailable(f"{self.url} is not a VirtualStar Server (no hello)")
        self.hello = first.get("data", {})
        auth = self.hello.get("auth") or {}
        if auth.get("required"):
            try:
                self.role = await self._authenticate(ws, auth, timeout_s)
            except BaseException:
                await ws.close()
                raise
        else:
            self.role = auth.get("role") or "operator"
        self._ws = ws

    async def _authenticate(self, ws: ClientConnection, auth: dict[str, Any],
                            timeout_s: float) -> str:
        from astcom_client.auth import client_mac, new_nonce, server_proof  # when asked

        if not self._password:
            raise VssRequestError("unauthorized", f"the VirtualStar Server at {self.url} needs a "
                                  f"password: give vs --password PW or set ${PASSWORD_ENV_VAR}")
        server_nonce = bytes.fromhex(auth["nonce"])
        client_nonce = new_nonce()
        mac = client_mac(self._password, server_nonce, client_nonce)
        await ws.send(json.dumps({"id": "auth", "cmd": "auth", "params": {
            "client_nonce": client_nonce.hex(), "mac": mac.hex()}}))
        while True:
            async with asyncio.timeout(timeout_s):
                doc = json.loads(await ws.recv())
            if doc.get("id") == "auth":
                break
        if not doc.get("ok"):
            err = doc.get("error") or {}
            raise VssRequestError(str(err.get("code", "unauthorized")),
                                  f"{self.url}: {err.get('message', 'authentication failed')}")
        result = doc["result"]
        proof = server_proof(self._password, server_nonce, client_nonce)
        if not hmac.compare_digest(bytes.fromhex(result.get("server_proof") or ""), proof):
            raise ServerUnavailable(f"{self.url} accepted the password but could not prove it "
                                    "knows it: not the server you meant")
        return str(result["role"])

    async def _run(self) -> None:
        delay = 0.2
        while True:
            await self._read_until_lost()
            self._fail_pending(ServerUnavailable(f"lost the connection to {self.url}"))
            if not self.reconnect or self._closed:
                self._put(("disconnected", {"url": self.url}))
                return
            while not self._closed:
                await asyncio.sleep(delay)
                try:
                    await self._open(min(5.0, self.silence_s))
                except ServerUnavailable:
                    delay = min(2 * delay, 2.0)
                    continue
                except VssRequestError as exc:  # the password stopped working: give up
                    self._put(("disconnected", {"url": self.url, "reason": exc.message}))
                    return
                delay = 0.2
                self.reconnects += 1
                self._put(("reconnected", {"url": self.url, "reconnects": self.reconnects}))
                break

    async def _read_until_lost(self) -> None:
        from websockets.exceptions import ConnectionClosed

        ws = self._ws
        if ws is None:
            return
        try:
            while True:
                async with asyncio.timeout(self.silence_s):
                    text = await ws.recv()
                doc = json.loads(text)
                if "event" in doc:
                    self._put((doc["event"], doc.get("data", {})))
                else:
                    fut = self._pending.pop(doc.get("id"), None)
                    if fut is not None and not fut.done():
                        fut.set_result(doc)
        except (ConnectionClosed, TimeoutError, OSError, ValueError):
            pass
        finally:
            self._ws = None
            with contextlib.suppress(Exception):
                async with asyncio.timeout(1.0):
                    await ws.close()

    def _put(self, item: tuple[str, dict[str, Any]]) -> None:
        if self._events.full():
            self._events.get_nowait()
        self._events.put_nowait(item)

    def _fail_pending(self, error: Exception) -> None:
        for fut in self._pending.values():
            if not fut.done():
                fut.set_exception(error)
        self._pending.clear()

    @property
    def connected(self) -> bool:
        return self._ws is not None

    async def request(self, cmd: str, params: dict[str, Any] | None = None,
                      timeout_s: float | None = None) -> Any:
        """Send one command and return its result; raise VssRequestError or ServerUnavailable."""
        ws = self._ws
        if ws is None:
            raise ServerUnavailable(f"not connected to {self.url}")
        from websockets.exceptions import ConnectionClosed

        rid = next(self._ids)
        fut = asyncio.get_running_loop().create_future()
        self._pending[rid] = fut
        try:
            await ws.send(json.dumps({"id": rid, "cmd": cmd, "params": params or {}}))
        except ConnectionClosed:
            self._pending.pop(rid, None)
            raise ServerUnavailable(f"lost the connection to {self.url}") from None
        async with asyncio.timeout(timeout_s):
            doc = await fut
        if doc.get("ok"):
            return doc.get("result")
        err = doc.get("error") or {}
        raise VssRequestError(str(err.get("code", "error")), str(err.get("message", "")))

    async def send_raw(self, text: str, timeout_s: float = 5.0) -> dict[str, Any]:
        """Send a raw text frame and return the next reply (tests of bad input)."""
        ws = self._ws
        if ws is None:
            raise ServerUnavailable(f"not connected to {self.url}")
        fut = asyncio.get_running_loop().create_future()
        self._pending[None] = fut  # replies to unparseable frames carry id null
        with contextlib.suppress(ValueError):
            doc = json.loads(text)
            if isinstance(doc, dict) and isinstance(doc.get("id"), int | str):
                self._pending[doc["id"]] = self._pending.pop(None)
        await ws.send(text)
        async with asyncio.timeout(timeout_s):
            return await fut

    async def events(self) -> AsyncIterator[tuple[str, dict[str, Any]]]:
        """Yield (event name, data) as they arrive; ends after a final disconnect."""
        while True:
            item = await self._events.get()
            yield item
            if item[0] == "disconnected":
                return

    async def next_event(self, name: str, timeout_s: float) -> dict[str, Any]:
        """Return the data of the next event called `name` (others are skipped)."""
        async def find() -> dict[str, Any]:
            async for kind, data in self.events():
                if kind == name:
                    return data
            raise ServerUnavailable(f"disconnected from {self.url} before a {name} event")

        async with asyncio.timeout(timeout_s):
            return await find()

    async def close(self) -> None:
        """Close the connection (no reconnect)."""
        self._closed = True
        ws = self._ws
        if ws is not None:
            with contextlib.suppress(Exception):
                await ws.close()
        if self._reader is not None:
            self._reader.cancel()
            await asyncio.wait({self._reader})
            if not self._reader.cancelled():
                self._reader.exception()  # retrieved: the connection is closed either way
        self._fail_pending(ServerUnavailable("the client closed the connection"))

    async def __aenter__(self) -> VssClient:
        return self

    async def __aexit__(self, *exc: object) -> None:
        await self.close()


def call_server(url: str, cmd: str, params: dict[str, Any] | None = None, *,
                on_event=None, timeout_s: float | None = None,
                password: str | None = None) -> Any:
    """Connect, send one command, return its result (blocking; for command lines).

    on_event(name, data) sees every server event while the answer is awaited.
    Raises VssRequestError or ServerUnavailable.
    """

    async def run() -> Any:
        async with await VssClient.connect(url, password=password) as client:
            watcher = None
            if on_event is not None:
                async def pump() -> None:
                    async for kind, data in client.events():
                        on_event(kind, data)

                watcher = asyncio.get_running_loop().create_task(pump())
            try:
                return await client.request(cmd, params, timeout_s)
            finally:
                if watcher is not None:
                    watcher.cancel()

    return asyncio.run(run())

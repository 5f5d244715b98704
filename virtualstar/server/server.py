"""The VirtualStar Server: the `Telescope` behind a WebSocket/JSON API.

Each client connection gets a ``hello`` event, then every event the telescope
emits and a ``heartbeat`` event every `heartbeat_s` seconds. Requests are
handled concurrently (one task each), so a client waiting for a long track
can still ask for status on the same socket. A client that disconnects only
loses its pending answers: operations belong to the telescope, never to a
connection. A slow client's event queue drops its oldest events rather than
holding up the server.
"""

from __future__ import annotations

import asyncio
import contextlib
import itertools
import json
import logging
import time
from dataclasses import dataclass
from http import HTTPStatus
from typing import Any

from websockets.asyncio.server import Server, ServerConnection, serve
from websockets.exceptions import ConnectionClosed
from websockets.http11 import Request, Response

from .access import AccessConfig, Session, check_listen, refuse_origin
from .commands import COMMANDS, dispatch
from .event_log import QUIET_COMMANDS, describe
from .exceptions import BadRequest, VssError
from .protocol import API_VERSION, ErrorReply, Event, Reply, decode_request
from .telescope import Telescope

__all__ = ["DEFAULT_PORT", "VssServer", "parse_listen_url"]

log = logging.getLogger("virtualstar.server")

DEFAULT_PORT = 8740
EVENT_QUEUE = 256


def parse_listen_url(url: str) -> tuple[str, int]:
    """Return (host, port) of a ``ws://HOST:PORT`` URL; raise BadRequest otherwise."""
    from urllib.parse import urlsplit

    parts = urlsplit(url)
    try:
        port = parts.port
    except ValueError:
        port = -1
    if parts.scheme != "ws" or not parts.hostname or port is None or port < 0:
        raise BadRequest(f"listen address {url!r}: expected ws://HOST:PORT, e.g. "
                         f"ws://127.0.0.1:{DEFAULT_PORT} (port 0 picks a free one)")
    return parts.hostname, port


@dataclass(eq=False)  # identity hash: kept in a set
class _Client:
    ws: ServerConnection
    queue: asyncio.Queue[str]
    session: Session
    dropped: int = 0

    def put(self, text: str) -> None:
        if not self.session.may_watch:  # events are for authenticated clients only
            return
        if self.queue.full():
            with contextlib.suppress(asyncio.QueueEmpty):
                self.queue.get_nowait()
            self.dropped += 1
        self.queue.put_nowait(text)


class VssServer:
    """Serve a Telescope to WebSocket clients; `await start(url)` returns the bound URL."""

    def __init__(self, telescope: Telescope, *, heartbeat_s: float = 1.0,
                 access: AccessConfig | None = None) -> None:
        self.telescope = telescope
        self.heartbeat_s = heartbeat_s
        self.access = access or AccessConfig()
        self._clients: set[_Client] = set()
        self._subscribers: list[asyncio.Queue[tuple[str, dict[str, Any]]]] = []
        self._seq = itertools.count(1)
        self._server: Server | None = None
        self._heartbeat: asyncio.Task | None = None
        self.url = ""
        self.requests = 0
        telescope.emit = self.broadcast

    def broadcast(self, kind: str, data: dict[str, Any]) -> None:
        """Push an event to every connected client (and every in-process subscriber);
        keep it in the event log (`log` command, docs/events.md)."""
        logged = describe(kind, data)
        if logged is not None:
            level, log_kind, message = logged
            fields = {(f"{kind}_{k}" if k in _RESERVED else k): v
                      for k, v in data.items() if _flat(v)}
            self.telescope.log_event(level, log_kind, message, event=kind, **fields)
        seq = next(self._seq)
        text = Event(kind, data, seq).to_json()
        for client in list(self._clients):
            client.put(text)
        if self._subscribers:
            frozen = json.loads(text)["data"]  # as a socket client would see it, then and there
            for queue in self._subscribers:
                if queue.full():
                    queue.get_nowait()
                queue.put_nowait((kind, frozen))

    def subscribe(self, maxsize: int = 1024) -> asyncio.Queue[tuple[str, dict[str, Any]]]:
        """Return a queue that receives every event from now on (in-process clients)."""
        queue: asyncio.Queue[tuple[str, dict[str, Any]]] = asyncio.Queue(maxsize)
        self._subscribers.append(queue)
        return queue

    def unsubscribe(self, queue: asyncio.Queue) -> None:
        if queue in self._subscribers:
            self._subscribers.remove(queue)

    async def call(self, cmd: str, params: dict[str, Any] | None = None) -> Any:
        """Run one command as a client would, in this process; raise VssError subclasses.

        In-process callers are trusted as operators (they could drive the mount anyway).
        """
        self.requests += 1
        if cmd not in QUIET_COMMANDS:
            self.telescope.log_event("info", "command", f"{cmd} (in-process)", command=cmd,
                                     client="in-process", role="operator",
                                     params=json.dumps(params or {})[:500])
        return await dispatch(self.telescope, cmd, params or {})

    async def start(self, url: str | None = f"ws://127.0.0.1:{DEFAULT_PORT}") -> str:
        """Start the telescope and listen; return the bound ``ws://`` URL ('' if `url` is None)."""
        host, port = parse_listen_url(url) if url is not None else ("", 0)
        if url is not None:
            check_listen(host, self.access)
        await self.telescope.start()
        if url is None:
            return ""
        self._server = await serve(self._session, host, port, max_size=1 << 20,
                                   ping_interval=None, process_request=self._check_origin)
        bound = self._server.sockets[0].getsockname()
        self.url = f"ws://{host}:{bound[1]}"
        self._heartbeat = asyncio.get_running_loop().create_task(self._beat())
        log.info("VirtualStar Server listening on %s", self.url)
        return self.url

    async def close(self) -> None:
        """Stop listening, close client connections, stop the telescope."""
        if self._heartbeat is not None:
            self._heartbeat.cancel()
            await asyncio.wait({self._heartbeat})
        if self._server is not None:
            self._server.close()
            with contextlib.suppress(TimeoutError):
                await asyncio.wait_for(self._server.wait_closed(), 5.0)
        await self.telescope.close()

    async def __aenter__(self) -> VssServer:
        return self

    async def __aexit__(self, *exc: object) -> None:
        await self.close()

    async def _beat(self) -> None:
        while True:
            await asyncio.sleep(self.heartbeat_s)
            self.broadcast("heartbeat", {"t_unix": time.time(),
                                         "mount_connected": self.telescope.link.connected})

    def _check_origin(self, connection: ServerConnection, request: Request) -> Response | None:
        reason = refuse_origin(request.headers.get_all("Origin"), self.access)
        if reason is None:
            return None
        log.warning("WebSocket handshake from %s: %s", connection.remote_address, reason)
        return connection.respond(HTTPStatus.FORBIDDEN, reason + "\n")

    async def _session(self, ws: ServerConnection) -> None:
        client = _Client(ws, asyncio.Queue(EVENT_QUEUE), Session(self.access))
        self._clients.add(client)
        peer = _peer(ws)
        self.telescope.log_event("info", "connection", f"client {peer} connected", client=peer)
        writer = asyncio.get_running_loop().create_task(self._writer(client))
        tasks: set[asyncio.Task] = set()
        hello = {"server": "virtualstar", "api_version": API_VERSION,
                 "commands": sorted([*COMMANDS, "auth"]), "heartbeat_s": self.heartbeat_s,
                 "auth": client.session.hello()}
        if client.session.may_watch:  # no password needed: say where the mount answers ASTCom
            hello["mount_endpoint"] = self.telescope.config.mount_endpoint or None
        client.queue.put_nowait(Event("hello", hello, next(self._seq)).to_json())
        try:
            async for message in ws:
                task = asyncio.get_running_loop().create_task(self._handle(client, message))
                tasks.add(task)
                task.add_done_callback(tasks.discard)
        except ConnectionClosed:
            pass
        finally:
            self._clients.discard(client)
            self.telescope.log_event("info", "connection", f"client {peer} disconnected",
                                     client=peer)
            pending = {*tasks, writer}
            for task in pending:
                task.cancel()
            await asyncio.wait(pending)

    def _log_command(self, client: _Client, cmd: str, params: dict[str, Any]) -> None:
        """Check the client may send `cmd` (raise as `permit` does) and log it with the
        client and its role; a command its role may not send is a warning."""
        peer = _peer(client.ws)
        role = client.session.role.label if client.session.role else "none"
        try:
            client.session.permit(cmd)
        except VssError as exc:
            self.telescope.log_event("warning", "command", f"{cmd} from {peer} ({role}) "
                                     f"refused: {exc}", command=cmd, client=peer, role=role)
            raise
        if cmd not in QUIET_COMMANDS:
            self.telescope.log_event("info", "command", f"{cmd} from {peer} ({role})",
                                     command=cmd, client=peer, role=role,
                                     params=json.dumps(params)[:500])

    def _log_refusal(self, client: _Client, cmd: str, exc: VssError) -> None:
        """A command the server refused or that failed (a bad target, the Sun zone, not
        arrived...): a warning with the code, beside the command's own info line. An
        operation that a `stop` or a newer command ended was neither: an info line saying
        how it ended (`outcome`: stopped or aborted)."""
        if cmd in QUIET_COMMANDS:
            return
        peer = _peer(client.ws)
        role = client.session.role.label if client.session.role else "none"
        if exc.code == "aborted":
            outcome = "stopped" if getattr(exc, "stopped", False) else "aborted"
            self.telescope.log_event("info", "command", f"{cmd} from {peer} ({role}) ended: "
                                     f"{exc} [{outcome}]", command=cmd, client=peer,
                                     role=role, code=exc.code, outcome=outcome)
            return
        self.telescope.log_event("warning", "command", f"{cmd} from {peer} ({role}) refused: "
                                 f"{exc} [{exc.code}]", command=cmd, client=peer, role=role,
                                 code=exc.code)

    async def _writer(self, client: _Client) -> None:
        with contextlib.suppress(ConnectionClosed):
            while True:
                await client.ws.send(await client.queue.get())

    async def _handle(self, client: _Client, message: str | bytes) -> None:
        self.requests += 1
        rid = None
        try:
            request = decode_request(message)
            rid = request.id
            if request.cmd == "auth":
                result = client.session.authenticate(request.params)
            else:
                self._log_command(client, request.cmd, request.params)
                try:
                    result = await dispatch(self.telescope, request.cmd, request.params)
                except VssError as exc:
                    self._log_refusal(client, request.cmd, exc)
                    raise
            text = Reply(rid, result).to_json()
        except BadRequest as exc:
            text = ErrorReply(rid if rid is not None else _guess_id(message), exc.code,
                              str(exc)).to_json()
        except VssError as exc:
            text = ErrorReply(rid, exc.code, str(exc)).to_json()
        except asyncio.CancelledError:
            raise
        except Exception as exc:  # a bug answers as an error; the server keeps running
            log.exception("request failed")
            text = ErrorReply(rid, "internal", f"{type(exc).__name__}: {exc}").to_json()
        # answers are never dropped, unlike events
        with contextlib.suppress(ConnectionClosed):
            await client.ws.send(text)
            if client.session.closed_for_failures:
                await client.ws.close(1008, "too many wrong passwords")


def _peer(ws: ServerConnection) -> str:
    addr = getattr(ws, "remote_address", None)
    return f"{addr[0]}:{addr[1]}" if isinstance(addr, tuple) and len(addr) >= 2 else "?"


_RESERVED = frozenset({"t_us", "level", "kind", "message", "event"})  # the record's own names


def _flat(value: Any) -> bool:
    return isinstance(value, str | int | float | bool) or value is None


def _guess_id(message: str | bytes) -> Any:
    with contextlib.suppress(Exception):
        doc = json.loads(message)
        if isinstance(doc, dict) and isinstance(doc.get("id"), int | str):
            return doc["id"]
    return None

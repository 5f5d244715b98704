"""The VirtualStar Server: the `Telescope` behind a WebSocket/JSON API.

Each client connection gets a ``hello`` event, then every event the telescope
emits and a ``heartbeat`` event every `heartbeat_s` seconds. Requests are
handled concurrently (one task each), so a client waiting for a long track
can still ask for status on the same socket. A client that disconnects only
loses its pending answers: operations belong to the telescope, never to a
connection. A slow client's event queue drops its oldest events rather than
holding up the server.

Every connection has a budget (`access.Budget`: tiny before it authenticates,
larger after): a request is read only while the connection has a free slot of
requests in flight, and a slot is freed once its answer has been handed to the
socket. A peer that does not read its answers therefore stops being read (the
kernel's buffers then hold its flood back), and nothing it sends is buffered
without bound or delays anyone else. Password attempts are throttled per address
and overall (`astcom_client.throttle`), each wrong one logged as an `auth` warning.
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

from astcom_client.auth import Role
from astcom_client.throttle import AuthThrottle

from .access import AccessConfig, Budget, Session, check_listen, refuse_origin
from .commands import COMMANDS, dispatch
from .event_log import QUIET_COMMANDS, describe
from .exceptions import BadRequest, Throttled, VssError
from .protocol import API_VERSION, ErrorReply, Event, Reply, decode_request
from .telescope import Telescope

__all__ = ["DEFAULT_PORT", "VssServer", "parse_listen_url"]

log = logging.getLogger("virtualstar.server")

DEFAULT_PORT = 8740
EVENT_QUEUE = 256
MAX_QUEUED_MESSAGES = 8  # read from the socket but not yet taken; beyond, reading pauses
_WATCHING = ", ".join(sorted(name for name, c in COMMANDS.items() if c.role == Role.OBSERVER))


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


class _Slots:
    """A connection's requests in flight: `take` waits while all are in use."""

    def __init__(self, size: int) -> None:
        self.size = size
        self.used = 0
        self._freed = asyncio.Event()

    async def take(self) -> None:
        while self.used >= self.size:
            self._freed.clear()
            await self._freed.wait()
        self.used += 1

    def give(self) -> None:
        self.used -= 1
        self._freed.set()

    def resize(self, size: int) -> None:
        self.size = size
        self._freed.set()


@dataclass(eq=False)  # identity hash: kept in a set
class _Client:
    ws: ServerConnection
    queue: asyncio.Queue[str]
    session: Session
    peer: str = "?"
    address: str = "?"
    dropped: int = 0
    slots: _Slots | None = None
    tokens: float = 0.0
    tokens_s: float = 0.0
    refused: int = 0  # requests refused for want of a password
    throttled: int = 0  # password attempts refused unchecked
    requests: int = 0

    def put(self, text: str) -> None:
        if not self.session.may_watch:  # events are for authenticated clients only
            return
        if self.queue.full():
            with contextlib.suppress(asyncio.QueueEmpty):
                self.queue.get_nowait()
            self.dropped += 1
        self.queue.put_nowait(text)

    def apply(self, budget: Budget) -> None:
        """Give the connection `budget` (a larger one once it has authenticated)."""
        if self.slots is None:
            self.slots = _Slots(budget.in_flight)
        else:
            self.slots.resize(budget.in_flight)
        self.tokens, self.tokens_s = float(budget.burst), time.monotonic()
        with contextlib.suppress(AttributeError):  # websockets' own per-message limit
            self.ws.protocol.max_message_size = budget.message_bytes

    async def pace(self, budget: Budget) -> None:
        """Wait until the request rate of `budget` lets one more request be read."""
        if budget.rate_per_s is None:
            return
        now = time.monotonic()
        self.tokens = min(float(budget.burst),
                          self.tokens + (now - self.tokens_s) * budget.rate_per_s)
        self.tokens_s = now
        if self.tokens < 1.0:
            await asyncio.sleep((1.0 - self.tokens) / budget.rate_per_s)
            self.tokens, self.tokens_s = 1.0, time.monotonic()
        self.tokens -= 1.0


class VssServer:
    """Serve a Telescope to WebSocket clients; `await start(url)` returns the bound URL."""

    def __init__(self, telescope: Telescope, *, heartbeat_s: float = 1.0,
                 access: AccessConfig | None = None) -> None:
        self.telescope = telescope
        self.heartbeat_s = heartbeat_s
        self.access = access or AccessConfig()
        self._clients: set[_Client] = set()
        self.throttle = AuthThrottle(self.access.throttle)
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
        self._server = await serve(self._session, host, port,
                                   max_size=self.access.authenticated.message_bytes,
                                   max_queue=MAX_QUEUED_MESSAGES, compression=None,
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
                async with asyncio.timeout(5.0):
                    await self._server.wait_closed()
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
        peer = _peer(ws)
        client = _Client(ws, asyncio.Queue(EVENT_QUEUE), Session(self.access), peer,
                         peer.rpartition(":")[0] or peer)
        refusal = self._door(client)
        if refusal is not None:
            await ws.close(1013, refusal)
            return
        client.apply(client.session.budget)
        self._clients.add(client)
        self.telescope.log_event("info", "connection", f"client {peer} connected", client=peer)
        loop = asyncio.get_running_loop()
        writer = loop.create_task(self._writer(client))
        timer = None
        if not client.session.role:
            timer = loop.call_later(self.access.auth_timeout_s, self._auth_expired, client)
        tasks: set[asyncio.Task] = set()
        hello = {"server": "virtualstar", "api_version": API_VERSION,
                 "commands": sorted([*COMMANDS, "auth"]), "heartbeat_s": self.heartbeat_s,
                 "auth": client.session.hello()}
        if client.session.may_watch:  # no password needed: say where the mount answers ASTCom
            hello["mount_endpoint"] = self.telescope.config.mount_endpoint or None
        client.queue.put_nowait(Event("hello", hello, next(self._seq)).to_json())
        assert client.slots is not None
        try:
            while True:
                # a slot first: a peer that does not read its answers is not read either
                await client.slots.take()
                await client.pace(client.session.budget)
                try:
                    message = await ws.recv()
                except ConnectionClosed:
                    client.slots.give()
                    break
                client.requests += 1
                task = loop.create_task(self._handle(client, message))
                tasks.add(task)
                task.add_done_callback(tasks.discard)
        finally:
            if timer is not None:
                timer.cancel()
            self._clients.discard(client)
            self._log_disconnect(client)
            pending = {*tasks, writer}
            for task in pending:
                task.cancel()
            await asyncio.wait(pending)

    def _door(self, client: _Client) -> str | None:
        """Why one more connection that has not authenticated is refused, or None."""
        if not self.access.required:
            return None
        waiting = [c for c in self._clients if not c.session.role]
        if len(waiting) >= self.access.max_unauthenticated:
            why = (f"too many connections waiting to authenticate (at most "
                   f"{self.access.max_unauthenticated}); retry shortly")
        elif sum(c.address == client.address for c in waiting) >= \
                self.access.max_unauthenticated_per_address:
            why = (f"too many connections from {client.address} waiting to authenticate (at "
                   f"most {self.access.max_unauthenticated_per_address}); retry shortly")
        else:
            return None
        self.telescope.log_event("warning", "connection", f"client {client.peer} refused: {why}",
                                 client=client.peer)
        return why

    def _auth_expired(self, client: _Client) -> None:
        if not client.session.role:
            asyncio.get_running_loop().create_task(client.ws.close(
                1008, f"not authenticated within {self.access.auth_timeout_s:g} s"))

    def _log_disconnect(self, client: _Client) -> None:
        notes = []
        if client.refused:
            notes.append(f"{client.refused} requests refused for want of a password")
        if client.throttled:
            notes.append(f"{client.throttled} password attempts refused unchecked (throttled)")
        if self.access.required and not client.session.role:
            notes.append("never authenticated")
        text = f"client {client.peer} disconnected" + (f" ({'; '.join(notes)})" if notes else "")
        self.telescope.log_event("warning" if client.refused or client.throttled else "info",
                                 "connection", text, client=client.peer,
                                 requests=client.requests, refused=client.refused,
                                 throttled=client.throttled)

    def _permit(self, client: _Client, cmd: str, params: dict[str, Any]) -> None:
        """Check the client may send `cmd` (raise as `permit` does) and log it with the
        client and its role; a command its role may not send is a warning (one sent
        without a password is only counted, in the connection's disconnect event)."""
        command = COMMANDS.get(cmd)
        needed = command.role if command is not None else Role.OBSERVER
        role = client.session.role.label if client.session.role else "none"
        try:
            client.session.permit(cmd, needed, _WATCHING)
        except VssError as exc:
            if not client.session.role:
                client.refused += 1
            else:
                self.telescope.log_event("warning", "command", f"{cmd} from {client.peer} "
                                         f"({role}) refused: {exc}", command=cmd,
                                         client=client.peer, role=role)
            raise
        if cmd not in QUIET_COMMANDS:
            self.telescope.log_event("info", "command", f"{cmd} from {client.peer} ({role})",
                                     command=cmd, client=client.peer, role=role,
                                     params=json.dumps(params)[:500])

    def _log_refusal(self, client: _Client, cmd: str, exc: VssError) -> None:
        """A command the server refused or that failed (a bad target, the Sun zone, not
        arrived...): a warning with the code, beside the command's own info line. An
        operation that a `stop` or a newer command ended was neither: an info line saying
        how it ended (`outcome`: stopped or aborted)."""
        if cmd in QUIET_COMMANDS:
            return
        role = client.session.role.label if client.session.role else "none"
        if exc.code == "aborted":
            outcome = "stopped" if getattr(exc, "stopped", False) else "aborted"
            self.telescope.log_event("info", "command", f"{cmd} from {client.peer} ({role}) ended: "
                                     f"{exc} [{outcome}]", command=cmd, client=client.peer,
                                     role=role, code=exc.code, outcome=outcome)
            return
        self.telescope.log_event("warning", "command", f"{cmd} from {client.peer} ({role}) refused: "
                                 f"{exc} [{exc.code}]", command=cmd, client=client.peer, role=role,
                                 code=exc.code)

    async def _authenticate(self, client: _Client, params: dict[str, Any]) -> dict[str, Any]:
        """Check an `auth` request: throttled per address and overall, logged when wrong."""
        session = client.session
        attempt = session.parse_auth(params)
        if attempt is None:
            return {"role": session.role.label, "server_proof": None}
        verdict = self.throttle.reserve(client.address, time.monotonic())
        if verdict.refused:
            client.throttled += 1
            raise Throttled(str(session.refused(verdict.message(client.address))))
        try:
            if verdict.wait_s > 0:
                await asyncio.sleep(verdict.wait_s)  # held: the guesses of one address queue up
        except asyncio.CancelledError:
            self.throttle.cancelled(client.address, time.monotonic())
            raise
        try:
            result = session.verify(attempt)
        except VssError as exc:
            failure = self.throttle.failed(client.address, time.monotonic())
            notes = [f"{failure.failures} in a row from {client.address}"]
            if failure.locked_s:
                notes.append(f"{client.address} locked out for {failure.locked_s:g} s")
            if failure.refused:
                notes.append(f"{failure.refused} attempts refused unchecked since the last")
            self.telescope.log_event("warning", "auth", f"wrong password from {client.peer} "
                                     f"({'; '.join(notes)})", client=client.peer,
                                     address=client.address, failures=failure.failures,
                                     locked_s=failure.locked_s, refused=failure.refused)
            raise exc
        self.throttle.succeeded(client.address, time.monotonic())
        client.apply(session.budget)
        self.telescope.log_event("info", "auth", f"client {client.peer} authenticated as "
                                 f"{result['role']}", client=client.peer,
                                 address=client.address, role=result["role"])
        return result

    async def _writer(self, client: _Client) -> None:
        with contextlib.suppress(ConnectionClosed):
            while True:
                await client.ws.send(await client.queue.get())

    async def _handle(self, client: _Client, message: str | bytes) -> None:
        try:
            text = await self._answer(client, message)
            # answers are never dropped, unlike events; the slot is freed once the answer
            # is in the socket's buffer (a peer that does not read holds its slots)
            with contextlib.suppress(ConnectionClosed):
                await client.ws.send(text)
                if client.session.closed_for_failures:
                    await client.ws.close(1008, "too many wrong passwords")
        finally:
            assert client.slots is not None
            client.slots.give()

    async def _answer(self, client: _Client, message: str | bytes) -> str:
        self.requests += 1
        rid = None
        try:
            request = decode_request(message)
            rid = request.id
            if request.cmd == "auth":
                result = await self._authenticate(client, request.params)
            else:
                self._permit(client, request.cmd, request.params)
                try:
                    result = await dispatch(self.telescope, request.cmd, request.params)
                except VssError as exc:
                    self._log_refusal(client, request.cmd, exc)
                    raise
            return Reply(rid, result).to_json()
        except BadRequest as exc:
            return ErrorReply(rid if rid is not None else getattr(exc, "request_id", None),
                              exc.code, str(exc)).to_json()
        except VssError as exc:
            return ErrorReply(rid, exc.code, str(exc)).to_json()
        except asyncio.CancelledError:
            raise
        except Exception as exc:  # a bug answers as an error; the server keeps running
            log.exception("request failed")
            return ErrorReply(rid, "internal", f"{type(exc).__name__}: {exc}").to_json()


def _peer(ws: ServerConnection) -> str:
    addr = getattr(ws, "remote_address", None)
    return f"{addr[0]}:{addr[1]}" if isinstance(addr, tuple) and len(addr) >= 2 else "?"


_RESERVED = frozenset({"t_us", "level", "kind", "message", "event"})  # the record's own names


def _flat(value: Any) -> bool:
    return isinstance(value, str | int | float | bool) or value is None

"""The device side of ASTCom: serve a Collection to many clients and feed their streams.

The device loop and the Endpoint share one asyncio event loop (see docs/architecture.md,
"Threading model"): the loop computes a block of ticks, calls `publish`, and awaits;
requests are served between blocks.
"""

from __future__ import annotations

import asyncio
import contextlib
import contextvars
import itertools
import logging
import ssl
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from .auth import Authenticator, Role
from .codec import Codec, CodecLimits
from .exceptions import (
    AstcomError,
    AuthenticationFailed,
    AuthTimeout,
    ConnectionClosed,
    DeviceError,
    TooMany,
)
from .origins import check_allowed_origins
from .protocol import (
    AuthRequested,
    RequestReceived,
    ServerConnection,
    ServerOptions,
    ServerState,
)
from .registry import Collection
from .service import EndpointService, PendingInvoke, ServiceLimits
from .throttle import AuthThrottle, Failure, ThrottlePolicy
from .transports import (
    MemoryTransport,
    ServerHandle,
    Transport,
    memory_pair,
    server_ssl_context,
    start_server,
)
from .url import parse_url

__all__ = ["Endpoint", "EndpointConfig"]

log = logging.getLogger("astcom.endpoint")


@dataclass(frozen=True)
class EndpointConfig:
    """Everything an Endpoint enforces; all limits are per endpoint unless said otherwise.

    `passwords` maps role ("observer", "operator") to password; None turns
    authentication off (every client is an operator: loopback tests and demos only).
    `allowed_origins` says which web pages may open a WebSocket (the handshake's
    `Origin` header; clients that send none, i.e. non-browser ones, are always
    accepted): None (default) accepts pages served from loopback only
    (http(s)://127.0.0.1, localhost, [::1], any port); otherwise a list of origins
    `http(s)://host[:port]`, "loopback" for the default set, or "*" for any page.
    Other pages get HTTP 403 with the reason.

    Before a connection has authenticated it may send `max_pending_frames` frames of
    `max_pending_frame_bytes` at most (more, or larger, close it), and its password attempts are throttled per address
    and overall by `throttle` (astcom_client/throttle.py): held a moment, or refused
    unchecked with ERR 429. A peer that does not read its replies is not read either:
    each request is answered before the next is read.
    """

    loop_rate_hz: float = 1000.0
    passwords: Mapping[str, str] | None = None
    name: str = "astcom"
    max_clients: int = 32  # authenticated connections
    max_pending: int = 8  # connections not yet authenticated (they never take a client's slot)
    max_frame_bytes: int = 1 << 20
    max_depth: int = 16
    max_array_len: int = 100_000
    max_str_bytes: int = 1 << 16
    max_messages: int = 4096
    max_names_per_message: int = 1024
    max_streams_per_client: int = 64
    auth_timeout_s: float = 10.0
    max_pending_frame_bytes: int = 4096  # before authentication
    max_pending_frames: int = 16  # frames a connection may send before it has authenticated
    throttle: ThrottlePolicy = ThrottlePolicy()
    queue_packets: int = 256  # per client; the oldest stream packet is dropped beyond it
    flush_interval_s: float = 0.02  # a stream packet holds about this much time of samples
    certfile: str | None = None
    keyfile: str | None = None
    allowed_origins: Sequence[str] | None = None

    def __post_init__(self) -> None:
        object.__setattr__(self, "allowed_origins", check_allowed_origins(self.allowed_origins))

    def limits(self) -> dict[str, Any]:
        """Return the limits announced in the HELLO reply."""
        return {"max_frame_bytes": self.max_frame_bytes, "max_depth": self.max_depth,
                "max_array_len": self.max_array_len, "max_str_bytes": self.max_str_bytes,
                "max_messages": self.max_messages,
                "max_names_per_message": self.max_names_per_message,
                "max_streams_per_client": self.max_streams_per_client,
                "auth_timeout_s": self.auth_timeout_s, "queue_packets": self.queue_packets,
                "max_clients": self.max_clients, "max_pending": self.max_pending,
                "max_pending_frame_bytes": self.max_pending_frame_bytes,
                "max_pending_frames": self.max_pending_frames}


# Who sent the request a device function or setter is running for: (client name, role
# label, client id). Set around each request, so a device may log who asked (an event
# log) without the registry knowing about connections.
current_client: contextvars.ContextVar[tuple[str, str, int]] = contextvars.ContextVar(
    "astcom_current_client", default=("", "", 0))


class Endpoint:
    """Serve `collection` over any number of URLs; `publish` feeds the streams.

    `on_client(what, name, role, client_id)`, if set, is called with "connected" once a
    client is authenticated (its role known) and "disconnected" when it leaves.
    `on_auth_failure(peer, failure)`, if set, is called for every wrong password (a
    device logs it) with the `throttle.Failure` it cost the peer's address.
    """

    def __init__(self, collection: Collection, config: EndpointConfig | None = None) -> None:
        self.config = config or EndpointConfig()
        cfg = self.config
        self.collection = collection
        collection.freeze()
        self.codec = Codec(CodecLimits(cfg.max_frame_bytes, cfg.max_depth, cfg.max_array_len,
                                       cfg.max_str_bytes))
        self.service = EndpointService(
            collection, self.codec, loop_rate_hz=cfg.loop_rate_hz,
            limits=ServiceLimits(cfg.max_messages, cfg.max_names_per_message,
                                 cfg.max_streams_per_client, cfg.max_array_len,
                                 cfg.flush_interval_s))
        authenticator = Authenticator(cfg.passwords)
        self._options = ServerOptions(authenticator, self.codec, cfg.name,
                                      cfg.loop_rate_hz, cfg.queue_packets, cfg.limits(),
                                      admit=self._admit, gate_auth=authenticator.required)
        self.throttle = AuthThrottle(cfg.throttle)
        self._ids = itertools.count(1)
        self._wakers: dict[int, asyncio.Event] = {}
        self._servers: list[ServerHandle] = []
        self._sessions: set[asyncio.Task[None]] = set()
        self.urls: list[str] = []
        self.on_client: Callable[[str, str, str, int], None] | None = None
        self.on_auth_failure: Callable[[str, Failure], None] | None = None

    def _announce(self, what: str, conn: ServerConnection) -> None:
        if self.on_client is not None:
            try:
                self.on_client(what, conn.peer_name, conn.role.label if conn.role else "",
                               conn.client_id)
            except Exception:  # a device's logging must never cut a connection
                log.exception("on_client failed")

    # -- device side ------------------------------------------------------------------------
    def publish(self, first_tick: int, first_t_us: int, n_ticks: int,
                trace: np.ndarray | None = None) -> None:
        """Tell the endpoint ticks [first_tick, first_tick + n_ticks) are computed.

        `trace` is a float64 array (n_ticks, collection.trace_width) of the traced
        signals per tick, or None (then every signal is sampled at the block's end).
        `first_t_us` is the mount time of `first_tick` in integer microseconds.
        """
        if trace is not None and trace.shape != (n_ticks, self.collection.trace_width):
            raise ValueError(f"trace has shape {trace.shape}; expected "
                             f"({n_ticks}, {self.collection.trace_width})")
        self.service.publish(first_tick, first_t_us, n_ticks, trace)
        if self.service.groups:
            for conn in self.service.connections.values():
                if conn.queue_depth:
                    self._wakers[conn.client_id].set()

    @property
    def wanted_trace_columns(self) -> np.ndarray:
        """Return the trace columns some active stream needs (a device may fill only these)."""
        return self.service.wanted_trace_columns

    def stats(self) -> dict[str, Any]:
        """Return the same figures as the STATS command."""
        return self.service.stats()

    # -- serving ----------------------------------------------------------------------------
    async def serve(self, url: str, *, ssl_context: ssl.SSLContext | None = None) -> str:
        """Listen on `url` (port 0 picks a free port) and return the bound URL."""
        where = parse_url(url)
        if where.secure and ssl_context is None:
            if not self.config.certfile:
                raise ValueError(f"{where.scheme}:// needs EndpointConfig(certfile=..., keyfile=...) "
                                 "or an ssl_context")
            ssl_context = server_ssl_context(self.config.certfile, self.config.keyfile)
        handle = await start_server(where, self.handle_connection,
                                    max_frame_bytes=self.config.max_frame_bytes,
                                    ssl_context=ssl_context,
                                    allowed_origins=self.config.allowed_origins)
        self._servers.append(handle)
        self.urls.append(handle.url)
        log.info("ASTCom endpoint %s listening on %s", self.config.name, handle.url)
        return handle.url

    def connect_in_memory(self, maxsize: int = 64) -> MemoryTransport:
        """Return the client end of an in-process connection served by this endpoint."""
        client_end, server_end = memory_pair(maxsize)
        task = asyncio.get_running_loop().create_task(self.handle_connection(server_end))
        self._sessions.add(task)
        task.add_done_callback(self._sessions.discard)
        return client_end

    async def close(self) -> None:
        """Stop listening and close every connection."""
        for handle in self._servers:
            await handle.close()
        self._servers.clear()
        for conn in list(self.service.connections.values()):
            conn.close(ConnectionClosed.code, "endpoint shutting down")
            waker = self._wakers.get(conn.client_id)
            if waker:
                waker.set()
        for task in list(self._sessions):
            # the timeout cancels a session still stuck on a peer that stopped reading.
            with contextlib.suppress(asyncio.TimeoutError, asyncio.CancelledError, Exception):
                async with asyncio.timeout(2.0):
                    await task

    async def __aenter__(self) -> Endpoint:
        return self

    async def __aexit__(self, *exc: object) -> None:
        await self.close()

    async def handle_connection(self, transport: Transport) -> None:
        """Run one client's session until it ends; never raises."""
        task = asyncio.current_task()
        if task is not None:
            self._sessions.add(task)
        conn = ServerConnection(self._options, client_id=next(self._ids))
        try:
            refusal = self._admit() or self._admit_pending()
            if refusal is not None:
                conn.close(TooMany.code, refusal)
                await self._send_pending(conn, transport)
                return
            await self._session(conn, transport)
        except Exception:  # a bug must end one session, never the endpoint
            log.exception("session %d with %s failed", conn.client_id, transport.peer)
        finally:
            with contextlib.suppress(Exception):
                await transport.close(conn.close_code or 1000, conn.close_reason)
            if task is not None:
                self._sessions.discard(task)

    def _counts(self) -> tuple[int, int]:
        """Return (authenticated, pending) open connections."""
        authenticated = pending = 0
        for conn in self.service.connections.values():
            if conn.state is ServerState.CLOSED:
                continue
            if conn.role is Role.NONE:
                pending += 1
            else:
                authenticated += 1
        return authenticated, pending

    def _admit(self) -> str | None:
        """Return why one more authenticated client is refused, or None (at AUTH and at the door)."""
        if self._counts()[0] >= self.config.max_clients:
            return f"too many clients: this endpoint accepts at most {self.config.max_clients}"
        return None

    def _admit_pending(self) -> str | None:
        # Unauthenticated peers get their own, smaller pool: holding it full until
        # auth_timeout_s cannot lock authenticated clients out of theirs.
        if self._counts()[1] >= self.config.max_pending:
            return (f"too many connections waiting to authenticate: this endpoint accepts at most "
                    f"{self.config.max_pending} (each has {self.config.auth_timeout_s:g} s); "
                    "retry shortly")
        return None

    async def _session(self, conn: ServerConnection, transport: Transport) -> None:
        wake = asyncio.Event()
        control_lock = asyncio.Lock()
        self.service.attach(conn)
        self._wakers[conn.client_id] = wake
        writer = asyncio.create_task(self._writer(conn, transport, wake, control_lock))
        loop = asyncio.get_running_loop()
        timer = loop.call_later(self.config.auth_timeout_s, self._auth_expired, conn, wake)
        if self._options.gate_auth:
            _limit_frames(transport, self.config.max_pending_frame_bytes)
        announced = False
        frames_before_auth = 0
        try:
            while conn.state is not ServerState.CLOSED and not writer.done():
                try:
                    data = await transport.recv()
                except AstcomError as exc:  # e.g. a text frame, an oversized TCP frame
                    conn.send_error(None, exc)
                    conn.close(exc.code, exc.message, send_error=False)
                    break
                if data is None:
                    break
                if not conn.role:
                    frames_before_auth += 1
                    if frames_before_auth > self.config.max_pending_frames:
                        conn.close(TooMany.code, f"more than {self.config.max_pending_frames} "
                                   "frames before authenticating")
                        await self._send_pending(conn, transport)
                        break
                for event in conn.receive_frame(data):
                    if isinstance(event, RequestReceived):
                        await self._execute(conn, event)
                    elif isinstance(event, AuthRequested):
                        await self._gate_auth(conn, event, transport.peer)
                if conn.role:
                    timer.cancel()
                    if not announced:
                        announced = True
                        _limit_frames(transport, self.config.max_frame_bytes)
                        self._announce("connected", conn)
                # Replies go out from here, without a hop through the writer task (latency).
                try:
                    await self._send_control(conn, transport, control_lock)
                except ConnectionClosed:
                    break
                if conn.state is ServerState.CLOSED:
                    wake.set()
        finally:
            timer.cancel()
            if announced:
                self._announce("disconnected", conn)
            self.service.detach(conn)
            if conn.state is not ServerState.CLOSED:
                conn.close(1000, "")
            wake.set()
            with contextlib.suppress(Exception):
                async with asyncio.timeout(2.0):
                    await writer
            self._wakers.pop(conn.client_id, None)

    async def _execute(self, conn: ServerConnection, event: RequestReceived) -> None:
        token = current_client.set((conn.peer_name, conn.role.label if conn.role else "",
                                    conn.client_id))
        try:
            result = self.service.execute(conn, event.command)
            if isinstance(result, PendingInvoke):
                result = await self._finish_invoke(result)
        except AstcomError as exc:
            conn.send_error(event.seq, exc)
            return
        finally:
            current_client.reset(token)
        conn.send_result(event.seq, result)

    async def _gate_auth(self, conn: ServerConnection, event: AuthRequested, peer: str) -> None:
        """Hold or refuse an AUTH as the throttle says, check it, report the outcome."""
        address = peer.rpartition(":")[0] or peer
        verdict = self.throttle.reserve(address, time.monotonic())
        if verdict.refused:  # counted by the throttle, not logged one by one (a flood)
            conn.finish_auth(event.seq, event.auth, verdict.message(address))
            return
        try:
            if verdict.wait_s > 0:
                await asyncio.sleep(verdict.wait_s)  # the guesses of one address queue up
        except asyncio.CancelledError:
            self.throttle.cancelled(address, time.monotonic())
            raise
        conn.finish_auth(event.seq, event.auth)
        now = time.monotonic()
        if conn.role:
            self.throttle.succeeded(address, now)
        elif conn.close_code == AuthenticationFailed.code:
            failure = self.throttle.failed(address, now)
            log.warning("wrong password from %s (%d in a row%s)", peer, failure.failures,
                        f"; locked out for {failure.locked_s:g} s" if failure.locked_s else "")
            if self.on_auth_failure is not None:
                try:
                    self.on_auth_failure(peer, failure)
                except Exception:  # a device's logging must never cut a connection
                    log.exception("on_auth_failure failed")
        else:  # malformed, timed out, or refused for want of a client slot: not a guess
            self.throttle.cancelled(address, now)

    @staticmethod
    async def _finish_invoke(pending: PendingInvoke) -> dict[str, Any]:
        try:
            value = await pending.awaitable
        except Exception as exc:
            raise DeviceError(f"{pending.function.name} failed: {type(exc).__name__}: {exc}"
                              ) from None
        return pending.complete(value)

    def _auth_expired(self, conn: ServerConnection, wake: asyncio.Event) -> None:
        if conn.state is not ServerState.READY and conn.state is not ServerState.CLOSED:
            conn.close(AuthTimeout.code, f"not authenticated within {self.config.auth_timeout_s:g} s")
            wake.set()

    async def _send_control(self, conn: ServerConnection, transport: Transport,
                            lock: asyncio.Lock) -> None:
        async with lock:  # one sender of replies at a time keeps them in request order
            while (frame := conn.next_control()) is not None:
                await transport.send(frame)

    async def _writer(self, conn: ServerConnection, transport: Transport, wake: asyncio.Event,
                      control_lock: asyncio.Lock) -> None:
        try:
            while True:
                await wake.wait()
                wake.clear()
                if conn.has_control:
                    await self._send_control(conn, transport, control_lock)
                # Each packet goes out under the lock of the replies, taken per packet: a reply
                # waits for at most one packet, and a stream's first packet cannot overtake
                # the STREAM_START reply still being sent (spec §6: never DATA before it).
                while True:
                    async with control_lock:
                        frame = conn.next_stream()
                        if frame is None:
                            break
                        await transport.send(frame)
                if conn.state is ServerState.CLOSED:
                    await self._send_control(conn, transport, control_lock)
                    break
        except ConnectionClosed:
            pass
        finally:
            if conn.state is not ServerState.CLOSED:
                conn.close(ConnectionClosed.code, "")
            with contextlib.suppress(Exception):
                await transport.close(conn.close_code or 1000, conn.close_reason)

    async def _send_pending(self, conn: ServerConnection, transport: Transport) -> None:
        with contextlib.suppress(Exception):
            while (frame := conn.next_frame()) is not None:
                async with asyncio.timeout(2.0):
                    await transport.send(frame)


def _limit_frames(transport: Transport, max_bytes: int) -> None:
    """Set the largest frame `transport` reads, if it can tell (the pre-auth budget)."""
    limit = getattr(transport, "limit_frames", None)
    if limit is not None:
        limit(max_bytes)
